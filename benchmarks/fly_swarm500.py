"""500 mock vehicles flown by one `fly`: swarm500 over two MAVLink networks (250 system ids each).

    .venv/bin/python benchmarks/fly_swarm500.py [--plan out/swarm500/plan.json] [--speedup 1]
        [--out out/fly500] [--vehicles 500]

Plans missions/swarm500.toml (or flies a saved --plan), starts one mock process per network
(sitl_mock.plan_fleet.MockVehicles, one shared simulated clock) and runs gcs_planner.flight.fly on
them as `gcs-planner fly` does: every mission uploaded, the fleet taken off, each route started
on time, every received frame logged to MCAP, each vehicle judged by the conformance report.
Prints one table: vehicles uploaded / completed / conforming, frames the link delivered against
raw frames read back from the MCAP (the stock mcap stream reader, via read_flight), MAVLink
sequence gaps (frames lost before the GCS), the GCS process's CPU (the mock processes not
counted), wall time and the mock's lag events. --vehicles N flies the first N of the plan.
"""

from __future__ import annotations

import argparse
import asyncio
import time
from pathlib import Path

from gcs_planner.flight import FlyOptions, fly, networks
from gcs_planner.plan import Plan
from gcs_planner.planning import plan_scenario
from gcs_planner.scenario import load_scenario
from gcs_planner.telemetry import read_flight
from sitl_mock.plan_fleet import MockVehicles

SCENARIO = Path(__file__).resolve().parents[1] / "missions" / "swarm500.toml"


def _sequence_loss(flight) -> float:
    """Frames lost before the GCS, from MAVLink sequence gaps, over the whole fleet."""
    lost = expected = 0.0
    for sysid in flight.sysids:
        _, loss = flight.link_loss(sysid, window_s=1e9)
        n = len(flight.frames_of(sysid))
        if len(loss):
            expected += n / (1.0 - loss[0])
            lost += n / (1.0 - loss[0]) - n
    return lost / expected if expected else 0.0


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--plan", type=Path, help="fly this plan.json (default: plan swarm500 first)")
    p.add_argument("--speedup", type=float, default=1.0)
    p.add_argument("--out", type=Path, default=Path("out/fly500"))
    p.add_argument("--vehicles", type=int, default=500)
    args = p.parse_args()
    scenario = load_scenario(SCENARIO)
    args.out.mkdir(parents=True, exist_ok=True)
    t_plan = time.monotonic()
    plan = Plan.load(args.plan) if args.plan else plan_scenario(scenario)
    plan_s = time.monotonic() - t_plan
    plan.save(args.out / "plan.json")
    plan.vehicles = plan.vehicles[: args.vehicles]
    vehicles = MockVehicles(plan.vehicles, plan.origin, speedup=args.speedup)
    cpu0, t0 = time.process_time(), time.monotonic()
    result = asyncio.run(fly(scenario, plan, FlyOptions(out_dir=args.out, rrd=False), vehicles))
    cpu_s, wall_s = time.process_time() - cpu0, time.monotonic() - t0
    flight = read_flight(result.mcap_path)
    reports = result.reports
    tracks = flight.positions.values()
    log_s = max(float(t.t_s[-1]) for t in tracks) - min(float(t.t_s[0]) for t in tracks)
    rows = [
        ("vehicles", len(plan.vehicles)),
        ("networks (one mock process each)", networks(plan)),
        ("missions uploaded", sum(u.ok for u in result.uploads.values())),
        ("missions completed", sum(r.completed for r in reports)),
        ("vehicles conforming", sum(r.passed for r in reports)),
        ("frames delivered by the link", result.frames_received),
        ("raw frames read back from the MCAP", len(flight.frames)),
        ("frames lost before the GCS (sequence gaps)", f"{100 * _sequence_loss(flight):.3f} %"),
        ("GCS CPU [s] (this process)", f"{cpu_s:.1f}"),
        ("GCS CPU / wall", f"{cpu_s / wall_s:.2f}"),
        ("fly wall [s]", f"{wall_s:.1f}"),
        ("telemetry logged over [s, wall]", f"{log_s:.1f}"),
        ("speed-up", f"{args.speedup:g}"),
        ("mock lag events", vehicles.lag_events),
        ("planning wall [s]", f"{plan_s:.1f}" if not args.plan else "(saved plan)"),
    ]
    width = max(len(name) for name, _ in rows)
    print(f"| {'swarm500 fly':<{width}} | value |\n|{'-' * (width + 2)}|-------|")
    for name, value in rows:
        print(f"| {name:<{width}} | {value} |")
    bad = [r for r in reports if not r.passed]
    for r in bad[:10]:
        print(f"sysid {r.sysid}: {'; '.join(r.failures[:2])}")


if __name__ == "__main__":
    main()
