"""What ArduCopter's S-curve legs cost the mock: CPU per copter per physics step, against the mock's
own tuned multirotor kinematics (the peer, numpy over the fleet) in the same run.

N copters cruise straight 2 km legs with the next leg preloaded; the fleet's kinematics are stepped
at the mock's 0.05 s for ``--steps`` steps, best of ``--rounds``. A copter on S-curve legs is
Python per vehicle (sitl_mock.wpnav, sitl_mock.scurve); the tuned model is one numpy pass for all.

    python benchmarks/mock_scurve.py --counts 10 100 250
"""

from __future__ import annotations

import argparse
import platform
import time
from datetime import UTC, datetime

import numpy as np

from sitl_mock.flight import AIRFRAMES, Arrival, Guidance, Kinematics
from sitl_mock.wpnav import STOCK_PARAMS, WaypointNav

DT_S = 0.05  # the mock fleet's physics step
PARAMS = {**STOCK_PARAMS, "WP_SPD_UP": 2.5, "WP_SPD_DN": 1.5}


def fleet(count: int, scurve: bool) -> Kinematics:
    """``count`` copters at 30 m, each flying 2 km east then on, 20 m apart."""
    start = np.column_stack([np.zeros(count), 20.0 * np.arange(count), np.full(count, 30.0)])
    kin = Kinematics([AIRFRAMES["multirotor"]] * count, start - [0.0, 0.0, 30.0])
    kin.pos[:] = start
    for i in range(count):
        leg, after = start[i] + [2000.0, 0.0, 0.0], start[i] + [4000.0, 0.0, 0.0]
        if scurve:
            nav = kin.wpnav[i] = WaypointNav(PARAMS)
            nav.init(start[i], 10.0)
            nav.set_destination(leg)
            nav.set_destination_next(after)
            kin.command(i, Guidance.TRACK, leg, Arrival.TRACKED)
        else:
            kin.command(i, Guidance.PASS, leg, Arrival.RADIUS_3D, 2.0, 10.0)
    for _ in range(round(20.0 / DT_S)):  # 20 s: up to cruise speed
        kin.step(DT_S)
    return kin


def us_per_vehicle_step(count: int, scurve: bool, steps: int, rounds: int) -> float:
    best = np.inf
    for _ in range(rounds):
        kin = fleet(count, scurve)
        t0 = time.process_time()
        for _ in range(steps):
            kin.step(DT_S)
        best = min(best, time.process_time() - t0)
    return best / steps / count * 1e6


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--counts", type=int, nargs="+", default=[10, 100, 250])
    p.add_argument("--steps", type=int, default=200)
    p.add_argument("--rounds", type=int, default=3)
    args = p.parse_args()
    now = datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC")
    print(f"Machine: {platform.machine()}, Python {platform.python_version()}. Date: {now}.")
    print(f"CPU time of {args.steps} physics steps of {DT_S} s, best of {args.rounds}, copters in cruise.\n")
    print("| copters | legs | us per copter-step | / tuned | one core's share at real time (20 steps/s) |")
    print("|---:|---|---:|---:|---:|")
    for count in args.counts:
        tuned = us_per_vehicle_step(count, False, args.steps, args.rounds)
        scurve = us_per_vehicle_step(count, True, args.steps, args.rounds)
        for name, us in (("tuned (numpy)", tuned), ("S-curve (Python)", scurve)):
            share = us * 1e-6 * count / DT_S
            print(f"| {count} | {name} | {us:.1f} | {us / tuned:.1f} | {100 * share:.1f} % |")


if __name__ == "__main__":
    main()
