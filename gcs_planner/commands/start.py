"""Start a vehicle's mission: optionally upload FILE first, then arm and send MISSION_START.

Order: ArduPilot-style vehicles are armed in GUIDED and then get MISSION_START (which switches
them to AUTO; ArduCopter refuses to arm in AUTO by default); PX4-style vehicles are armed and then
get MISSION_START. --no-arm only sends MISSION_START (the vehicle runs the mission once armed).
"""

from __future__ import annotations

import argparse
import asyncio
import time

from gcs_planner.commands._mission_cli import add_connection_arguments, autopilot_of, vehicle_link
from gcs_planner.commands.upload import prepare
from gcs_planner.errors import UserError
from gcs_planner.mavlink.command import CommandClient
from gcs_planner.mavlink.mission import MissionClient


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_connection_arguments(p)
    p.add_argument(
        "file", metavar="FILE", nargs="?", help="upload this mission first (.plan, WPL, plan.json)"
    )
    p.add_argument("--vehicle", help="vehicle id in plan.json [the one with --sysid]")
    p.add_argument("--scenario", help="scenario file whose fence and rally points to upload too")
    p.add_argument("--no-arm", action="store_true", help="do not arm; only send MISSION_START")


def run(args: argparse.Namespace) -> int:
    if args.file:
        prepare(args, args.autopilot if args.autopilot != "auto" else "px4", args.sysid)
    return asyncio.run(_start(args))


async def _start(args: argparse.Namespace) -> int:
    async with vehicle_link(args) as (link, heartbeat):
        autopilot = autopilot_of(heartbeat, args.autopilot)
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
            if autopilot == "ardupilot":
                steps.append(("mode GUIDED", lambda: command.set_mode("GUIDED")))
            steps.append(("arm", command.arm))
        steps.append(("mission start", command.mission_start))
        for name, step in steps:
            t0 = time.monotonic()
            try:
                await step()
            except UserError:
                print(f"{name:<16} {'FAILED':<10} {time.monotonic() - t0:>7.2f}")
                raise
            print(f"{name:<16} {'OK':<10} {time.monotonic() - t0:>7.2f}")
    return 0


def _bound(upload, items, mission_type):
    return lambda: upload(items, mission_type=mission_type)
