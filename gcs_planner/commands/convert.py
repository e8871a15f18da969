"""Convert a mission file: .plan, .mission, WPL 110 / 120 or a fence / rally list -> .plan or WPL.

OUTPUT ending in .plan is written as QGroundControl JSON (mission, fence and rally); any other
name as QGC WPL 110 holding one list: the mission, or the one --list names. Prints what the
reader interpreted ("note:") and what OUTPUT cannot carry ("warning:"), one line each
(docs/mission-files.md); nothing is written when INPUT cannot be read.
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

from gcs_planner.commands._mission_cli import MISSION_TYPES, print_losses
from gcs_planner.core.errors import UserError
from gcs_planner.core.validation import output_file
from gcs_planner.missions.files import load_mission_file, save_mission_file
from gcs_planner.wire.types import MissionType


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", metavar="INPUT", help="mission file to read")
    p.add_argument("output", metavar="OUTPUT", help="file to write (.plan, else WPL)")
    p.add_argument("--list", choices=sorted(MISSION_TYPES), help="the one list a WPL OUTPUT holds [mission]")


def run(args: argparse.Namespace) -> int:
    output_file(args.output, "OUTPUT", [args.input])
    mf = load_mission_file(args.input)
    if args.list:
        if Path(args.output).suffix.lower() == ".plan":
            raise UserError("--list picks the one list of a WPL OUTPUT; a .plan holds all three")
        kind = MISSION_TYPES[args.list]
        mf = replace(
            mf,
            mission=mf.mission if kind == MissionType.MISSION else [],
            fence=mf.fence if kind == MissionType.FENCE else [],
            rally=mf.rally if kind == MissionType.RALLY else [],
            home=mf.home if kind == MissionType.MISSION else None,
            home_item=mf.home_item if kind == MissionType.MISSION else None,
        )
    for note in mf.notes:
        print(f"note: {note}")
    print_losses(save_mission_file(args.output, mf))
    print(
        f"wrote {args.output}: {len(mf.mission)} mission items, {len(mf.fence)} fence, {len(mf.rally)} rally"
    )
    return 0
