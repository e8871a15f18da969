"""Download a vehicle's mission (and fence and rally points) and print it; optionally save it to FILE.

FILE ending in .plan is written as QGroundControl JSON with all three lists; any other name as QGC
WPL 110 holding the one list --type names (mission: home at row 0). Frames are written with the
numbers QGC and Mission Planner use (5 / 6 / 11 as 0 / 3 / 10). Without FILE, the items are printed only.
"""

from __future__ import annotations

import argparse
import asyncio
from pathlib import Path

from gcs_planner.autopilots import Conventions
from gcs_planner.commands._mission_cli import (
    MISSION_TYPES,
    add_connection_arguments,
    autopilot_of,
    home_position,
    print_items,
    print_losses,
    vehicle_link,
)
from gcs_planner.core.errors import UserError
from gcs_planner.core.validation import output_file
from gcs_planner.mavlink.mission import MissionClient
from gcs_planner.missions.files import MissionFile, in_file_frames, save_mission_file
from gcs_planner.wire.types import MissionType


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_connection_arguments(p)
    p.add_argument("file", metavar="FILE", nargs="?", help="write the lists here (.plan, else WPL)")
    p.add_argument(
        "--type",
        choices=[*MISSION_TYPES, "all"],
        default=None,
        help="which list(s) to download [all for a .plan FILE, else mission]",
    )


def run(args: argparse.Namespace) -> int:
    if args.type is None:
        args.type = "all" if args.file and Path(args.file).suffix.lower() == ".plan" else "mission"
    if args.file and args.type == "all" and Path(args.file).suffix.lower() != ".plan":
        raise UserError(f"{args.file}: a WPL file holds one list; write a .plan or choose --type")
    return asyncio.run(_download(args))


async def _download(args: argparse.Namespace) -> int:
    types = list(MISSION_TYPES.values()) if args.type == "all" else [MISSION_TYPES[args.type]]
    if args.file:
        output_file(args.file, "FILE")  # before the vehicle is asked: a bad path costs no download
    async with vehicle_link(args) as (link, heartbeat):
        autopilot = autopilot_of(heartbeat.autopilot, heartbeat.type, args.autopilot)
        client = MissionClient(link, args.sysid, args.compid)
        lists = {}
        for mission_type in types:
            lists[mission_type] = await client.download(mission_type=mission_type)
        home = None
        if args.file and autopilot != Conventions.ARDUPILOT:
            home = await home_position(link, args.sysid, args.compid)  # ArduPilot's is item 0
    losses = []
    if args.file:  # written before anything is printed: a closed stdout (| head) must not lose it
        in_file = {t: in_file_frames(items) for t, items in lists.items()}
        mf = MissionFile.from_items(
            in_file.get(MissionType.MISSION, []),
            autopilot,
            home=home,
            fence=in_file.get(MissionType.FENCE),
            rally=in_file.get(MissionType.RALLY),
            lists=frozenset(in_file),
        )
        losses = save_mission_file(args.file, mf)
    for mission_type, items in lists.items():
        print_items(items, f"{mission_type.name.lower()}: {len(items)} items")
    if args.file:
        print_losses(losses)
        print(f"wrote {args.file}")
    return 0
