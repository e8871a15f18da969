"""500 mock vehicles flown by one `fly`: swarm500 over two MAVLink networks (250 system ids each).

    .venv/bin/python benchmarks/fly_swarm500.py [--plan out/swarm500/plan.json] [--speedup X]
        [--out out/fly500] [--vehicles 500] [--errors errors.json]

Plans missions/swarm500.toml (or flies a saved --plan), starts the mock fleet (one per network;
in lockstep with the GCS on one virtual clock, docs/clock.md, or with --speedup X paced on the
wall clock, one process per network) and runs gcs_planner.flight.fly on them as `gcs-planner fly`
does: every mission uploaded, the fleet taken off, each route started on time, every received
frame logged to MCAP, each vehicle judged by the conformance report. Prints one table: vehicles
uploaded / completed / conforming, frames the link delivered against raw frames read back from
the MCAP (the stock mcap stream reader, via read_flight), MAVLink sequence gaps (frames lost
before the GCS), this process's CPU (the GCS; in lockstep the mock fleets too, paced mock
processes not counted), wall time, the mock's lag events, then the along-track time errors flown
(every planned path point a second apart, conformance.schedule_errors_s: quantiles, and the
error differences of vehicles planned within 20 m of each other; --errors writes them as JSON for
the separation model, docs/timing-separation.md). --vehicles N flies the first N of the plan.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

import gcs_planner.flight.static_plan as static_plan
from gcs_planner.core import lockstep
from gcs_planner.flight import FlyOptions, fly, networks
from gcs_planner.model.plan import Plan
from gcs_planner.planning import load_scenario, plan_scenario
from gcs_planner.safety.conformance import (
    SCHEDULE_STEP_S,
    Track,
    route_acceptance_m,
    route_window,
    schedule_errors_s,
)
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


class _Tracks:
    """Keeps the tracks and route starts the conformance report is given (the fly result has neither)."""

    def __init__(self) -> None:
        self.tracks: dict[int, Track] = {}
        self.route_t0_s: dict[int, float] = {}
        self._report = static_plan.conformance_report
        static_plan.conformance_report = self

    def __call__(self, plan, tracks, *args, route_t0_s=None, **kwargs):
        self.tracks, self.route_t0_s = tracks, dict(route_t0_s or {})
        return self._report(plan, tracks, *args, route_t0_s=route_t0_s, **kwargs)


def _time_errors(plan: Plan, seen: _Tracks, max_cross_track_m: float) -> dict[int, np.ndarray]:
    """sysid -> flown minus planned time [s] at the route's path points a second apart."""
    errors = {}
    for vp in plan.vehicles:
        tr = seen.tracks.get(vp.sysid)
        if tr is None or vp.sysid not in seen.route_t0_s:
            continue
        up = tr.positions[:, 2] >= 1.0
        tr = Track(tr.times_s[up], tr.positions[up])
        accept = route_acceptance_m(vp)
        window = route_window(tr, vp.path, accept)
        route = Track(tr.times_s[window], tr.positions[window])
        errors[vp.sysid] = schedule_errors_s(route, vp, seen.route_t0_s[vp.sysid], max_cross_track_m + accept)
    return errors


def _error_rows(errors: dict[int, np.ndarray]) -> list[tuple[str, str]]:
    e = np.concatenate([v[np.isfinite(v)] for v in errors.values()]) if errors else np.zeros(0)
    if not len(e):
        return []
    worst = np.array([np.nanmax(np.abs(v)) for v in errors.values() if np.isfinite(v).any()])
    a = np.abs(e)
    q95, q99 = np.quantile(a, [0.95, 0.99])
    return [
        ("time error points (1 s apart)", len(e)),
        ("time error mean / median [s]", f"{e.mean():+.2f} / {np.median(e):+.2f}"),
        ("|time error| p95 / p99 / max [s]", f"{q95:.2f} / {q99:.2f} / {a.max():.2f}"),
        ("worst |error| per vehicle, median / max [s]", f"{np.median(worst):.2f} / {worst.max():.2f}"),
    ]  # fmt: skip


