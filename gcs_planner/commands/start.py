"""Start a vehicle's mission: optionally upload FILE first, then arm and send MISSION_START.

Order: ArduCopter is armed in GUIDED and then gets MISSION_START (which switches it to AUTO;
ArduCopter refuses to arm in AUTO by default); other vehicles are armed and then get
MISSION_START(0, 0), the only range ArduPilot accepts. Arming waits for the vehicle's pre-arm
checks (--arm-timeout) and a refusal names the autopilot's own reason. --no-arm only sends
MISSION_START (the vehicle runs the mission once armed).
"""

from __future__ import annotations

import argparse
import asyncio
import sys
import time

from gcs_planner.autopilots import Conventions, quirks_for
from gcs_planner.commands._mission_cli import add_connection_arguments, autopilot_of, vehicle_link
from gcs_planner.commands.upload import add_clear_absent_argument, prepare
from gcs_planner.core.errors import UserError
from gcs_planner.core.validation import MAX_DURATION_S, number_flag
from gcs_planner.mavlink.command import CommandClient
from gcs_planner.mavlink.errors import MissionRejectedError
from gcs_planner.mavlink.mission import MissionClient
from gcs_planner.mavlink.preflight import arm_when_ready
from gcs_planner.mavlink.vehicle_status import VehicleStatus


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_connection_arguments(p)
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


def run(args: argparse.Namespace) -> int:
    if args.file:
        prepare(args, args.autopilot if args.autopilot != "auto" else Conventions.PX4, args.sysid)
    return asyncio.run(_start(args))


async def _start(args: argparse.Namespace) -> int:
    async with vehicle_link(args) as (link, heartbeat):
        autopilot = autopilot_of(heartbeat.autopilot, heartbeat.type, args.autopilot)
        quirks = quirks_for(heartbeat.autopilot, heartbeat.type)
        status = VehicleStatus(link, [args.sysid])
        print(f"vehicle {args.sysid} ({autopilot})")
        print(f"{'step':<16} {'result':<10} {'time_s':>7}")
        steps = []
        if args.file:
            mission = MissionClient(link, args.sysid, args.compid)
            for mission_type, items in prepare(args, autopilot, args.sysid):
                steps.append(
                    (f"upload {mission_type.name.lower()}", _bound(mission.upload, items, mission_type))
                )
        command = CommandClient(link, args.sysid, args.compid)
        if not args.no_arm:
            mode = quirks.start_arm_mode
            if mode is not None:
                steps.append((f"mode {mode}", lambda: command.set_mode(mode)))

            def waiting(sysid: int, reason: str) -> None:
                print(f"  not ready to arm yet: {reason}", file=sys.stderr)

            steps.append(
                ("arm", lambda: arm_when_ready(link, status, args.sysid, args.arm_timeout, waiting=waiting))
            )
        armed_here = not args.no_arm
        steps.append(("mission start", lambda: _start_or_disarm(command, status, args.sysid, armed_here)))
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


async def _start_or_disarm(
    command: CommandClient, status: VehicleStatus, sysid: int, armed_here: bool
) -> None:
    """MISSION_START; when the vehicle refuses it (PX4 with a mission its check rejected) a vehicle
    this command armed is disarmed again - never left armed on the ground - and the error carries
    the vehicle's own words."""
    texts_before = status.tracks[sysid].text_count
    try:
        await command.mission_start(0, 0)
    except UserError as exc:
        disarmed = ""
        if armed_here:
            await command.disarm()
            disarmed = "; disarmed it again"
        reason = status.reason(sysid, texts_before)
        said = f" (it said {reason!r})" if reason else ""
        raise UserError(f"vehicle {sysid} refused the mission start: {exc}{said}{disarmed}") from exc


def _bound(upload, items, mission_type):
    return lambda: upload(items, mission_type=mission_type)
