"""Sweep throughput: one local worker, two local workers and a two-worker Dask LocalCluster on one study.

    nice .venv/bin/python benchmarks/sweep_throughput.py studies/swarm_small_budget.toml

Each configuration runs the whole study into a fresh CSV; wall time from submit to the last row
(the LocalCluster's start-up included). Prints runs per minute, the speed-up over one worker, the
mean CPU time of a run inside its worker (so a slower run tells apart from start-up and scheduling)
and the Dask / local-pool ratio at two workers. --seeds N replaces the study's seeds by 0..N-1 (a
longer study: the fixed start-up weighs less).
"""

from __future__ import annotations

import argparse
import csv
import statistics
import tempfile
import time
from pathlib import Path

import msgspec

from gcs_planner.analysis.sweep import load_study, run_study


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("study", type=Path)
    ap.add_argument("--seeds", type=int, default=None, help="seeds 0..N-1 instead of the study's")
    args = ap.parse_args()
    study, base = load_study(args.study)
    if args.seeds:
        study = msgspec.structs.replace(study, seeds=list(range(args.seeds)))
    configs = {
        "local, 1 worker": (1, None),
        "local, 2 workers": (2, None),
        "Dask LocalCluster, 2 workers": (2, "local"),
    }
    wall, cpu = {}, {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, (workers, scheduler) in configs.items():
            out = Path(tmp) / f"{workers}{scheduler}.csv"
            t = time.perf_counter()
            n = run_study(study, base, out, workers, scheduler)
            wall[name] = time.perf_counter() - t
            with out.open(newline="") as f:
                cpu[name] = statistics.mean(float(r["cpu_s"]) for r in csv.DictReader(f))
    one = wall["local, 1 worker"]
    print(f"study {args.study} ({n} runs)")
    print("| configuration | wall s | runs / min | speed-up over 1 worker | CPU s per run |")
    print("|---|---|---|---|---|")
    for name, seconds in wall.items():
        print(f"| {name} | {seconds:.1f} | {60 * n / seconds:.1f} | {one / seconds:.2f} | {cpu[name]:.2f} |")
    ratio = wall["Dask LocalCluster, 2 workers"] / wall["local, 2 workers"]
    print(f"Dask / local pool at 2 workers: {ratio:.3f}")


if __name__ == "__main__":
    main()
