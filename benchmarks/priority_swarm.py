"""Benchmark the priority swarm planner against PSO / DE / GWO baselines, and its scaling to 500 UAVs.

    nice .venv/bin/python benchmarks/priority_swarm.py compare --out bench_swarm.json  # seeds 0..9
    nice .venv/bin/python benchmarks/priority_swarm.py scale --out bench_scale.json
    .venv/bin/python benchmarks/priority_swarm.py table bench_swarm.json bench_scale.json

compare: for each 40-UAV scenario and seed, the method runs first; every baseline then gets the
same evaluation budget per UAV (the method's total evaluations / UAVs). Results are appended to
the JSON file after every run (a long run can be read while it goes). Budget flags override the
scenario's [planner] table so the study fits on a shared 2-core machine.
scale: the method on a 40-UAV subset of swarm500 and on all 500 UAVs (time per UAV, growth).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from gcs_planner.planning import config_of
from gcs_planner.planning.baselines import METHODS, plan_baseline
from gcs_planner.planning.priority_swarm import plan as plan_method
from gcs_planner.scenario import load_scenario

MISSIONS = Path(__file__).resolve().parent.parent / "missions"
SCENARIOS = ("swarm40_open", "swarm40_cylinders", "swarm40_passages", "swarm40_urban")


def _record(plan, scenario: str, method: str, seed: int, cpu_s: float) -> dict:
    m = plan.metrics
    return {
        "scenario": scenario,
        "method": method,
        "seed": seed,
        "cost": m["cost_total"],
        "feasible": m["feasible_count"],
        "vehicles": len(plan.vehicles),
        "evaluations": m["evaluations"],
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
    scenarios = {name: load_scenario(MISSIONS / f"{name}.toml") for name in args.scenarios}
    for scenario in scenarios.values():
        scenario.planner.update(particles=args.particles, iterations=args.iterations, rounds=args.rounds)
        scenario.planner.update(rrt_iterations=args.rrt_iterations)
    for seed in args.seeds:  # seeds outermost: a cut-short run still covers every scenario
        for name, scenario in scenarios.items():
            cpu = time.process_time()
            plan = plan_method(scenario, config_of(scenario), np.random.default_rng(seed))
            rec = _record(plan, name, "priority_swarm", seed, time.process_time() - cpu)
            _append(args.out, rec)
            budget = rec["evaluations"] // len(scenario.vehicles)
            for method in args.baselines:
                cpu = time.process_time()
                base = plan_baseline(scenario, np.random.default_rng(seed), method, budget)
                _append(args.out, _record(base, name, method, seed, time.process_time() - cpu))


def scale(args) -> None:
    full = load_scenario(MISSIONS / "swarm500.toml")
    for n in args.sizes:
        scenario = load_scenario(MISSIONS / "swarm500.toml")
        scenario.vehicles = full.vehicles[:n] if n < len(full.vehicles) else full.vehicles
        t0, cpu = time.perf_counter(), time.process_time()
        plan = plan_method(scenario, config_of(scenario), np.random.default_rng(args.seed))
        rec = _record(plan, f"swarm500[:{n}]", "priority_swarm", args.seed, time.process_time() - cpu)
        rec["wall_s"] = time.perf_counter() - t0
        rec["cpu_s_per_uav"] = rec["cpu_s"] / n
        rec["check"] = plan.metrics["check"]
        _append(args.out, rec)


def table(args) -> None:
    rows = []
    for path in args.files:
        rows += json.loads(Path(path).read_text())
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
        feas = np.array([r["feasible"] / r["vehicles"] for r in sel])
        all_ok = np.mean([r["feasible"] == r["vehicles"] for r in sel])
        print(
            f"| {sc} | {method} | {len(sel)} | {cost.mean():.2f} | {cost.std():.2f} |"
            f" {100 * feas.mean():.1f} % | {100 * all_ok:.0f} % |"
            f" {np.mean([r['iterations_to_1pct'] for r in sel]):.1f} |"
            f" {np.mean([r['wall_s'] for r in sel]):.1f} |"
            f" {np.mean([r.get('cpu_s', np.nan) for r in sel]):.1f} |"
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
    c.add_argument("--out", type=Path, default=Path("bench_swarm.json"))
    s = sub.add_parser("scale")
    s.add_argument("--sizes", type=int, nargs="+", default=[40, 500])
    s.add_argument("--seed", type=int, default=1)
    s.add_argument("--out", type=Path, default=Path("bench_scale.json"))
    t = sub.add_parser("table")
    t.add_argument("files", nargs="+")
    args = p.parse_args(argv)
    {"compare": compare, "scale": scale, "table": table}[args.cmd](args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
