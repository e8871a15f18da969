"""Plan a scenario file and write plan.json.

Runs the planner named in the scenario's [planner] table with its seed (or --seed) and prints a
per-vehicle table: path length, planned time, feasibility.
"""

from __future__ import annotations

import argparse

import numpy as np

from gcs_planner.progress import plan_with_progress
from gcs_planner.scenario import load_scenario


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("scenario", help="scenario file (missions/*.toml)")
    p.add_argument("-o", "--output", default="plan.json", help="plan file to write [plan.json]")
    p.add_argument("--seed", type=int, default=None, help="random seed (default: the file's)")


def run(args: argparse.Namespace) -> int:
    scenario = load_scenario(args.scenario)
    plan = plan_with_progress(scenario, args.seed)
    plan.save(args.output)
    print(f"{'vehicle':<10} {'sysid':>5} {'length_m':>10} {'time_s':>8}  feasible")
    for v in plan.vehicles:
        length = float(np.linalg.norm(np.diff(v.path, axis=0), axis=1).sum())
        print(f"{v.vehicle_id:<10} {v.sysid:>5} {length:>10.1f} {v.path_times_s[-1]:>8.1f}  {v.feasible}")
    print(f"wrote {args.output} ({len(plan.vehicles)} vehicles, planner {plan.planner})")
    return 0 if plan.feasible else 1
