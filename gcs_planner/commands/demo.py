"""Run the bundled demo: plan missions/swarm_small.toml and fly it against mock vehicles.

Five multirotors cross a field with three towers: priority-swarm planning, concurrent upload
over MAVLink/UDP to five mock autopilots in lockstep with the tool (gcs_planner.core.lockstep: as fast
as the CPU allows, the same flight every time), MCAP + Rerun logs, and the conformance report.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from gcs_planner.commands import fly as fly_command
from gcs_planner.commands.fly import SPEEDUP
from gcs_planner.core.errors import UserError

DEMO_SCENARIO = Path(__file__).resolve().parents[2] / "missions" / "swarm_small.toml"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("-o", "--out", default="out/demo", help="output folder [out/demo]")
    p.add_argument(
        "--speedup",
        type=SPEEDUP,
        default=None,
        help="pace the mock vehicles at this rate of the wall clock [none: lockstep, as fast as it goes]",
    )


def run(args: argparse.Namespace) -> int:
    if not DEMO_SCENARIO.exists():
        raise UserError(f"bundled scenario not found at {DEMO_SCENARIO} (run from a source checkout)")
    print(f"demo: planning and flying {DEMO_SCENARIO.name} against mock vehicles")
    fly_args = fly_command.build_parser_defaults(DEMO_SCENARIO, args.out, args.speedup)
    return fly_command.run(fly_args)
