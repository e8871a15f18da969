"""Cost of plan -> items (with validation) and of the file formats, per mission size.

    nice .venv/bin/python benchmarks/mission_items.py [--sizes 100 1000 10000] [--repeat 3]

Prints the best of ``--repeat`` runs [ms] for: plan_to_items (geodesy, items, validate_items),
WPL write + read, .plan write + read; and checks each file round trip is exact.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from gcs_planner.core.geo import Origin
from gcs_planner.missions.files import MissionFile
from gcs_planner.missions.items import plan_to_items
from gcs_planner.missions.planfile import dumps_plan, loads_plan
from gcs_planner.missions.wpl import dumps_wpl, loads_wpl_items
from gcs_planner.model.plan import VehiclePlan

ORIGIN = Origin(47.397742, 8.545594, 488.0)


def random_plan(n: int, rng: np.random.Generator) -> VehiclePlan:
    wps = np.cumsum(rng.uniform(-50, 50, (n, 3)), axis=0) + [0, 0, 500]
    times = np.arange(n) * 5.0
    return VehiclePlan("v", 1, wps, times, rng.choice([8.0, 10.0], n), wps, times)


def best_ms(fn, repeat: int) -> tuple[float, object]:
    best, out = float("inf"), None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return 1e3 * best, out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[100, 1000, 10000])
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    rng = np.random.default_rng(1)
    print("| waypoints | items | plan_to_items ms | WPL write+read ms | .plan write+read ms | exact |")
    print("|---:|---:|---:|---:|---:|---|")
    for n in args.sizes:
        vp = random_plan(n, rng)
        t_items, items = best_ms(lambda vp=vp: plan_to_items(vp, ORIGIN, "ardupilot"), args.repeat)
        t_wpl, back = best_ms(lambda items=items: loads_wpl_items(dumps_wpl(items)), args.repeat)
        mf = MissionFile.from_items(items, "ardupilot")
        t_plan, mf_back = best_ms(lambda mf=mf: loads_plan(dumps_plan(mf)), args.repeat)
        exact = back == items and mf_back.items("ardupilot") == items
        print(f"| {n} | {len(items)} | {t_items:.1f} | {t_wpl:.1f} | {t_plan:.1f} | {exact} |")


if __name__ == "__main__":
    main()
