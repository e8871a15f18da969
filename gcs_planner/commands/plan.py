"""Plan a scenario file and write plan.json.

Runs the planner named in the scenario's [planner] table with its seed (or --seed) and prints a
per-vehicle table: path length, planned time, feasibility (the plan checker's verdict), then
each finding of an infeasible vehicle; exits 1 when any vehicle is infeasible.
"""

from __future__ import annotations

import argparse

import numpy as np

from gcs_planner.commands.progress import plan_with_progress, say_ignored_tables
from gcs_planner.core.errors import UserError
from gcs_planner.core.validation import number_flag, output_file
from gcs_planner.model.scenario import MAX_SEED
from gcs_planner.planning import load_scenario

SEED = number_flag(0, MAX_SEED, whole=True)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("scenario", help="scenario file (missions/*.toml)")
    p.add_argument("-o", "--output", default="plan.json", help="plan file to write [plan.json]")
    p.add_argument("--seed", type=SEED, default=None, help="random seed (default: the file's)")
    p.add_argument("--convergence", metavar="PNG", help="also plot the optimiser's best cost per iteration")


def run(args: argparse.Namespace) -> int:
    output_file(args.output, "-o", [args.scenario])
    if args.convergence:
        output_file(args.convergence, "--convergence", [args.scenario, args.output])
    scenario = load_scenario(args.scenario)
    plan = plan_with_progress(scenario, args.seed)
    plan.save(args.output)
    say_ignored_tables(scenario)
    if args.convergence:
        _plot_convergence(plan, args.convergence)
    print(f"{'vehicle':<10} {'sysid':>5} {'length_m':>10} {'time_s':>8}  feasible")
    for v in plan.vehicles:
        length = float(np.linalg.norm(np.diff(v.path, axis=0), axis=1).sum())
        print(f"{v.vehicle_id:<10} {v.sysid:>5} {length:>10.1f} {v.path_times_s[-1]:>8.1f}  {v.feasible}")
    for v in plan.vehicles:
        for note in (n for n in v.notes if n.startswith("check: ")):
            print(f"{v.vehicle_id}: {note}")
    print(f"wrote {args.output} ({len(plan.vehicles)} vehicles, planner {plan.planner})")
    return 0 if plan.feasible else 1


def _convergence_curves(plan) -> dict[str, list[float]]:
    """Best cost per iteration as planners record it: metrics["convergence"] (whole fleet) or
    metrics[vehicle]["history"] (per vehicle)."""
    curves = {}
    if isinstance(plan.metrics.get("convergence"), list):
        curves["fleet"] = plan.metrics["convergence"]
    for key, value in plan.metrics.items():
        if isinstance(value, dict) and isinstance(value.get("history"), list):
            curves[key] = value["history"]
    if not curves:
        raise UserError(f"planner {plan.planner!r} records no convergence history to plot")
    return curves


def _plot_convergence(plan, path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    for name, curve in _convergence_curves(plan).items():
        ax.plot(np.arange(1, len(curve) + 1), curve, label=name)
    ax.set(xlabel="iteration", ylabel="best cost", title=f"{plan.planner} convergence")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    print(f"wrote {path}")
