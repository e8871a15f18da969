"""Seed 004's joint PSO (Table 1) against library optimisers on the same cost, start and budget.

    pip install -e ".[bench]" && pip install --no-deps mealpy==3.0.3 opfunu==1.0.4 pandas
    nice python benchmarks/deconflict_peers.py --sizes 4 6 8 10 --seeds 1 2 3 4 5

For missions/deconflict_{n}uav.toml the method's stage-1 search (planner.joint_search: every UAV's
interior waypoints and leg durations) is given, unchanged, to the method's PSO and to the peers of
planner_peers.py (scipy DE, pyswarms, CMA-ES, mealpy GWO). Everyone starts from the method's initial
swarm (the straight flight plans plus its Gaussian spread) and gets its budget, particles x
iterations cost rows (40 x 150), without early stop. A run is judged on the best candidate it
evaluated within the budget: conflict-free and within every limit by the planner's own check (the
waypoint polylines with corner margins), the evaluations it took to get there (Table 1 counts
iterations: divide by 40), and its cost F.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np
from planner_peers import PEERS

from gcs_planner.planning import config_of, load_scenario
from gcs_planner.planning.deconflict4d import build_problem
from gcs_planner.planning.deconflict4d.planner import Search, initial_tracks, joint_search, swarm_config
from gcs_planner.planning.pso import minimize

MISSIONS = Path(__file__).resolve().parent.parent / "missions"


class Budgeted:
    """The search's cost as any optimiser calls it: rows counted, the best within budget kept."""

    def __init__(self, search: Search, budget: int) -> None:
        self.search, self.budget = search, budget
        self.used, self.best, self.feasible, self.first = 0, math.inf, False, None

    def __call__(self, x: np.ndarray) -> np.ndarray:
        x = np.clip(np.atleast_2d(x), self.search.lower, self.search.upper)
        ev = self.search.evaluate(x)
        for cost, ok in zip(ev.cost, ev.feasible, strict=True):
            self.used += 1
            if self.used <= self.budget and cost < self.best:
                self.best, self.feasible = float(cost), bool(ok)
            if self.feasible and self.first is None:
                self.first = self.used
        return ev.cost


def run_one(size: int, method: str, seed: int) -> dict:
    scenario = load_scenario(MISSIONS / f"deconflict_{size}uav.toml")
    problem = build_problem(scenario, config_of(scenario))
    s = problem.settings
    search = joint_search(problem, initial_tracks(problem))
    rng = np.random.default_rng(seed)
    init = search.initial_swarm(s.particles, rng)
    cost = Budgeted(search, s.particles * s.iterations)
    cpu = time.process_time()
    if method == "method_pso":
        minimize(cost, search.lower, search.upper, swarm_config(s, s.particles, s.iterations), rng, init=init)
    else:
        PEERS[method](cost, search.lower, search.upper, s.particles, cost.budget, seed, init)
    return {"uavs": size, "method": method, "seed": seed, "conflict_free": cost.feasible,
            "evaluations_to_free": cost.first, "cost": cost.best, "evaluations": cost.used,
            "cpu_s": time.process_time() - cpu}  # fmt: skip


def table(rows: list[dict]) -> None:
    print("| UAVs | method | runs conflict-free | evaluations to conflict-free (mean) | cost F, mean (std) |"
          " evaluations | CPU s |")  # fmt: skip
    print("|---|---|---|---|---|---|---|")
    order = ["method_pso", *PEERS]
    keys = sorted({(r["uavs"], r["method"]) for r in rows}, key=lambda k: (k[0], order.index(k[1])))
    for size, method in keys:
        sel = [r for r in rows if (r["uavs"], r["method"]) == (size, method)]
        free = [r["evaluations_to_free"] for r in sel if r["evaluations_to_free"] is not None]
        cost = np.array([r["cost"] for r in sel])
        reach = f"{np.mean(free):.0f}" if free else "-"
        print(f"| {size} | {method} | {sum(r['conflict_free'] for r in sel)}/{len(sel)} | {reach} |"
              f" {cost.mean():.1f} ({cost.std():.1f}) | {np.mean([r['evaluations'] for r in sel]):.0f} |"
              f" {np.mean([r['cpu_s'] for r in sel]):.1f} |")  # fmt: skip


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[4, 6, 8, 10])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3, 4, 5])
    ap.add_argument("--methods", nargs="+", default=["method_pso", *PEERS], choices=["method_pso", *PEERS])
    ap.add_argument("--out", type=Path, default=Path("bench_deconflict_peers.json"), help="resumed if there")
    args = ap.parse_args()
    rows = json.loads(args.out.read_text()) if args.out.exists() else []
    done = {(r["uavs"], r["method"], r["seed"]) for r in rows}
    for size in args.sizes:
        for seed in args.seeds:
            for method in args.methods:
                if (size, method, seed) not in done:
                    rows.append(run_one(size, method, seed))
                    args.out.write_text(json.dumps(rows, indent=1))
                    print(json.dumps(rows[-1]), flush=True)
    table(rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
