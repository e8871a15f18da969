"""Monte Carlo of the coalition planner (seed 003 sections 5.2-5.3): method vs baselines, and link study.

    nice .venv/bin/python benchmarks/coalition_montecarlo.py [--study mc|comm|both] [--runs 20] [--workers 2]

mc:   24/32/40/48/56 UAVs (Table 1 type mix 11:11:10, random positions in the 8 x 7 km area and
      headings), the three Table 2 targets and needs, >= --runs runs per size, for the method (ACO),
      the polynomial baseline (Sujit et al.) and global optimisation (no link limits). Reported:
      mean coalition effectiveness J (0 for a target not served by t_end) and mean time from a
      target's reveal to its last task, with the share of targets served.
comm: 32 UAVs, link range 1000/1500/2000/2500 m paired with one-way delay 0.2/2/3.5/5.5 s (as the
      paper pairs them), x margin delta_t 0.3/1.0/3.0 s (--full-grid: every range x delay pair).
      Each message gets a uniform extra delay of up to 0.25 dt_d (jitter), so a small margin loses
      late bids. Runs per cell = --runs.
Threats are left out here to keep the default run short (they are exercised by the timeline
scenario and the tests); every run uses its own seed (run index), identical across methods. A run
is gcs_planner.planning.coalition.montecarlo.run, the task studies/coalition_mc.toml sweeps.
"""

from __future__ import annotations

import argparse
import math
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from gcs_planner.planning.coalition import montecarlo

MISSION = Path(__file__).resolve().parents[1] / "missions" / "coalition_paper.toml"
SIZES = (24, 32, 40, 48, 56)
METHODS = ("aco", "polynomial", "global")
LINKS = ((1000.0, 0.2), (1500.0, 2.0), (2000.0, 3.5), (2500.0, 5.5))
MARGINS = (0.3, 1.0, 3.0)


def one_run(job: tuple) -> dict:
    n, seed, params = job
    return montecarlo.run(MISSION, {"uavs": n, **params}, seed)


def run_cells(cells: dict, runs: int, workers: int) -> dict:
    jobs = [(key, (n, seed, params)) for key, (n, params) in cells.items() for seed in range(runs)]
    with ProcessPoolExecutor(max_workers=workers) as pool:
        results = list(pool.map(one_run, [j for _, j in jobs], chunksize=2))
    out: dict = {}
    for (key, _), r in zip(jobs, results):
        out.setdefault(key, []).append(r)
    return out


def stats(rows: list[dict], key: str) -> str:
    v = np.array([r[key] for r in rows], dtype=float)
    v = v[np.isfinite(v)]
    if not len(v):
        return "-"  # e.g. completion time when no target was served
    return (
        f"{v.mean():8.4f} +- {v.std(ddof=1) / math.sqrt(len(v)):6.4f}" if len(v) > 1 else f"{v.mean():8.4f}"
    )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--study", choices=("mc", "comm", "both"), default="both")
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--full-grid", action="store_true", help="comm study: every range x delay pair")
    args = ap.parse_args()
    t0 = time.perf_counter()
    if args.study in ("mc", "both"):
        cells = {(n, m): (n, {"method": m, "t_end_s": 350.0}) for n in SIZES for m in METHODS}
        res = run_cells(cells, args.runs, args.workers)
        print(f"\nMonte Carlo, {args.runs} runs per cell (mean +- standard error)")
        print(
            f"{'UAVs':>5} {'method':>10} {'effectiveness J':>19} {'reveal->done [s]':>19} {'served':>8}"
            f" {'optimiser [s]':>14}"
        )
        for n in SIZES:
            for m in METHODS:
                rows = res[(n, m)]
                print(
                    f"{n:5d} {m:>10} {stats(rows, 'J'):>19} {stats(rows, 'completion_s'):>19}"
                    f" {np.mean([r['served'] for r in rows]):8.3f}"
                    f" {np.nanmean([r['optimiser_s'] for r in rows]):14.4f}"
                )
    if args.study in ("comm", "both"):
        links = (
            [(r, d) for r in (1000.0, 1500.0, 2000.0, 2500.0) for d in (0.2, 2.0, 3.5, 5.5)]
            if args.full_grid
            else list(LINKS)
        )
        cells = {
            (r, d, mg): (
                32,
                {
                    "link_range_m": r,
                    "delay_s": d,
                    "margin_s": mg,
                    "delay_jitter_s": 0.25 * d,
                    "t_end_s": 350.0,
                },
            )
            for r, d in links
            for mg in MARGINS
        }
        res = run_cells(cells, args.runs, args.workers)
        print(f"\nCommunication study, 32 UAVs, ACO, {args.runs} runs per cell (mean +- standard error)")
        print(
            f"{'range [m]':>9} {'delay [s]':>9} {'margin [s]':>10} {'effectiveness J':>19}"
            f" {'reveal->done [s]':>19}"
            f" {'served':>8}"
        )
        for key in cells:
            rows = res[key]
            print(
                f"{key[0]:9.0f} {key[1]:9.1f} {key[2]:10.1f} {stats(rows, 'J'):>19}"
                f" {stats(rows, 'completion_s'):>19} {np.mean([r['served'] for r in rows]):8.3f}"
            )
    print(f"\nwall time {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
