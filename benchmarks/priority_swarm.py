"""Benchmark the priority swarm planner against PSO / DE / GWO baselines, and its scaling to 500 UAVs.

    nice .venv/bin/python benchmarks/priority_swarm.py compare --out bench_swarm.csv  # seeds 0..9
    nice .venv/bin/python benchmarks/priority_swarm.py scale --out bench_scale.json [--timing-error-s 0]
    .venv/bin/python benchmarks/priority_swarm.py table bench_swarm.csv bench_scale.json

compare: studies/priority_swarm_compare.toml through the sweep runner (--workers processes; the
CSV is appended as runs finish, so a rerun redoes no finished run). Each run is one scenario and
seed: the method first, then every baseline with the same evaluation budget per UAV (the method's
total evaluations / UAVs). Budget flags override the scenario's [planner] table so the study fits
on a shared 2-core machine.
scale: the method on a 40-UAV subset of swarm500 and on all 500 UAVs (time per UAV, growth), one
plan at a time so that its wall time is the planner's own.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import sys
import time
from pathlib import Path

import msgspec
import numpy as np

from gcs_planner.analysis.sweep import load_study, run_study
from gcs_planner.commands.progress import counting_bar
from gcs_planner.planning import certify_plan, config_of, load_scenario
from gcs_planner.planning.baselines import METHODS
from gcs_planner.planning.priority_swarm import plan as plan_method

MISSIONS = Path(__file__).resolve().parent.parent / "missions"
STUDY = MISSIONS.parent / "studies" / "priority_swarm_compare.toml"
SCENARIOS = ("swarm40_open", "swarm40_cylinders", "swarm40_passages", "swarm40_urban")


def _record(plan, scenario: str, method: str, seed: int, cpu_s: float) -> dict:
    m = plan.metrics
    return {
        "scenario": scenario,
        "method": method,
        "seed": seed,
        "cost": m["cost_total"],
        "feasible": m["feasible_count"] / len(plan.vehicles),
        "iterations_to_1pct": m["iterations_to_1pct"],
        "wall_s": m["wall_time_s"],
        "cpu_s": cpu_s,
    }


def _append(out: Path, rec: dict) -> None:
    rows = json.loads(out.read_text()) if out.exists() else []
    rows.append(rec)
    out.write_text(json.dumps(rows, indent=1))
    print(json.dumps(rec), flush=True)


def compare(args) -> None:
    study, base = load_study(STUDY)
    grid = {
        "scenario": [f"../missions/{name}.toml" for name in args.scenarios],
        "baselines": [",".join(args.baselines)],
        "particles": [args.particles],
        "iterations": [args.iterations],
        "rounds": [args.rounds],
        "rrt_iterations": [args.rrt_iterations],
    }
    study = msgspec.structs.replace(study, grid=grid, seeds=args.seeds)
    with counting_bar("comparing", "run") as progress:
        run_study(study, base, args.out, args.workers, progress=progress)


def _compared_rows(path: Path) -> list[dict]:
    """compare's CSV as one record per (run, method) that ran."""
    records = []
    for row in csv.DictReader(path.open(newline="")):
        for method in ("priority_swarm", *METHODS):
            if row["error"] or row.get(f"{method}.cost_total", "") in ("", "nan"):  # not run
                continue
            records.append({
                "scenario": Path(row["scenario"]).stem,
                "method": method,
                "seed": int(row["seed"]),
                "cost": float(row[f"{method}.cost_total"]),
                "feasible": float(row[f"{method}.feasible_fraction"]),
                "iterations_to_1pct": float(row[f"{method}.iterations_to_1pct"]),
                "wall_s": float(row[f"{method}.wall_time_s"]),
                "cpu_s": float(row[f"{method}.cpu_s"]),
            })  # fmt: skip
    return records


def scale(args) -> None:
    full = load_scenario(MISSIONS / "swarm500.toml")
    for n in args.sizes:
        scenario = load_scenario(MISSIONS / "swarm500.toml")
        scenario.vehicles = full.vehicles[:n] if n < len(full.vehicles) else full.vehicles
        config = config_of(scenario)
        if args.timing_error_s is not None:
            config = msgspec.structs.replace(config, timing_error_s=args.timing_error_s)
        t0, cpu = time.perf_counter(), time.process_time()
        plan = plan_method(scenario, config, np.random.default_rng(args.seed))
        certify_plan(plan, scenario)  # as plan_scenario does: the one checker's verdict is the plan's
        rec = _record(plan, f"swarm500[:{n}]", "priority_swarm", args.seed, time.process_time() - cpu)
        rec["wall_s"] = time.perf_counter() - t0
        rec["cpu_s_per_uav"] = rec["cpu_s"] / n
        rec["check"] = plan.metrics["check"]
        rec["timing_error_s"] = config.timing_error_s
        rec["evaluations"] = plan.metrics["evaluations"]
        rec["load_1min"] = os.getloadavg()[0]
        _append(args.out, rec)


def table(args) -> None:
    rows = []
    for path in map(Path, args.files):
        rows += _compared_rows(path) if path.suffix == ".csv" else json.loads(path.read_text())
    keys = sorted(
        {(r["scenario"], r["method"]) for r in rows}, key=lambda k: (k[0], k[1] != "priority_swarm", k[1])
    )
    print(
        "| scenario | method | runs | cost mean | cost std | feasible | all ok | iters 1 % | wall s | CPU s |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    for sc, method in keys:
        sel = [r for r in rows if r["scenario"] == sc and r["method"] == method]
        cost = np.array([r["cost"] for r in sel])
        feas = np.array([r["feasible"] for r in sel])
        print(
            f"| {sc} | {method} | {len(sel)} | {cost.mean():.2f} | {cost.std():.2f} |"
            f" {100 * feas.mean():.1f} % | {100 * np.mean(feas == 1.0):.0f} % |"
            f" {np.mean([r['iterations_to_1pct'] for r in sel]):.1f} |"
            f" {np.mean([r['wall_s'] for r in sel]):.1f} |"
            f" {np.mean([r['cpu_s'] for r in sel]):.1f} |"
        )


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    c = sub.add_parser("compare")
    c.add_argument("--scenarios", nargs="+", default=list(SCENARIOS))
    c.add_argument("--seeds", type=int, nargs="+", default=list(range(10)))
    c.add_argument("--particles", type=int, default=10)
    c.add_argument("--iterations", type=int, default=15)
    c.add_argument("--rounds", type=int, default=2)
    c.add_argument("--rrt-iterations", type=int, default=200)
    c.add_argument("--baselines", nargs="*", default=list(METHODS), choices=METHODS)
    c.add_argument("--workers", type=int, default=2, help="sweep runner processes [2]")
    c.add_argument("--out", type=Path, default=Path("bench_swarm.csv"), help="results CSV, resumed")
    s = sub.add_parser("scale")
    s.add_argument("--sizes", type=int, nargs="+", default=[40, 500])
    s.add_argument("--seed", type=int, default=1)
    s.add_argument("--timing-error-s", type=float, help="planner timing_error_s [the default]")
    s.add_argument("--out", type=Path, default=Path("bench_scale.json"))
    t = sub.add_parser("table")
    t.add_argument("files", nargs="+")
    args = p.parse_args(argv)
    {"compare": compare, "scale": scale, "table": table}[args.cmd](args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
