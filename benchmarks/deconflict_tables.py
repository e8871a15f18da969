"""Seed 004 Tables 1-3 beside ours: iterations and wall time to conflict-free per stage.

For 4-10 UAVs (missions/deconflict_{n}uav.toml) three configurations of the same planner:
- Table 1, PSO only: the joint PSO alone (maxiteration 150); iterations until the best particle
  is conflict-free (150 + "no" when it never is);
- Table 2, PSO + delayed take-off: the joint PSO capped at --stage-pso iterations, then delays;
  iterations = PSO iterations + delay steps; trajectories adjusted = UAVs delayed;
- Table 3, PSO + waypoints: the same capped PSO, then waypoint insertion (no delays), so the
  waypoint stage is measured on its own; iterations = PSO + insertion-PSO iterations.
Each cell is the mean over --seeds seeds (planner seeds 1..k), run through the sweep runner as
studies/deconflict_table{1,2,3}.toml (--workers processes; rows kept in --out, so a rerun redoes
no finished run). Then the scaled 50 / 100 UAV scenarios with the full method (wall time to
conflict-free; target for 100: < 300 s on 2 cores).

    nice .venv/bin/python benchmarks/deconflict_tables.py [--seeds 3] [--sizes 4 ... 10]
        [--scaled 50 100] [--stage-pso 5] [--workers 2] [--out out]
"""

from __future__ import annotations

import argparse
import csv
import logging
import os
import time
from pathlib import Path

import msgspec
import numpy as np

from gcs_planner.analysis.sweep import load_study, run_study, summarise
from gcs_planner.planning import config_of, load_scenario
from gcs_planner.planning.deconflict4d import build_problem, planner

PAPER_T1 = {4: 50, 5: 104, 6: 140, 7: 149, 8: 150, 9: 150, 10: 150}
PAPER_T2 = {4: (1, 22), 5: (2, 89), 6: (3, 165), 7: (4, 256), 8: (5, 442), 9: (6, 587), 10: (8, 767)}
PAPER_T3 = {6: (5, 343), 7: (5, 174), 8: (5, 191), 9: (6, 311), 10: (8, 400)}
MISSIONS = os.path.join(os.path.dirname(__file__), "..", "missions")
STUDIES = Path(__file__).resolve().parents[1] / "studies"


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


def _table(number: int, sizes: list[int], seeds: list[int], stage_pso: int, out: Path, workers: int):
    """studies/deconflict_table{number}.toml over these sizes and seeds through the sweep runner
    (resumable: runs already in out's CSV are not redone); per size, (summary row, runs free)."""
    study, base = load_study(STUDIES / f"deconflict_table{number}.toml")
    grid = {**study.grid, "scenario": [f"../missions/deconflict_{n}uav.toml" for n in sizes]}
    if number > 1:
        grid["iterations"] = [stage_pso]
    study = msgspec.structs.replace(study, grid=grid, seeds=seeds)
    csv_path = out / (f"deconflict_table{number}" + (f"_pso{stage_pso}" if number > 1 else "") + ".csv")
    run_study(study, base, csv_path, workers=workers)
    rows = list(csv.DictReader(csv_path.open(newline="")))
    by_size = {}
    for entry, n in zip(summarise(study, csv_path), sizes, strict=True):
        runs = [r for r in rows if r["scenario"] == entry["scenario"] and int(r["seed"]) in seeds]
        free = sum(r["conflict_free"] == "True" and r["limits_ok"] == "True" for r in runs)
        by_size[n] = (entry, f"{free}/{len(runs)}")
    return by_size


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--sizes", type=int, nargs="*", default=list(range(4, 11)))
    ap.add_argument("--scaled", type=int, nargs="*", default=[50, 100])
    ap.add_argument("--stage-pso", type=int, default=5, help="PSO iterations before delays / waypoints")
    ap.add_argument("--workers", type=int, default=2, help="sweep runner processes [2]")
    ap.add_argument("--out", type=Path, default=Path("out"), help="folder of the sweeps' CSVs [out]")
    args = ap.parse_args()
    logging.basicConfig(level=logging.WARNING)
    seeds = list(range(1, args.seeds + 1))
    args.out.mkdir(parents=True, exist_ok=True)
    t1, t2, t3 = (_table(k, args.sizes, seeds, args.stage_pso, args.out, args.workers) for k in (1, 2, 3))
    print(f"seeds {seeds}; iterations are means; 'free' = runs conflict-free / runs; s = CPU s per run")
    head = (
        f"{'UAVs':>4} | {'T1 paper':>8} {'PSO':>6} {'free':>4} {'s':>6} | {'T2 paper':>9} {'+delay':>7} "
        f"{'adj':>4} {'free':>4} {'s':>6} | {'T3 paper':>9} {'+wps':>6} {'added':>5} {'free':>4} {'s':>6}"
    )
    print(head)
    print("-" * len(head))
    for n in args.sizes:
        (r1, f1), (r2, f2), (r3, f3) = t1[n], t2[n], t3[n]
        p2, p3 = PAPER_T2[n], PAPER_T3.get(n)
        cells = [
            f"{n:>4} | {PAPER_T1[n]:>8} {r1['iterations_total mean']:>6.1f} {f1} {r1['cpu_s mean']:>6.2f}",
            f"{f'{p2[0]} / {p2[1]}':>9} {r2['iterations_total mean']:>7.1f}"
            f" {r2['uavs_delayed mean']:>4.1f} {f2} {r2['cpu_s mean']:>6.2f}",
            f"{(f'{p3[0]} / {p3[1]}' if p3 else '-'):>9} {r3['iterations_total mean']:>6.1f}"
            f" {r3['waypoints_added mean']:>5.1f} {f3} {r3['cpu_s mean']:>6.2f}",
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
