"""Conformance of flown tracks to a plan: did each vehicle do what was planned, safely?

Pure numpy over arrays of logged positions (local ENU metres, seconds), so the same report runs
live after `gcs-planner fly` and offline on a replayed log.

Choices:
- Cross-track deviation is the 3-D distance from each flown sample to the planned (smoothed)
  path polyline. It is measured only while the vehicle flies its route: from the first sample
  within ``acceptance_m`` of the first planned point to the last sample within ``acceptance_m``
  of the final planned point (take-off climb and landing are not part of the planned path).
  ``acceptance_m`` defaults to the plan's waypoint acceptance radius + 1 m.
- Separation is checked on a common time grid (``step_s``, default 0.1 s) after linear
  interpolation of each airborne track; exact to the distance flown in one step.
- Obstacle clearance is the distance outside the obstacle's surface (cylinder radius without its
  planning buffer, hemisphere radius); negative means inside.
- Manned traffic (MovingObstacle) is checked at every flown sample against its true,
  constant-velocity track; the bound is its own ``min_distance_m``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from gcs_planner.plan import Plan
from gcs_planner.scenario import Cylinder, Hemisphere

__all__ = [
    "MovingObstacle",
    "Track",
    "VehicleReport",
    "conformance_report",
    "format_report",
    "point_to_polyline_m",
]


@dataclass
class Track:
    """A flown track: times [s] and ENU positions [m], plus mission progress seen in flight."""

    times_s: np.ndarray
    positions: np.ndarray
    mission_completed: bool = False


@dataclass(frozen=True)
class MovingObstacle:
    """Other traffic (e.g. a manned aircraft) at ``position_m`` at ``t0_s``, at constant velocity."""

    name: str
    position_m: tuple[float, float, float]
    velocity_mps: tuple[float, float, float]
    t0_s: float
    min_distance_m: float

    def positions(self, times_s: np.ndarray) -> np.ndarray:
        dt = np.asarray(times_s, dtype=float)[:, None] - self.t0_s
        return np.asarray(self.position_m) + dt * np.asarray(self.velocity_mps)


@dataclass
class VehicleReport:
    vehicle_id: str
    sysid: int
    completed: bool
    cross_track_max_m: float
    cross_track_mean_m: float
    min_separation_m: float
    min_obstacle_clearance_m: float
    min_traffic_distance_m: float
    flight_time_s: float
    planned_time_s: float
    failures: list[str] = field(default_factory=list)

    @property
    def passed(self) -> bool:
        return not self.failures


def point_to_polyline_m(points: np.ndarray, polyline: np.ndarray, chunk: int = 4096) -> np.ndarray:
    """Distance [m] from each of (N, 3) points to the (M, 3) polyline, vectorised in chunks."""
    points = np.asarray(points, dtype=float)
    polyline = np.asarray(polyline, dtype=float)
    if len(polyline) == 1:
        return np.linalg.norm(points - polyline[0], axis=1)
    a, b = polyline[:-1], polyline[1:]
    ab = b - a
    ab2 = np.maximum((ab**2).sum(axis=1), 1e-12)
    out = np.empty(len(points))
    for lo in range(0, len(points), chunk):
        p = points[lo : lo + chunk, None, :]
        t = np.clip(((p - a) * ab).sum(axis=2) / ab2, 0.0, 1.0)
        d2 = ((a + t[..., None] * ab - p) ** 2).sum(axis=2)
        out[lo : lo + chunk] = np.sqrt(d2.min(axis=1))
    return out


def route_acceptance_m(vp, acceptance_m: float | None = None) -> float:
    """How near the route's first / last point counts as there: the plan's radius + 1 m."""
    return vp.acceptance_radius_m + 1.0 if acceptance_m is None else acceptance_m


def route_window(track: Track, planned: np.ndarray, acceptance_m: float) -> slice:
    """Samples from leaving the route's first point to reaching its last one.

    Leaving is the last sample of the first stay within ``acceptance_m`` of the first point
    (a vehicle may hover there until its start time); reaching is the first sample within
    ``acceptance_m`` of the last point. Where the telemetry rate left no sample that close, the
    closest sample stands in.
    """
    d_start = np.linalg.norm(track.positions - planned[0], axis=1)
    near = d_start <= acceptance_m
    if near.any():
        first = int(np.argmax(near))
        away = np.flatnonzero(~near[first:])
        start = first + (int(away[0]) - 1 if len(away) else len(near) - 1 - first)
    else:
        start = int(np.argmin(d_start))
    d_end = np.linalg.norm(track.positions[start:] - planned[-1], axis=1)
    reached = np.flatnonzero(d_end <= acceptance_m)
    end = start + (int(reached[0]) if len(reached) else int(np.argmin(d_end)))
    return slice(start, end + 1)


def _obstacle_clearance_m(positions: np.ndarray, cylinders, hemispheres) -> float:
    clearance = np.inf
    for c in cylinders:
        inside_band = (positions[:, 2] >= c.z_min_m) & (positions[:, 2] <= c.z_max_m)
        if inside_band.any():
            d = np.hypot(positions[inside_band, 0] - c.x, positions[inside_band, 1] - c.y) - c.radius_m
            clearance = min(clearance, float(d.min()))
    for h in hemispheres:
        d = np.linalg.norm(positions - np.array([h.x, h.y, h.z]), axis=1) - h.radius_m
        clearance = min(clearance, float(d.min()))
    return clearance


def _min_separation_m(tracks: dict[int, Track], step_s: float) -> dict[int, float]:
    """Smallest distance from each vehicle to any other, over their common airborne time."""
    ids = list(tracks)
    result = {i: np.inf for i in ids}
    if len(ids) < 2:
        return result
    t0 = min(float(tr.times_s[0]) for tr in tracks.values())
    t1 = max(float(tr.times_s[-1]) for tr in tracks.values())
    grid = np.arange(t0, t1 + step_s, step_s)
    pos = np.full((len(ids), len(grid), 3), np.nan)
    for k, i in enumerate(ids):
        tr = tracks[i]
        live = (grid >= tr.times_s[0]) & (grid <= tr.times_s[-1])
        for axis in range(3):
            pos[k, live, axis] = np.interp(grid[live], tr.times_s, tr.positions[:, axis])
    for k in range(len(ids)):
        d = np.linalg.norm(pos[k + 1 :] - pos[k], axis=2)
        if d.size == 0 or np.all(np.isnan(d)):
            continue
        others = np.nanmin(d, axis=1)
        result[ids[k]] = min(result[ids[k]], float(np.nanmin(others)))
        for j, dmin in zip(ids[k + 1 :], others, strict=True):
            if np.isfinite(dmin):
                result[j] = min(result[j], float(dmin))
    return result


def conformance_report(
    plan: Plan,
    tracks: dict[int, Track],
    separation_m: dict[int, float],
    cylinders: list[Cylinder] = (),
    hemispheres: list[Hemisphere] = (),
    traffic: list[MovingObstacle] = (),
    max_cross_track_m: float = 15.0,
    acceptance_m: float | None = None,
    min_airborne_alt_m: float = 1.0,
    step_s: float = 0.1,
) -> list[VehicleReport]:
    """Per-vehicle report; ``failures`` lists every bound broken (empty = passed)."""
    airborne = {}
    for sysid, tr in tracks.items():
        up = tr.positions[:, 2] >= min_airborne_alt_m
        if up.sum() >= 2:
            airborne[sysid] = Track(tr.times_s[up], tr.positions[up], tr.mission_completed)
    separation = _min_separation_m(airborne, step_s)
    reports = []
    for vp in plan.vehicles:
        tr = airborne.get(vp.sysid)
        failures: list[str] = []
        if tr is None:
            reports.append(
                VehicleReport(
                    vp.vehicle_id,
                    vp.sysid,
                    False,
                    np.nan,
                    np.nan,
                    np.nan,
                    np.nan,
                    np.nan,
                    0.0,
                    float(vp.times_s[-1] - vp.times_s[0]),
                    ["never airborne"],
                )
            )
            continue
        accept = route_acceptance_m(vp, acceptance_m)
        window = route_window(tr, vp.path, accept)
        xt = point_to_polyline_m(tr.positions[window], vp.path)
        xt_max = float(xt.max()) if len(xt) else np.inf
        xt_mean = float(xt.mean()) if len(xt) else np.inf
        clearance = _obstacle_clearance_m(tr.positions, cylinders, hemispheres)
        if not tr.mission_completed:
            failures.append("mission not completed")
        if xt_max > max_cross_track_m:
            failures.append(f"cross-track {xt_max:.1f} m > {max_cross_track_m:.1f} m")
        bound = separation_m.get(vp.sysid, 0.0)
        if separation[vp.sysid] < bound:
            failures.append(f"separation {separation[vp.sysid]:.1f} m < {bound:.1f} m")
        if clearance < 0.0:
            failures.append(f"entered an obstacle by {-clearance:.1f} m")
        traffic_m = np.inf
        for other in traffic:
            d = float(np.linalg.norm(tr.positions - other.positions(tr.times_s), axis=1).min())
            traffic_m = min(traffic_m, d)
            if d < other.min_distance_m:
                failures.append(f"{other.name} within {d:.1f} m < {other.min_distance_m:.1f} m")
        reports.append(
            VehicleReport(
                vehicle_id=vp.vehicle_id,
                sysid=vp.sysid,
                completed=tr.mission_completed,
                cross_track_max_m=xt_max,
                cross_track_mean_m=xt_mean,
                min_separation_m=separation[vp.sysid],
                min_obstacle_clearance_m=clearance,
                min_traffic_distance_m=traffic_m,
                flight_time_s=float(tr.times_s[window][-1] - tr.times_s[window][0]) if len(xt) else 0.0,
                planned_time_s=float(vp.times_s[-1] - vp.times_s[0]),
                failures=failures,
            )
        )
    return reports


def format_report(reports: list[VehicleReport]) -> str:
    """The report as a fixed-width table, one row per vehicle."""
    head = (
        f"{'vehicle':<8} {'sysid':>5} {'done':>5} {'xt_max_m':>9} {'xt_mean_m':>9} {'min_sep_m':>9}"
        f" {'clear_m':>8} {'traffic_m':>9} {'flown_s':>8} {'plan_s':>7}  result"
    )
    rows = [head]
    for r in reports:
        verdict = "PASS" if r.passed else "; ".join(r.failures)
        rows.append(
            f"{r.vehicle_id:<8} {r.sysid:>5} {'yes' if r.completed else 'no':>5} {r.cross_track_max_m:>9.2f}"
            f" {r.cross_track_mean_m:>9.2f} {r.min_separation_m:>9.1f} {r.min_obstacle_clearance_m:>8.1f}"
            f" {r.min_traffic_distance_m:>9.1f} {r.flight_time_s:>8.1f} {r.planned_time_s:>7.1f}  {verdict}"
        )
    return "\n".join(rows)
