"""Clear a vehicle's mission, fence or rally list (or all three) and confirm each was cleared.

Uses MISSION_CLEAR_ALL. A vehicle armed and flying its mission in AUTO is refused unless --force;
a vehicle that refuses MISSION_CLEAR_ALL (ArduPilot in AUTO) is reported, and only with --force is
the list emptied by uploading an empty one instead (see gcs_planner.mavlink.mission).
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
    vehicle_link,
)
from gcs_planner.core.errors import UserError
from gcs_planner.mavlink.mission import MissionClient
from gcs_planner.wire.types import MissionType


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_connection_arguments(p)
    p.add_argument(
        "--type", choices=[*MISSION_TYPES, "all"], default="mission", help="list to clear [mission]"
    )
    add_force_argument(p)


def run(args: argparse.Namespace) -> int:
    return asyncio.run(_clear(args))


async def _clear(args: argparse.Namespace) -> int:
    mission_type = MissionType.ALL if args.type == "all" else MISSION_TYPES[args.type]
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
