"""Sweep scaling: runs per minute and CPU time per run at 1, 2, ... N workers (local pool, Dask).

    .venv/bin/python benchmarks/sweep_scaling.py studies/swarm_small_budget.toml --seeds 4 --workers 1 2
    .venv/bin/python benchmarks/sweep_scaling.py STUDY --workers 1 8 16 --dask local cli tcp://HOST:8786

Each configuration runs the whole study into a fresh CSV (``run_study``, as ``gcs-planner sweep``).
Wall time is from submit to the last row (a LocalCluster's start-up included); CPU per run is the
``cpu_s`` each run measured inside its worker (process CPU time of that run alone). The model: a
run is a fixed amount of work, so with the workers on separate cores its CPU time stays what it is
at one worker and runs / min grows with the workers; a CPU time per run that grows with the workers
is contention (shared caches and memory bandwidth, SMT siblings, native thread pools, or other jobs
on the machine), and the speed-up falls short by that factor. The table gives both, and the
machine's load average before and after each configuration. ``--dask`` adds a Dask configuration
per worker count: ``local`` (a LocalCluster of that many workers) or ``cli`` (a cluster started as a
user would, by this script: ``dask scheduler`` and ``dask worker ADDRESS --nworkers N --nthreads 1``
as processes of their own, over tcp on loopback); a scheduler address is a cluster you started,
measured once, at the worker count it has. --seeds N replaces the study's seeds by 0..N-1.
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import datetime
import os
import platform
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import msgspec

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from gcs_planner.analysis.sweep import load_study, run_study  # noqa: E402


def load_average() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def measure(study, base: Path, workers: int, scheduler: str | None, tmp: Path) -> dict:
    """One configuration: wall s, runs, CPU per run (mean, median, max), failed runs, load before/after."""
    out = tmp / f"{workers}-{(scheduler or 'pool').replace('/', '_').replace(':', '_')}.csv"
    before = load_average()
    t0 = time.perf_counter()
    n = run_study(study, base, out, workers, scheduler)
    wall = time.perf_counter() - t0
    with out.open(newline="") as f:
        rows = list(csv.DictReader(f))
    cpu = [float(r["cpu_s"]) for r in rows if not r["error"]]
    return {
        "runs": n,
        "wall": wall,
        "cpu_mean": statistics.mean(cpu),
        "cpu_median": statistics.median(cpu),
        "cpu_max": max(cpu),
        "failed": sum(bool(r["error"]) for r in rows),
        "load": f"{before} -> {load_average()}",
    }


def cluster_workers(address: str) -> int:
    """How many workers the Dask cluster whose scheduler is at ``address`` has now."""
    from distributed import Client

    with Client(address) as client:
        return len(client.scheduler_info()["workers"])


@contextlib.contextmanager
def dask_cli_cluster(workers: int) -> Iterator[str]:
    """The address of a Dask cluster started as a user starts one: a ``dask scheduler`` process and
    a ``dask worker`` process with ``workers`` single-threaded workers, on loopback; stopped after."""
    from distributed import Client

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        address = f"tcp://127.0.0.1:{s.getsockname()[1]}"
    dask = str(Path(sys.executable).with_name("dask"))
    quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
    port = address.rsplit(":", 1)[1]
    scheduler = subprocess.Popen([dask, "scheduler", "--host", "127.0.0.1", "--port", port, "--no-dashboard"],
                                 **quiet)  # fmt: skip
    worker = subprocess.Popen([dask, "worker", address, "--nworkers", str(workers), "--nthreads", "1",
                               "--no-dashboard"], **quiet)  # fmt: skip
    try:
        with Client(address, timeout=60) as client:
            client.wait_for_workers(workers, timeout=120)
        yield address
    finally:
        for proc in (worker, scheduler):
            proc.terminate()
            proc.wait(30)


def table(results: dict[str, dict], one: dict) -> str:
    rows = [
        "| configuration | workers | runs | wall s | runs / min | speed-up | CPU s / run (mean, median, max) "
        "| CPU / run vs 1 worker | failed | load average before -> after |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---|",
    ]
    for name, r in results.items():
        rows.append(
            f"| {name} | {r['workers']} | {r['runs']} | {r['wall']:.1f} | {60 * r['runs'] / r['wall']:.1f}"
            f" | {one['wall'] / r['wall']:.2f}"
            f" | {r['cpu_mean']:.2f}, {r['cpu_median']:.2f}, {r['cpu_max']:.2f}"
            f" | {r['cpu_mean'] / one['cpu_mean']:.2f} | {r['failed']} | {r['load']} |"
        )
    return "\n".join(rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("study", type=Path)
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--seeds", type=int, default=None, help="seeds 0..N-1 instead of the study's")
    ap.add_argument("--dask", nargs="*", default=[], help="'local' and/or scheduler addresses")
    ap.add_argument("--out", type=Path, help="also write the markdown here")
    args = ap.parse_args()
    study, base = load_study(args.study)
    if args.seeds:
        study = msgspec.structs.replace(study, seeds=list(range(args.seeds)))
    results: dict[str, dict] = {}
    with tempfile.TemporaryDirectory() as tmp:
        configs = [("local pool", None)] + [("Dask LocalCluster", "local")] * ("local" in args.dask)
        for workers in args.workers:
            for name, scheduler in configs:
                r = measure(study, base, workers, scheduler, Path(tmp))
                results[f"{name}, {workers}"] = {**r, "workers": workers}
            if "cli" in args.dask:
                with dask_cli_cluster(workers) as address:
                    r = measure(study, base, workers, address, Path(tmp))
                results[f"Dask scheduler + worker processes (tcp), {workers}"] = {**r, "workers": workers}
        for address in (s for s in args.dask if s not in ("local", "cli")):  # it has the workers it has
            workers = cluster_workers(address)
            r = measure(study, base, workers, address, Path(tmp))
            results[f"Dask {address}, {workers}"] = {**r, "workers": workers}
    one = results[f"local pool, {args.workers[0]}"]
    text = "\n".join(
        [
            f"Machine: {platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}."
            f" Date: {datetime.datetime.now(datetime.UTC):%Y-%m-%d %H:%M} UTC.",
            f"Command: `{' '.join([Path(sys.executable).name, *sys.argv])}`",
            "",
            table(results, one),
            "",
        ]
    )
    print(text)
    if args.out:
        args.out.write_text(text)


if __name__ == "__main__":
    main()