def _encounter_errors(plan: Plan, errors: dict[int, np.ndarray], within_m: float = 20.0) -> np.ndarray:
    """|e_a - e_b| [s] of every pair of vehicles planned within ``within_m`` of each other, at the
    planned time of each such moment (0.5 s grid): the time error that moves two vehicles toward
    each other where they meet."""
    step = 0.5
    t_end = max(float(vp.times_s[-1]) for vp in plan.vehicles)
    grid = np.arange(0.0, t_end + step, step)
    pos, err = [], []
    for vp in plan.vehicles:
        e = errors.get(vp.sysid)
        live = (grid >= vp.times_s[0]) & (grid <= vp.times_s[-1])
        p = np.full((len(grid), 3), np.nan)
        p[live] = np.stack([np.interp(grid[live], vp.path_times_s, vp.path[:, k]) for k in range(3)], 1)
        pos.append(p)
        pts = vp.times_s[0] + SCHEDULE_STEP_S * np.arange(0 if e is None else len(e))
        err.append(np.interp(grid, pts, e) if e is not None and len(e) else np.full(len(grid), np.nan))
    pos, err = np.stack(pos), np.stack(err)
    out = []
    for k in range(len(grid)):
        up = np.flatnonzero(np.isfinite(pos[:, k, 0]))
        if len(up) < 2:
            continue
        pairs = cKDTree(pos[up, k]).query_pairs(within_m, output_type="ndarray")
        if len(pairs):
            out.append(np.abs(err[up[pairs[:, 0]], k] - err[up[pairs[:, 1]], k]))
    d = np.concatenate(out) if out else np.zeros(0)
    return d[np.isfinite(d)]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--plan", type=Path, help="fly this plan.json (default: plan swarm500 first)")
    p.add_argument("--speedup", type=float, help="pace the mock at X x the wall clock [lockstep]")
    p.add_argument("--out", type=Path, default=Path("out/fly500"))
    p.add_argument("--vehicles", type=int, default=500)
    p.add_argument("--errors", type=Path, help="write each vehicle's time errors [s] here (JSON)")
    p.add_argument("--autopilot", choices=("ardupilot", "px4"), default="ardupilot", help="mock profile")
    args = p.parse_args()
    scenario = load_scenario(SCENARIO)
    args.out.mkdir(parents=True, exist_ok=True)
    t_plan = time.monotonic()
    plan = Plan.load(args.plan) if args.plan else plan_scenario(scenario)
    plan_s = time.monotonic() - t_plan
    plan.save(args.out / "plan.json")
    plan.vehicles = plan.vehicles[: args.vehicles]
    vehicles = MockVehicles(plan.vehicles, plan.origin, speedup=args.speedup, autopilot=args.autopilot)
    seen = _Tracks()
    options = FlyOptions(out_dir=args.out, rrd=False)
    cpu0, t0 = time.process_time(), time.monotonic()
    result = lockstep.run(fly(scenario, plan, options, vehicles), vehicles.lockstep)
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
        ("CPU [s] (this process: GCS, lockstep mock)", f"{cpu_s:.1f}"),
        ("CPU / wall", f"{cpu_s / wall_s:.2f}"),
        ("fly wall [s]", f"{wall_s:.1f}"),
        ("telemetry logged over [s, wall]", f"{log_s:.1f}"),
        ("clock", "lockstep" if args.speedup is None else f"paced, speed-up {args.speedup:g}"),
        ("mock autopilot", args.autopilot),
        ("mock lag events", vehicles.lag_events),
        ("planning wall [s]", f"{plan_s:.1f}" if not args.plan else "(saved plan)"),
    ]
    errors = _time_errors(plan, seen, options.max_cross_track_m)
    rows += _error_rows(errors)
    meet = _encounter_errors(plan, errors)
    if len(meet):
        q95, q99 = np.quantile(meet, [0.95, 0.99])
        rows.append(("|e_a - e_b| where planned < 20 m apart, p95 / p99 / max [s]",
                     f"{q95:.2f} / {q99:.2f} / {meet.max():.2f} ({len(meet)} pair samples)"))  # fmt: skip
    if args.errors:
        args.errors.write_text(json.dumps({str(k): [float(x) for x in v] for k, v in errors.items()}))
    width = max(len(name) for name, _ in rows)
    print(f"| {'swarm500 fly':<{width}} | value |\n|{'-' * (width + 2)}|-------|")
    for name, value in rows:
        print(f"| {name:<{width}} | {value} |")
    bad = [r for r in reports if not r.passed]
    for r in bad[:10]:
        print(f"sysid {r.sysid}: {'; '.join(r.failures[:2])}")


if __name__ == "__main__":
    main()
