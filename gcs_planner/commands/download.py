"""Download a vehicle's mission (and fence and rally points) and print it; optionally save it to FILE.

FILE ending in .plan is written as QGroundControl JSON with all three lists; any other name as QGC
WPL 110 holding the one list --type names (mission: home at row 0). Frames are written with the
numbers QGC and Mission Planner use (5 / 6 / 11 as 0 / 3 / 10). Without FILE, the items are printed only.

Many vehicles: --sysid 1,2,5 downloads from each at once and prints one row a vehicle; FILE then
names one file a vehicle with ``{sysid}`` in it (``fleet/{sysid}.plan``). A vehicle whose download
fails gets no file; the others' files are written, and the command ends with one line naming the
first failure.
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
    fleet_link,
    home_position,
    print_items,
    print_losses,
    vehicle_link,
)
from gcs_planner.core.errors import UserError
from gcs_planner.core.validation import output_file
from gcs_planner.mavlink.link import MavlinkLink
from gcs_planner.mavlink.mission import MissionClient
from gcs_planner.missions.files import Loss, MissionFile, in_file_frames, save_mission_file
from gcs_planner.wire.types import MissionItem, MissionType

SYSID_FIELD = "{sysid}"  # where a fleet download's FILE takes each vehicle's system id


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_connection_arguments(p, fleet=True)
    p.add_argument(
        "file",
        metavar="FILE",
        nargs="?",
        help=f"write the lists here (.plan, else WPL); for many vehicles a name with {SYSID_FIELD} in it",
    )
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
    if args.sysid is None:
        raise UserError("--sysid all: name the vehicles to download from as a list, e.g. 1,2,5")
    many = len(args.sysid) > 1
    if args.file and many and SYSID_FIELD not in args.file:
        raise UserError(
            f"FILE {args.file!r}: {len(args.sysid)} vehicles need one file each; put {SYSID_FIELD} in the"
            f" name, e.g. {SYSID_FIELD}.plan"
        )
    for sysid in args.sysid if args.file else ():  # before any vehicle is asked: a bad path costs nothing
        output_file(file_for(args.file, sysid), "FILE")
    return asyncio.run(_download_many(args) if many or args.sysid[0] > 255 else _download(args))


def file_for(pattern: str, sysid: int) -> str:
    """FILE for vehicle ``sysid``: ``{sysid}`` replaced by its id."""
    return pattern.replace(SYSID_FIELD, str(sysid))


async def fetch_lists(
    link: MavlinkLink, sysid: int, compid: int, types: list[MissionType], home_needed: bool
) -> tuple[dict[MissionType, list[MissionItem]], tuple[float, float, float] | None]:
    """Each list of ``types`` as the vehicle holds it, and its home when ``home_needed`` (an
    autopilot whose mission has no home item; None when it does not say)."""
    client = MissionClient(link, sysid, compid)
    lists = {t: await client.download(mission_type=t) for t in types}
    home = await home_position(link, sysid, compid) if home_needed else None
    return lists, home


def write_lists(path: str, lists: dict[MissionType, list[MissionItem]], autopilot: str, home) -> list[Loss]:
    """Save the downloaded ``lists`` to ``path`` in the file's own frame numbers; what the format
    could not carry."""
    in_file = {t: in_file_frames(items) for t, items in lists.items()}
    mf = MissionFile.from_items(
        in_file.get(MissionType.MISSION, []),
        autopilot,
        home=home,
        fence=in_file.get(MissionType.FENCE),
        rally=in_file.get(MissionType.RALLY),
        lists=frozenset(in_file),
    )
    return save_mission_file(path, mf)


def _types(args: argparse.Namespace) -> list[MissionType]:
    return list(MISSION_TYPES.values()) if args.type == "all" else [MISSION_TYPES[args.type]]


async def _download(args: argparse.Namespace) -> int:
    args.sysid = sysid = args.sysid[0]
    path = file_for(args.file, sysid) if args.file else None
    async with vehicle_link(args) as (link, heartbeat):
        autopilot = autopilot_of(heartbeat.autopilot, heartbeat.type, args.autopilot)
        home_needed = path is not None and autopilot != Conventions.ARDUPILOT  # ArduPilot's is item 0
        lists, home = await fetch_lists(link, sysid, args.compid, _types(args), home_needed)
    losses = []
    if path:  # written before anything is printed: a closed stdout (| head) must not lose it
        losses = write_lists(path, lists, autopilot, home)
    for mission_type, items in lists.items():
        print_items(items, f"{mission_type.name.lower()}: {len(items)} items")
    if path:
        print_losses(losses)
        print(f"wrote {path}")
    return 0


async def _download_many(args: argparse.Namespace) -> int:
    """Every vehicle of --sysid at once; one row each (item counts, the file written), then one line
    naming the first failure."""
    types = _types(args)

    async def one(sysid: int) -> tuple[str, dict, list[Loss], UserError | None]:
        info = link.vehicles[sysid]
        autopilot = autopilot_of(info.autopilot, info.mav_type, args.autopilot)
        path = file_for(args.file, sysid) if args.file else None
        try:
            lists, home = await fetch_lists(
                link, sysid, args.compid, types, path is not None and autopilot != Conventions.ARDUPILOT
            )
            losses = write_lists(path, lists, autopilot, home) if path else []
        except UserError as exc:
            return autopilot, {}, [], exc
        return autopilot, lists, losses, None

    async with fleet_link(args, args.sysid) as link:
        results = await asyncio.gather(*(one(s) for s in args.sysid))
    names = [t.name.lower() for t in types]
    print(f"{'sysid':>5} {'autopilot':<9} " + " ".join(f"{n:>7}" for n in names) + f" {'result':<8} file")
    for sysid, (autopilot, lists, _losses, error) in zip(args.sysid, results, strict=True):
        counts = " ".join(f"{len(lists[t]) if t in lists else '-':>7}" for t in types)
        written = file_for(args.file, sysid) if args.file and error is None else "-"
        print(f"{sysid:>5} {autopilot:<9} {counts} {'FAILED' if error else 'OK':<8} {written}")
    for sysid, (_autopilot, _lists, losses, _error) in zip(args.sysid, results, strict=True):
        for loss in losses:
            print(f"warning: vehicle {sysid}: {loss}")
    failed = [(s, e) for s, (_a, _l, _w, e) in zip(args.sysid, results, strict=True) if e is not None]
    if failed:
        raise UserError(
            f"{len(failed)} of {len(args.sysid)} downloads failed; vehicle {failed[0][0]}: {failed[0][1]}"
        )
    return 0
