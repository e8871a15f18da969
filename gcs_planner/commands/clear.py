"""Clear a vehicle's mission, fence or rally list (or all three) and confirm each was cleared.

Uses MISSION_CLEAR_ALL. A vehicle armed and flying its mission in AUTO is refused unless --force;
a vehicle that refuses MISSION_CLEAR_ALL (ArduPilot in AUTO) is reported, and only with --force is
the list emptied by uploading an empty one instead (see gcs_planner.mavlink.mission).

Many vehicles: --sysid 1,2,5 clears each at once, one row a vehicle; a vehicle flying its mission
refuses the whole command before anything is cleared. There is no --sysid all: a clear names the
vehicles it empties.
"""

from __future__ import annotations

import argparse
import asyncio
import time

from gcs_planner.commands._mission_cli import (
    MISSION_TYPES,
    add_connection_arguments,
    add_force_argument,
    check_not_flying_mission,
    fleet_link,
    vehicle_link,
)
from gcs_planner.core.errors import UserError
from gcs_planner.mavlink.mission import MissionClient
from gcs_planner.wire.types import MissionType


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_connection_arguments(p, fleet=True)
    p.add_argument(
        "--type", choices=[*MISSION_TYPES, "all"], default="mission", help="list to clear [mission]"
    )
    add_force_argument(p)


def run(args: argparse.Namespace) -> int:
    return asyncio.run(_clear(args))


async def _clear(args: argparse.Namespace) -> int:
    mission_type = MissionType.ALL if args.type == "all" else MISSION_TYPES[args.type]
    if args.sysid is None:
        raise UserError("--sysid all: a clear names the vehicles it empties; give them as a list, e.g. 1,2,5")
    if len(args.sysid) > 1 or args.sysid[0] > 255:  # many, or a fleet id on a second network
        return await _clear_many(args, args.sysid, mission_type)
    args.sysid = args.sysid[0]
    async with vehicle_link(args) as (link, _heartbeat):
        if mission_type in (MissionType.ALL, MissionType.MISSION):
            check_not_flying_mission(link, args.sysid, args.force, "clearing")
        client = MissionClient(link, args.sysid, args.compid)
        print(f"vehicle {args.sysid}")
        print(f"{'list':<8} {'result':<10} {'time_s':>7}")
        t0 = time.monotonic()
        try:
            notes = await client.clear(mission_type, force=args.force)
        except UserError:
            print(f"{args.type:<8} {'FAILED':<10} {time.monotonic() - t0:>7.2f}")
            raise
        print(f"{args.type:<8} {'CLEARED':<10} {time.monotonic() - t0:>7.2f}")
        for note in notes:
            print(f"note: {note}")
    return 0


async def _clear_many(args: argparse.Namespace, sysids: list[int], mission_type: MissionType) -> int:
    """Clear ``mission_type`` on every vehicle of ``sysids`` at once; one row each, then one line
    naming the first failure."""
    async with fleet_link(args, sysids) as link:
        if mission_type in (MissionType.ALL, MissionType.MISSION):
            for sysid in sysids:
                check_not_flying_mission(link, sysid, args.force, "clearing")

        async def one(sysid: int) -> tuple[UserError | None, list[str], float]:
            t0 = time.monotonic()
            try:
                notes = await MissionClient(link, sysid, args.compid).clear(mission_type, force=args.force)
            except UserError as exc:
                return exc, [], time.monotonic() - t0
            return None, notes, time.monotonic() - t0

        results = await asyncio.gather(*(one(s) for s in sysids))
    print(f"{'sysid':>5} {'list':<8} {'result':<10} {'time_s':>7}")
    for sysid, (error, _notes, took_s) in zip(sysids, results, strict=True):
        print(f"{sysid:>5} {args.type:<8} {'FAILED' if error else 'CLEARED':<10} {took_s:>7.2f}")
    for sysid, (_error, notes, _took_s) in zip(sysids, results, strict=True):
        for note in notes:
            print(f"note: vehicle {sysid}: {note}")
    failed = [(s, e) for s, (e, _n, _t) in zip(sysids, results, strict=True) if e is not None]
    if failed:
        raise UserError(
            f"{len(failed)} of {len(sysids)} clears failed; vehicle {failed[0][0]}: {failed[0][1]}"
        )
    return 0
