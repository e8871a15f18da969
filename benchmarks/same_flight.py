"""The same seed gives the same flight: the demo and the online paper coalition, flown twice, once
beside busy processes, compared row by row at full precision.

    python benchmarks/same_flight.py [--hogs 2] [--targets T1]

Each flight runs in lockstep (gcs_planner.core.lockstep, docs/clock.md). The first of each pair flies
on the machine as it is, the second beside ``--hogs`` processes spinning ``while True: pass``.
Printed: per flight the wall time of each run and whether every conformance row (the demo) or
task row and upload entry (the coalition; the planner's wall time per leg left out) is identical
(``repr``: a NaN equals a NaN). Exit 1 when one differs.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from gcs_planner.core import lockstep
from gcs_planner.flight import FlyOptions, fly
from gcs_planner.flight.coalition import HilOptions
from gcs_planner.flight.coalition.online_run import run_online
from gcs_planner.planning import load_scenario, plan_scenario
from sitl_mock.plan_fleet import MockVehicles, MockVehiclesProcess

MISSIONS = Path(__file__).resolve().parents[1] / "missions"


def demo_rows(out: Path) -> str:
    scenario = load_scenario(MISSIONS / "swarm_small.toml")
    plan = plan_scenario(scenario)
    vehicles = MockVehicles(plan.vehicles, plan.origin)
    result = lockstep.run(fly(scenario, plan, FlyOptions(out_dir=out, rrd=False), vehicles), True)
    return repr(result.reports)


def coalition_rows(out: Path, targets: tuple[str, ...] | None) -> str:
    options = HilOptions(out_dir=out, online=True, targets=targets)
    result = lockstep.run(
        run_online(load_scenario(MISSIONS / "coalition_paper.toml"), options, MockVehiclesProcess), True
    )
    uploads = [{k: v for k, v in u.items() if k != "plan_wall_ms"} for u in result.uploads]
    return repr((result.rows, uploads))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hogs", type=int, default=2, help="busy processes beside the second run [2]")
    ap.add_argument("--targets", default="", help="the coalition's targets, comma-separated [all]")
    args = ap.parse_args()
    targets = tuple(t for t in args.targets.split(",") if t) or None
    coalition = f"online paper coalition ({args.targets or 'all targets'})"
    flights = {"demo (swarm_small)": demo_rows, coalition: lambda out: coalition_rows(out, targets)}
    same = True
    print("| flight | run 1 wall [s] | run 2 wall [s], beside hogs | rows identical |")
    print("|---|---|---|---|")
    for name, rows_of in flights.items():
        walls, rows = [], []
        for busy in (False, True):
            hogs = [
                subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(args.hogs * busy)
            ]
            try:
                with tempfile.TemporaryDirectory() as out:
                    t0 = time.perf_counter()
                    rows.append(rows_of(Path(out)))
                    walls.append(time.perf_counter() - t0)
            finally:
                for hog in hogs:
                    hog.kill()
                    hog.wait()
        same &= rows[0] == rows[1]
        print(f"| {name} | {walls[0]:.1f} | {walls[1]:.1f} ({args.hogs} hogs) | {rows[0] == rows[1]} |")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
