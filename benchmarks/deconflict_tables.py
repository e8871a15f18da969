"""Seed 004 Tables 1-3 beside ours: iterations and wall time to conflict-free per stage.

For 4-10 UAVs (missions/deconflict_{n}uav.toml) three configurations of the same planner:
- Table 1, PSO only: the joint PSO alone (maxiteration 150); iterations until the best particle
  is conflict-free (150 + "no" when it never is);
- Table 2, PSO + delayed take-off: the joint PSO capped at --stage-pso iterations, then delays;
  iterations = PSO iterations + delay steps; trajectories adjusted = UAVs delayed;
- Table 3, PSO + waypoints: the same capped PSO, then waypoint insertion (no delays), so the
  waypoint stage is measured on its own; iterations = PSO + insertion-PSO iterations.
Each cell is the mean over --seeds seeds (planner seeds 1..k). Then the scaled 50 / 100 UAV
scenarios with the full method (wall time to conflict-free; target for 100: < 300 s on 2 cores).

    nice .venv/bin/python benchmarks/deconflict_tables.py [--seeds 3] [--sizes 4 ... 10]
        [--scaled 50 100] [--stage-pso 5]
"""

from __future__ import annotations

import argparse
import logging
import os
import time

import msgspec
import numpy as np

from gcs_planner.planning import config_of
from gcs_planner.planning.deconflict4d import build_problem, planner
from gcs_planner.scenario import load_scenario

PAPER_T1 = {4: 50, 5: 104, 6: 140, 7: 149, 8: 150, 9: 150, 10: 150}
PAPER_T2 = {4: (1, 22), 5: (2, 89), 6: (3, 165), 7: (4, 256), 8: (5, 442), 9: (6, 587), 10: (8, 767)}
PAPER_T3 = {6: (5, 343), 7: (5, 174), 8: (5, 191), 9: (6, 311), 10: (8, 400)}
MISSIONS = os.path.join(os.path.dirname(__file__), "..", "missions")


def _run(path: str, seed: int, **overrides) -> dict:
    scenario = load_scenario(path)
    problem = build_problem(scenario, config_of(scenario))
    problem.settings = msgspec.structs.replace(problem.settings, **overrides)
    t0 = time.perf_counter()
    out = planner.run(problem, np.random.default_rng(seed))
    m = out.metrics
    stages = m["stages"]
    return {
        "free": out.conflict_free and m["limits_ok"],
        "iters": m["iterations_to_conflict_free"] or m["iterations_total"],
        "delayed": sum(s.get("trajectories_adjusted", 0) for s in stages),
        "waypoints": m["waypoints_added"],
        "wall_s": time.perf_counter() - t0,
        "min_sep": m["dense_check"]["min_separation_ratio"],
    }


def _mean(rows: list[dict], key: str) -> float:
    return float(np.mean([r[key] for r in rows]))


def _free(rows: list[dict]) -> str:
    return f"{sum(r['free'] for r in rows)}/{len(rows)}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--sizes", type=int, nargs="*", default=list(range(4, 11)))
    ap.add_argument("--scaled", type=int, nargs="*", default=[50, 100])
    ap.add_argument("--stage-pso", type=int, default=5, help="PSO iterations before delays / waypoints")
    args = ap.parse_args()
    logging.basicConfig(level=logging.WARNING)
    seeds = range(1, args.seeds + 1)
    only_pso = dict(use_delay=False, use_waypoints=False, max_rounds=1)
    with_delay = dict(use_waypoints=False, max_rounds=1, iterations=args.stage_pso, early_stop=False)
    with_wps = dict(use_delay=False, max_rounds=1, iterations=args.stage_pso, early_stop=False)
    print(f"seeds {list(seeds)}; iterations are means; 'free' = runs conflict-free / runs")
    head = (
        f"{'UAVs':>4} | {'T1 paper':>8} {'PSO':>6} {'free':>4} {'s':>6} | {'T2 paper':>9} {'+delay':>7} "
        f"{'adj':>4} {'free':>4} {'s':>6} | {'T3 paper':>9} {'+wps':>6} {'added':>5} {'free':>4} {'s':>6}"
    )
    print(head)
    print("-" * len(head))
    for n in args.sizes:
        path = os.path.join(MISSIONS, f"deconflict_{n}uav.toml")
        r1 = [_run(path, s, **only_pso) for s in seeds]
        r2 = [_run(path, s, **with_delay) for s in seeds]
        r3 = [_run(path, s, **with_wps) for s in seeds]
        t2, t3 = PAPER_T2[n], PAPER_T3.get(n)
        cells = [
            f"{n:>4} | {PAPER_T1[n]:>8} {_mean(r1, 'iters'):>6.1f} {_free(r1)} {_mean(r1, 'wall_s'):>6.2f}",
            f"{f'{t2[0]} / {t2[1]}':>9} {_mean(r2, 'iters'):>7.1f} {_mean(r2, 'delayed'):>4.1f} {_free(r2)}"
            f" {_mean(r2, 'wall_s'):>6.2f}",
            f"{(f'{t3[0]} / {t3[1]}' if t3 else '-'):>9} {_mean(r3, 'iters'):>6.1f}"
            f" {_mean(r3, 'waypoints'):>5.1f} {_free(r3)} {_mean(r3, 'wall_s'):>6.2f}",
        ]
        print(" | ".join(cells), flush=True)
    if args.scaled:
        print()
        print(
            f"{'scaled':>6} {'free':>5} {'iters':>6} {'delayed':>7} {'wps':>4} {'min sep/sep':>11} {'s':>7}"
        )
        for n in args.scaled:
            path = os.path.join(MISSIONS, f"deconflict_{n}uav_scaled.toml")
            r = _run(path, 1)
            print(
                f"{n:>6} {str(r['free']):>5} {r['iters']:>6} {r['delayed']:>7} {r['waypoints']:>4} "
                f"{r['min_sep'] if r['min_sep'] is not None else '-':>11} {r['wall_s']:>7.1f}",
                flush=True,
            )


if __name__ == "__main__":
    main()
