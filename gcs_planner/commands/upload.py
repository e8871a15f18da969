"""Upload a mission (plus fence and rally points) to one vehicle and print what it accepted.

FILE is a QGroundControl .plan (mission, geofence, rally points), a QGC WPL 110 file
(.waypoints / .txt), or plan.json from `gcs-planner plan` (the vehicle named by --vehicle, else the
one whose sysid is --sysid; --scenario adds that scenario's fence and rally points). Every list is
validated before anything is sent; the upload succeeds only on the vehicle's MISSION_ACK(ACCEPTED).
"""

from __future__ import annotations

import argparse
import asyncio
import time

from gcs_planner.commands._mission_cli import add_connection_arguments, autopilot_of, vehicle_link
from gcs_planner.errors import UserError
from gcs_planner.mavlink.files import MissionFile, mission_input
from gcs_planner.mavlink.items import scenario_fence_items, scenario_rally_items
from gcs_planner.mavlink.mission import MissionClient
from gcs_planner.mavlink.types import MissionType
from gcs_planner.mavlink.validate import validate_items
from gcs_planner.scenario import load_scenario


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_connection_arguments(p)
    p.add_argument("file", metavar="FILE", help="mission: .plan, .waypoints/.txt (QGC WPL 110) or plan.json")
    p.add_argument("--vehicle", help="vehicle id in plan.json [the one with --sysid]")
    p.add_argument("--scenario", help="scenario file whose fence and rally points to upload too")
    p.add_argument("--verify", action="store_true", help="download each list again and compare")


def lists_to_upload(mf: MissionFile, autopilot: str) -> list[tuple[MissionType, list]]:
    """(mission_type, items) to send, validated: the mission always, fence and rally when present."""
    lists = [(MissionType.MISSION, mf.items(autopilot))]
    lists += [
        (t, items) for t, items in ((MissionType.FENCE, mf.fence), (MissionType.RALLY, mf.rally)) if items
    ]
    for mission_type, items in lists:
        validate_items(items, mission_type=mission_type)
    return lists


def prepare(args: argparse.Namespace, autopilot: str) -> list[tuple[MissionType, list]]:
    """Read FILE (+ --scenario) for ``autopilot`` and validate every list.

    Called once before any network I/O (with --autopilot, or "px4" when it is auto) so bad input
    never reaches the vehicle, and again with the vehicle's autopilot: a WPL file is uploaded
    row for row either way; .plan and plan.json get ArduPilot's home item only for ArduPilot.
    """
    mf = mission_input(args.file, autopilot=autopilot, vehicle=args.vehicle, sysid=args.sysid)
    if args.scenario:
        scenario = load_scenario(args.scenario)
        mf.fence, mf.rally = scenario_fence_items(scenario), scenario_rally_items(scenario)
    return lists_to_upload(mf, autopilot)


def run(args: argparse.Namespace) -> int:
    prepare(args, args.autopilot if args.autopilot != "auto" else "px4")
    return asyncio.run(_upload(args))


async def _upload(args: argparse.Namespace) -> int:
    async with vehicle_link(args) as (link, heartbeat):
        autopilot = autopilot_of(heartbeat, args.autopilot)
        lists = prepare(args, autopilot)
        client = MissionClient(link, args.sysid, args.compid)
        print(f"vehicle {args.sysid} ({autopilot}) on {args.connect}")
        print(f"{'list':<8} {'items':>6} {'result':<10} {'opaque_id':>10} {'time_s':>7} verified")
        for mission_type, items in lists:
            t0 = time.monotonic()
            name = mission_type.name.lower()
            try:
                result = await client.upload(items, mission_type=mission_type, verify=args.verify)
            except UserError:
                print(f"{name:<8} {len(items):>6} {'FAILED':<10} {'-':>10} {time.monotonic() - t0:>7.2f}")
                raise
            elapsed_s = time.monotonic() - t0
            print(
                f"{name:<8} {len(items):>6} {'ACCEPTED':<10} {result.opaque_id:>10} {elapsed_s:>7.2f}"
                f" {'yes' if result.verified else 'no'}"
            )
    return 0
