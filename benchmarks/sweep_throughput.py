"""Sweep throughput: one local worker, two local workers and a two-worker Dask LocalCluster on one study.

    nice .venv/bin/python benchmarks/sweep_throughput.py studies/swarm_small_budget.toml

Each configuration runs the whole study into a fresh CSV; wall time from submit to the last row
(the LocalCluster's start-up included). Prints runs per minute, the speed-up over one worker and
the Dask / local-pool ratio at two workers.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from gcs_planner.sweep import load_study, run_study


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("study", type=Path)
    args = ap.parse_args()
    study, scenario = load_study(args.study)
    configs = {
        "local, 1 worker": (1, None),
        "local, 2 workers": (2, None),
        "Dask LocalCluster, 2 workers": (2, "local"),
    }
    wall = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, (workers, scheduler) in configs.items():
            t = time.perf_counter()
            n = run_study(study, scenario, Path(tmp) / f"{workers}{scheduler}.csv", workers, scheduler)
            wall[name] = time.perf_counter() - t
    one = wall["local, 1 worker"]
    print(f"study {args.study} ({n} runs)\n| configuration | wall s | runs / min | speed-up over 1 worker |")
    print("|---|---|---|---|")
    for name, seconds in wall.items():
        print(f"| {name} | {seconds:.1f} | {60 * n / seconds:.1f} | {one / seconds:.2f} |")
    ratio = wall["Dask LocalCluster, 2 workers"] / wall["local, 2 workers"]
    print(f"Dask / local pool at 2 workers: {ratio:.3f}")


if __name__ == "__main__":
    main()
