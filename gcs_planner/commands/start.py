"""Start a vehicle's mission: optionally upload FILE first, then arm and send MISSION_START.

Order: ArduCopter is armed in GUIDED and then gets MISSION_START (which switches it to AUTO;
ArduCopter refuses to arm in AUTO by default); other vehicles are armed and then get
MISSION_START(0, 0), the only range ArduPilot accepts. Arming waits for the vehicle's pre-arm
checks (--arm-timeout) and a refusal names the autopilot's own reason. --no-arm only sends
MISSION_START (the vehicle runs the mission once armed).

Many vehicles: --sysid 1,2,5 (or all: every vehicle of a plan.json FILE) uploads FILE to each as
`upload` does, then arms them all and starts them only when every one is armed
(gcs_planner.mavlink.fleet.start_fleet); the last line names a vehicle that did not arm or refused
the start, and which others fly. Timing between vehicles is not kept: `fly` starts each route at
its planned time.
"""

from __future__ import annotations

import argparse
import asyncio
import sys
import time
from collections.abc import Awaitable

from gcs_planner.autopilots import Conventions, quirks_for
from gcs_planner.commands._mission_cli import (
    add_connection_arguments,
    add_force_argument,
    add_in_flight_argument,
    autopilot_of,
    check_not_flying_mission,
    fleet_link,
    vehicle_link,
)
from gcs_planner.commands.upload import (
    UploadSource,
    add_clear_absent_argument,
    prepare,
    target_sysids,
    upload_fleet_on,
)
from gcs_planner.core.errors import UserError
from gcs_planner.core.fleet_ids import network_of
from gcs_planner.core.validation import MAX_DURATION_S, number_flag
from gcs_planner.mavlink.command import CommandClient
from gcs_planner.mavlink.errors import MissionRejectedError
from gcs_planner.mavlink.fleet import DEFAULT_WORKERS, start_fleet
from gcs_planner.mavlink.mission import MissionClient
from gcs_planner.mavlink.preflight import arm_when_ready, start_or_disarm
from gcs_planner.mavlink.transfer import Timing
from gcs_planner.mavlink.vehicle_status import VehicleStatus


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_connection_arguments(p, fleet=True, all_of="every vehicle of a plan.json FILE")
    p.add_argument(
        "file", metavar="FILE", nargs="?", help="upload this mission first (.plan, WPL, plan.json)"
    )
    p.add_argument("--vehicle", help="vehicle id in plan.json [the one with --sysid]")
    p.add_argument("--scenario", help="scenario file whose fence and rally points to upload too")
    add_clear_absent_argument(p)
    p.add_argument("--no-arm", action="store_true", help="do not arm; only send MISSION_START")
    p.add_argument(
        "--arm-timeout",
        type=number_flag(0, MAX_DURATION_S),
        default=120.0,
        metavar="S",
        help="how long to wait for the vehicle's pre-arm checks to pass [120 s]",
    )
    add_force_argument(p)
    add_in_flight_argument(p)
    p.set_defaults(workers=DEFAULT_WORKERS, retries=2, verify=False)  # a fleet's upload, as `upload`'s


def run(args: argparse.Namespace) -> int:
    source = UploadSource(args) if args.file else None
    if source is not None:
        sysids = target_sysids(args, source)
        for sysid in sysids:  # bad input fails before the network is touched
            prepare(args, args.autopilot if args.autopilot != "auto" else Conventions.PX4, sysid, source)
    elif args.sysid is None:
        raise UserError("--sysid all needs a plan.json FILE; without one, name the vehicles, e.g. 1,2,5")
    else:
        sysids = args.sysid
    if len(sysids) > 1 or network_of(sysids[0]) > 0:
        return asyncio.run(_start_many(args, sysids, source))
    args.sysid = sysids[0]
    return asyncio.run(_start(args, source))


async def _start(args: argparse.Namespace, source: UploadSource | None) -> int:
    async with vehicle_link(args) as (link, heartbeat):
        autopilot = autopilot_of(heartbeat.autopilot, heartbeat.type, args.autopilot)
        quirks = quirks_for(heartbeat.autopilot, heartbeat.type)
        status = VehicleStatus(link, [args.sysid])
        print(f"vehicle {args.sysid} ({autopilot})")
        print(f"{'step':<16} {'result':<10} {'time_s':>7}")
        steps = []
        if source is not None:
            check_not_flying_mission(link, args.sysid, args.force, "an upload")
            mission = MissionClient(link, args.sysid, args.compid, timing=Timing(window=args.in_flight))
            for mission_type, items in prepare(args, autopilot, args.sysid, source):
                steps.append(
                    (f"upload {mission_type.name.lower()}", _bound(mission.upload, items, mission_type))
                )
        command = CommandClient(link, args.sysid, args.compid)
        if not args.no_arm:
            mode = quirks.start_arm_mode
            if mode is not None:
                steps.append((f"mode {mode}", lambda: command.set_mode(mode)))

            def arm() -> Awaitable[None]:
                return arm_when_ready(link, status, args.sysid, args.arm_timeout, waiting=_say_waiting)

            steps.append(("arm", arm))
        armed_here = not args.no_arm
        steps.append(("mission start", lambda: start_or_disarm(command, status, armed_here)))
        for name, step in steps:
            t0 = time.monotonic()
            try:
                await step()
            except UserError as exc:
                verdict = "REJECTED" if isinstance(exc, MissionRejectedError) else "FAILED"
                print(f"{name:<16} {verdict:<10} {time.monotonic() - t0:>7.2f}")
                raise
            print(f"{name:<16} {'OK':<10} {time.monotonic() - t0:>7.2f}")
    return 0


def _say_waiting(sysid: int, reason: str) -> None:
    print(f"  vehicle {sysid} not ready to arm yet: {reason}", file=sys.stderr)


def _bound(upload, items, mission_type):
    return lambda: upload(items, mission_type=mission_type)


async def _start_many(args: argparse.Namespace, sysids: list[int], source: UploadSource | None) -> int:
    """Upload (with FILE), then start the fleet (fleet.start_fleet); one row a vehicle."""
    async with fleet_link(args, sysids) as link:
        if source is not None:
            await upload_fleet_on(link, args, sysids, source)
        t0 = time.monotonic()
        results = await start_fleet(
            link,
            sysids,
            arm=not args.no_arm,
            compid=args.compid,
            arm_timeout_s=args.arm_timeout,
            waiting=_say_waiting,
        )
    took_s = time.monotonic() - t0
    refused = [s for s in sysids if results[s].arm_error is not None]
    print(f"{'sysid':>5} {'arm':<8} {'start':<8}")
    for s in sysids:
        r = results[s]
        armed = "-" if args.no_arm else "FAILED" if r.arm_error else "DISARMED" if refused else "OK"
        started = "-" if refused else "REFUSED" if r.start_error else "OK"
        print(f"{s:>5} {armed:<8} {started:<8}")
    print(f"{'armed and started' if not args.no_arm else 'started'} in {took_s:.2f} s")
    if refused:
        armed = [str(s) for s in sysids if s not in refused]
        again = f"; disarmed {', '.join(armed)} again" if armed else ""
        first = results[refused[0]].arm_error
        raise UserError(f"{len(refused)} of {len(sysids)} vehicles did not arm, none started{again}; {first}")
    if failed := [s for s in sysids if not results[s].ok]:
        flying = [str(s) for s in sysids if s not in failed]
        others = f"; {', '.join(flying)} fly their missions" if flying else ""
        first = results[failed[0]].start_error
        raise UserError(f"{len(failed)} of {len(sysids)} vehicles refused the start{others}; {first}")
    return 0
