"""The paper scenario flown online on the mock: tasks on time and angle, formations beside the simulation's.

    python benchmarks/coalition_online.py --runs 2 [--speedup 5] [--targets T1]

Each run flies all 32 UAVs with the contract net deciding in flight (flight.coalition.online_run):
sitl_mock in lockstep with the run (gcs_planner.core.lockstep), or with --speedup in its own process
paced by the wall clock. Printed per run: strikes and assessments within 1 s / 10 deg, the largest
time and angle errors, uploads, the CPU / wall time per formation in flight, the flight time
(first to last position report), wall time and their ratio (times real time); then the first
run's formations (leader, time, members) beside the event simulation's.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from gcs_planner.core import lockstep
from gcs_planner.flight.coalition import HilOptions
from gcs_planner.flight.coalition.online_run import run_online
from gcs_planner.flight.coalition.report import format_formations
from gcs_planner.planning import load_scenario
from sitl_mock.plan_fleet import MockVehiclesProcess

SCENARIO = Path(__file__).resolve().parents[1] / "missions" / "coalition_paper.toml"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=1)
    ap.add_argument("--speedup", type=float, default=None, help="pace the mock [none: lockstep]")
    ap.add_argument("--targets", default="", help="comma-separated target ids [all]")
    args = ap.parse_args()
    targets = tuple(t for t in args.targets.split(",") if t) or None
    print("| run | strikes ok | assessments ok | max abs dt [s] | max abs dangle [deg] | uploads ok "
          "| formations in flight: CPU / wall max [ms] | flight [s] | wall [s] | x real time |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|---|")
    first = None
    for run in range(args.runs):
        with tempfile.TemporaryDirectory() as out:
            options = HilOptions(out_dir=Path(out), speedup=args.speedup, online=True, targets=targets)
            run_main = run_online(load_scenario(SCENARIO), options, MockVehiclesProcess)
            r = lockstep.run(run_main, args.speedup is None)
        flight_s = max(t[-1] for t, _ in r.tracks.values()) - min(t[0] for t, _ in r.tracks.values())
        strikes = [x for x in r.rows if x.task == "strike"]
        assess = [x for x in r.rows if x.task == "assess"]
        dt = max(abs(x.time_error_s) for x in r.rows)
        da = max(abs(x.angle_error_deg) for x in r.rows)
        ok = sum(u["ok"] for u in r.uploads)
        cpu, wall = max(r.tender_cpu_s) * 1e3, max(r.tender_compute_s) * 1e3
        print(f"| {run + 1} | {sum(x.passed for x in strikes)} / {len(strikes)} "
              f"| {sum(x.passed for x in assess)} / {len(assess)} | {dt:.2f} | {da:.1f} "
              f"| {ok} / {len(r.uploads)} | {len(r.tender_cpu_s)}: {cpu:.1f} / {wall:.1f} "
              f"| {flight_s:.0f} | {r.wall_time_s:.1f} | {flight_s / r.wall_time_s:.1f} |")  # fmt: skip
        first = first or r
        for f in r.failures:
            print(f"  failure: {f}")
        for e in r.released_awards:
            print(f"  released: {e['uav']} {e['target']} {e['task']} (live leg late; re-tendered)")
        for x in r.rows:
            if not x.passed:
                legs = [u for u in r.uploads if u["uav"] == x.uav and u["kind"] == "award"]
                print(f"  missed: {x.uav} {x.target} {x.task} dt {x.time_error_s:+.2f} s "
                      f"dangle {x.angle_error_deg:+.1f} deg; its award uploads: "
                      + "; ".join(f"t0 {u.get('t0_s')} late {u.get('leg_late_s')} clear {u.get('clear')}"
                                  for u in legs))  # fmt: skip
    print()
    print(format_formations(first.formations))
    for row in first.formations:
        print(f"{row['target']}: sim {row['sim_members']}\n    online {row['online_members']}")


if __name__ == "__main__":
    main()
