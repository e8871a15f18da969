"""Fleet set-up and upload: `gcs-planner upload plan.json --sysid all` to N mock vehicles.

    .venv/bin/python benchmarks/fleet_upload.py --counts 100 200 400 1000 [--profile-dir out/fleet_upload]

For each N: writes a synthetic plan.json of N straight missions (fleet ids network x 256 + sysid,
250 vehicles a network, as `sitl-mock` numbers them; --waypoints mission items and a path sampled
every second, about the size of a planner's), starts `sitl-mock --vehicles N` in a subprocess as a
user would (one process per network of 250), waits for its "N vehicles" line, then times the
command a user types, `gcs-planner upload plan.json --sysid all --connect udpout:HOST:FIRST-LAST
...` (one --connect per network, the lines sitl-mock prints), as a subprocess: interpreter start,
plan reading, link set-up, heartbeats and every upload included. Prints one table: N, wall seconds,
seconds per vehicle, mission items ACCEPTED per second, missions ACCEPTED, the exit status.
--profile-dir runs the upload under `python -m cProfile -o DIR/upload_N.prof`.
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from gcs_planner.core.fleet_ids import fleet_id
from gcs_planner.core.geo import Origin
from gcs_planner.model.plan import Plan, VehiclePlan

PER_NETWORK = 250  # sitl-mock's default --per-network
ORIGIN = Origin(47.397742, 8.545594, 488.0)
READY = re.compile(r"(\d+) vehicles, speed-up")
NETWORK = re.compile(r"--connect (udpout:\S+?)\)")


def synthetic_plan(count: int, waypoints: int = 20, spacing_m: float = 100.0, speed_mps: float = 12) -> Plan:
    """``count`` multirotors flying straight, parallel lines 20 m apart: ``waypoints`` mission
    waypoints ``spacing_m`` apart, the path sampled every second; fleet ids as sitl-mock's networks."""
    vehicles = []
    for i in range(count):
        network, sysid = divmod(i, PER_NETWORK)
        y = 20.0 * i
        wps = np.array([[k * spacing_m, y, 30.0] for k in range(waypoints)])
        times = np.arange(waypoints) * spacing_m / speed_mps
        path_times = np.arange(0.0, times[-1], 1.0)
        along = path_times * speed_mps
        path = np.column_stack([along, np.full_like(path_times, y), np.full_like(path_times, 30.0)])
        vehicles.append(
            VehiclePlan(
                vehicle_id=f"uav{i + 1}",
                sysid=fleet_id(network, sysid + 1),
                waypoints=wps,
                times_s=times,
                speeds_mps=np.full(waypoints, speed_mps),
                path=path,
                path_times_s=path_times,
            )
        )
    return Plan(origin=ORIGIN, planner="straight", vehicles=vehicles)


def start_mock(count: int, base_port: int) -> tuple[subprocess.Popen, list[str]]:
    """`sitl-mock --vehicles count` in a subprocess, serving; its --connect URL per network."""
    cmd = [sys.executable, "-m", "sitl_mock.cli", "--vehicles", str(count), "--base-port", str(base_port)]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    urls: list[str] = []
    assert proc.stderr is not None
    for line in proc.stderr:
        urls += NETWORK.findall(line)
        if READY.search(line):
            break
    else:
        raise RuntimeError(f"sitl-mock exited ({proc.wait()}) before serving")
    if not urls:  # one network: sitl-mock prints a line per vehicle, not a --connect
        urls = [f"udpout:127.0.0.1:{base_port}-{base_port + count - 1}"]
    threading.Thread(target=proc.stderr.read, daemon=True).start()  # drain its log: a full pipe stalls it
    return proc, urls


def run_one(count: int, base_port: int, waypoints: int, workdir: Path, profile_dir: Path | None) -> dict:
    plan_path = workdir / f"plan_{count}.json"
    synthetic_plan(count, waypoints).save(plan_path)
    mock, urls = start_mock(count, base_port)
    try:
        cmd = [sys.executable]
        if profile_dir is not None:
            profile_dir.mkdir(parents=True, exist_ok=True)
            cmd += ["-m", "cProfile", "-o", str(profile_dir / f"upload_{count}.prof")]
        cmd += ["-m", "gcs_planner.cli", "upload", str(plan_path), "--sysid", "all"]
        cmd += [arg for url in urls for arg in ("--connect", url)]
        t0 = time.monotonic()
        done = subprocess.run(cmd, capture_output=True, text=True)
        wall_s = time.monotonic() - t0
    finally:
        mock.terminate()
        mock.wait(30)
    rows = [line.split() for line in done.stdout.splitlines()]
    accepted = [row for row in rows if len(row) >= 4 and row[3] == "ACCEPTED"]  # sysid list items result
    if done.returncode:
        print(done.stderr[-2000:], file=sys.stderr)
    items = sum(int(row[2]) for row in accepted)
    return {"n": count, "wall_s": wall_s, "accepted": len(accepted), "items": items, "rc": done.returncode}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--counts", type=int, nargs="+", default=[100, 200, 400, 1000])
    p.add_argument("--waypoints", type=int, default=20, help="mission waypoints per vehicle")
    p.add_argument("--base-port", type=int, default=24550)
    p.add_argument("--profile-dir", type=Path, help="run each upload under cProfile, writing here")
    args = p.parse_args()
    print(
        "| N | wall s | s / vehicle | items/s | accepted | exit |\n|---:|---:|---:|---:|---:|---:|",
        flush=True,
    )
    with tempfile.TemporaryDirectory() as tmp:
        for count in args.counts:
            r = run_one(count, args.base_port, args.waypoints, Path(tmp), args.profile_dir)
            print(
                f"| {r['n']} | {r['wall_s']:.1f} | {r['wall_s'] / r['n']:.3f}"
                f" | {r['items'] / r['wall_s']:.0f} | {r['accepted']} | {r['rc']} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
