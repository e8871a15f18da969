"""Conformance of flown tracks to a plan: did each vehicle do what was planned, safely?

Pure numpy over arrays of logged positions (local ENU metres, seconds), so the same report runs
live after `gcs-planner fly` and offline on a replayed log.

Choices:
- Cross-track deviation is the 3-D distance from each flown sample to the planned (smoothed)
  path polyline. It is measured only while the vehicle flies its route: from the first sample
  within ``acceptance_m`` of the first planned point to the last sample within ``acceptance_m``
  of the final planned point (take-off climb and landing are not part of the planned path).
  ``acceptance_m`` defaults to the plan's waypoint acceptance radius + 1 m.
- Separation and obstacle clearance use the plan checker's geometry (gcs_planner.geometry): each
  airborne track's closest approach to any other is solved exactly for linear motion between
  samples on slices of ``step_s`` (default 0.1 s), and the clearance is ``Obstacles.clearance``
  of each flown sample: the distance outside the obstacle's surface (cylinder radius without its
  planning buffer, hemisphere radius); negative means inside.
- Manned traffic (MovingObstacle) is checked at every flown sample against its true,
  constant-velocity track; the bound is its own ``min_distance_m``.
- Schedule: a deconflicted plan is separated in time as much as in space, so each vehicle's
  along-track time error is bounded. At every planned path point (one per ``SCHEDULE_STEP_S`` of
  plan time) the vehicle's time of closest approach is taken, in order along the route, and
  compared with the route start plus the point's planned time (see ``schedule_errors_s``). A
  multirotor whose speed ramp is known (``ramps``) starts its route from the hover, early by what
  the ramp loses (flight.ops.accel_lead_s), and brakes to a stop at its end: the points within
  its ramp's distance of the start are due that much earlier, those within it of the end that
  much later (geometry.ramp.stop_lag_s, the braking run backwards being the start).
  Telemetry that does not show the route flown in order is a failure, never a pass.
- On a site (gcs_planner.model.sites) the flown route (the cross-track window) is held to what the
  plan checker proved on the plan: inside the area, out of every no-fly zone's polygon and band,
  and ``terrain_clearance_m`` above the DEM (gcs_planner.model.sites.checks).
- A NaN (no data, impossible positions) is never within a bound: every comparison fails on it.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from gcs_planner.geometry.obstacles import Obstacles
from gcs_planner.geometry.ramp import stop_lag_s
from gcs_planner.model.plan import Plan, land_point
from gcs_planner.model.scenario import Cylinder, Hemisphere
from gcs_planner.safety.separation import Trajectory, closest_approach_m

if TYPE_CHECKING:  # shapely is imported only for a site
    from gcs_planner.model.sites.world import Site

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
    schedule_error_s: float = np.nan  # the worst along-track time error, signed (+ = late) [s]
    touchdown_m: float = np.nan  # where it landed after the route, from the planned land point [m]

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


SCHEDULE_STEP_S = 1.0  # planned time between the path points the schedule is checked at [s]
PASS_TOLERANCE_M = 3.0  # samples this much farther than a stretch's closest still belong to a pass
MAX_SCHEDULE_ERROR_S = 3.0  # default bound on the along-track time error [s] (docs/real-autopilots.md)


def schedule_errors_s(
    track: Track,
    vp,
    route_t0_s: float,
    near_m: float,
    ramp: tuple[float, float] | None = None,
    reached_m: float = 0.0,
) -> np.ndarray:
    """Flown minus planned time at path points ``SCHEDULE_STEP_S`` apart from the first waypoint's
    time to the last one's (+ = late) [s]; a plan's climb and descent, flown at the vehicle's own
    pace before and after its route, are not timed. ``ramp``: (acceleration, jerk) of the S-curve
    the vehicle leaves its start and brakes to its final stop on (module docstring);
    ``reached_m``: how near its ends the track's route begins and ends (route_window), where the
    first and last points are met, so their ramp times are taken there.

    Each point's flown time is that of a pass of the track near it, searched in the first stretch
    of samples within ``near_m`` after the previous point's match (so a route that passes a place
    twice is matched in order). A stretch can hold two passes where the route loops inside
    ``near_m`` of the point; its passes are the runs of samples within ``PASS_TOLERANCE_M`` of the
    stretch's closest, and the one nearest in time to the schedule (the planned time plus the
    previous point's error) is taken, at its closest sample. A point never come near is NaN.
    """
    times = np.arange(vp.times_s[0], vp.times_s[-1] + 1e-9, SCHEDULE_STEP_S)
    points = np.stack([np.interp(times, vp.path_times_s, vp.path[:, k]) for k in range(3)], axis=1)
    due = times
    if ramp is not None:
        arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(vp.path, axis=0), axis=1))])
        done = np.interp(times, vp.path_times_s, arc)
        early = stop_lag_s(np.maximum(done, reached_m), vp.first_leg_speed_mps, *ramp)
        late = stop_lag_s(np.maximum(arc[-1] - done, reached_m), float(vp.speeds_mps[-1]), *ramp)
        due = times - early + late
    errors = np.full(len(times), np.nan)
    i, last_error = 0, 0.0
    for k, (point, planned_s) in enumerate(zip(points, due)):
        d = np.linalg.norm(track.positions[i:] - point, axis=1)
        near = np.flatnonzero(d <= near_m)
        if not len(near):
            continue
        leave = np.flatnonzero(d[near[0] :] > near_m)
        stretch = d[near[0] : near[0] + (int(leave[0]) if len(leave) else len(d) - near[0])]
        close = stretch <= stretch.min() + PASS_TOLERANCE_M
        starts = np.flatnonzero(close & ~np.concatenate([[False], close[:-1]]))
        ends = np.flatnonzero(close & ~np.concatenate([close[1:], [False]])) + 1
        passes = [a + int(np.argmin(stretch[a:b])) for a, b in zip(starts, ends, strict=True)]
        due_s = route_t0_s + planned_s + last_error
        i += int(near[0] + min(passes, key=lambda j: abs(track.times_s[i + near[0] + j] - due_s)))
        errors[k] = last_error = track.times_s[i] - (route_t0_s + planned_s)
    return errors


def _obstacle_clearance_m(positions: np.ndarray, cylinders, hemispheres) -> float:
    """The flown samples' smallest clearance [m] from any obstacle surface (< 0: inside)."""
    return float(Obstacles.from_scenario(cylinders, hemispheres).clearance(positions, positions).min())


def _site_failures(site: Site, route: np.ndarray) -> list[str]:
    """Where the flown route leaves the site's area, enters its no-fly zones or comes closer to
    its terrain than the clearance, one phrase each."""
    from gcs_planner.model.sites.checks import area_exit, terrain_shortfall, zone_entries

    found = []
    if (where := area_exit(site, route)) is not None:
        found.append(f"left the site's area at ({where[0]:.0f}, {where[1]:.0f}) m")
    found += [f"entered no-fly zone {name!r}" for name in zone_entries(site, route)]
    if (short := terrain_shortfall(site, route, np.zeros(len(route) - 1, dtype=bool))) > 0:
        found.append(f"flew {short:.1f} m under the terrain clearance ({site.clearance_m:g} m)")
    return found


def _min_separation_m(tracks: dict[int, Track], step_s: float) -> dict[int, float]:
    """Smallest distance from each vehicle to any other, over their common airborne time."""
    trajs = [Trajectory(str(i), tr.times_s, tr.positions) for i, tr in tracks.items()]
    return {i: float(d) for i, d in zip(tracks, closest_approach_m(trajs, step_s), strict=True)}


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
    route_t0_s: Mapping[int, float] | None = None,
    max_schedule_error_s: float = MAX_SCHEDULE_ERROR_S,
    site: Site | None = None,
    ramps: Mapping[int, tuple[float, float]] | None = None,
) -> list[VehicleReport]:
    """Per-vehicle report; ``failures`` lists every bound broken (empty = passed). ``route_t0_s``:
    sysid -> when its route's time 0 was, on the tracks' clock (None: no schedule is checked);
    ``site``: the scenario's site, whose area, zones and terrain clearance the route keeps;
    ``ramps``: sysid -> (acceleration, jerk) of a multirotor's speed ramps (schedule_errors_s)."""
    airborne = {}
    for sysid, tr in tracks.items():
        up = tr.positions[:, 2] >= min_airborne_alt_m
        if up.sum() >= 2:
            airborne[sysid] = Track(tr.times_s[up], tr.positions[up], tr.mission_completed)
    separation = _min_separation_m(airborne, step_s)
    reports = []
    for vp in plan.vehicles:
        tr = airborne.get(vp.sysid)
        if tr is None:
            planned_s, nan = float(vp.times_s[-1] - vp.times_s[0]), np.nan
            reports.append(VehicleReport(vp.vehicle_id, vp.sysid, False, nan, nan, nan, nan, nan, 0.0,
                                         planned_s, ["never airborne"]))  # fmt: skip
            continue
        accept = route_acceptance_m(vp, acceptance_m)
        window = route_window(tr, vp.path, accept)
        xt = point_to_polyline_m(tr.positions[window], vp.path)
        xt_max = float(xt.max()) if len(xt) else np.inf
        failures: list[str] = []
        if not tr.mission_completed:
            failures.append("mission not completed")
        if not xt_max <= max_cross_track_m:
            failures.append(f"cross-track {xt_max:.1f} m > {max_cross_track_m:.1f} m")
        late_s = np.nan
        if route_t0_s is not None:
            route = Track(tr.times_s[window], tr.positions[window])
            ramp = (ramps or {}).get(vp.sysid) if vp.vehicle_type == "multirotor" else None
            late_s, problem = _schedule_verdict(route, vp, route_t0_s[vp.sysid], max_cross_track_m + accept,
                                                max_schedule_error_s, ramp, accept)  # fmt: skip
            failures += [problem] if problem else []
        clearance = _obstacle_clearance_m(tr.positions, cylinders, hemispheres)
        traffic_m = _traffic_m(tr, traffic, failures)
        bound = separation_m.get(vp.sysid, 0.0)
        if not separation[vp.sysid] >= bound:
            failures.append(f"separation {separation[vp.sysid]:.1f} m < {bound:.1f} m")
        if not clearance >= 0.0:
            failures.append(f"entered an obstacle by {-clearance:.1f} m")
        if site is not None and len(xt) > 1:
            failures += _site_failures(site, tr.positions[window])
        reports.append(
            VehicleReport(
                vehicle_id=vp.vehicle_id,
                sysid=vp.sysid,
                completed=tr.mission_completed,
                cross_track_max_m=xt_max,
                cross_track_mean_m=float(xt.mean()) if len(xt) else np.inf,
                min_separation_m=separation[vp.sysid],
                min_obstacle_clearance_m=clearance,
                min_traffic_distance_m=traffic_m,
                flight_time_s=float(tr.times_s[window][-1] - tr.times_s[window][0]) if len(xt) else 0.0,
                planned_time_s=float(vp.times_s[-1] - vp.times_s[0]),
                failures=failures,
                schedule_error_s=late_s,
                touchdown_m=_touchdown_m(tracks[vp.sysid], vp, tr.times_s[window][-1], min_airborne_alt_m),
            )
        )
    return reports


def _touchdown_m(track: Track, vp, route_end_s: float, ground_m: float) -> float:
    """Horizontal distance [m] from the plan's land point to the first report on the ground after
    the route; NaN when the plan does not land there or the vehicle did not come down."""
    if vp.final_action != "land":
        return np.nan
    down = np.flatnonzero((track.times_s > route_end_s) & (track.positions[:, 2] < ground_m))
    if not len(down):
        return np.nan
    return float(np.hypot(*(track.positions[down[0], :2] - land_point(vp)[:2])))


def _traffic_m(track: Track, traffic: list[MovingObstacle], failures: list[str]) -> float:
    """The nearest any traffic came [m]; each one within its bound is added to ``failures``."""
    nearest = np.inf
    for other in traffic:
        d = float(np.linalg.norm(track.positions - other.positions(track.times_s), axis=1).min())
        nearest = min(nearest, d)
        if not d >= other.min_distance_m:
            failures.append(f"{other.name} within {d:.1f} m < {other.min_distance_m:.1f} m")
    return nearest


def _schedule_verdict(
    track: Track,
    vp,
    route_t0_s: float,
    near_m: float,
    bound_s: float,
    ramp: tuple[float, float] | None,
    reached_m: float,
) -> tuple[float, str]:
    """(worst signed time error, the failure in words or '')."""
    errors = schedule_errors_s(track, vp, route_t0_s, near_m, ramp, reached_m)
    missed = int(np.isnan(errors).sum())
    if missed:
        return np.nan, f"route not flown in order: {missed} of {len(errors)} path points never come near"
    worst = float(errors[np.argmax(np.abs(errors))])
    if not abs(worst) <= bound_s:
        word = "late" if worst > 0 else "early"
        return worst, f"schedule {abs(worst):.1f} s {word} > {bound_s:.1f} s"
    return worst, ""


def format_report(reports: list[VehicleReport]) -> str:
    """The report as a fixed-width table, one row per vehicle."""
    head = (
        f"{'vehicle':<8} {'sysid':>5} {'done':>5} {'xt_max_m':>9} {'xt_mean_m':>9} {'min_sep_m':>9}"
        f" {'clear_m':>8} {'traffic_m':>9} {'flown_s':>8} {'plan_s':>7} {'late_s':>6} {'land_m':>6}  result"
    )
    rows = [head]
    for r in reports:
        verdict = "PASS" if r.passed else "; ".join(r.failures)
        rows.append(
            f"{r.vehicle_id:<8} {r.sysid:>5} {'yes' if r.completed else 'no':>5} {r.cross_track_max_m:>9.2f}"
            f" {r.cross_track_mean_m:>9.2f} {r.min_separation_m:>9.1f} {r.min_obstacle_clearance_m:>8.1f}"
            f" {r.min_traffic_distance_m:>9.1f} {r.flight_time_s:>8.1f} {r.planned_time_s:>7.1f}"
            f" {r.schedule_error_s:>6.1f} {r.touchdown_m:>6.1f}  {verdict}"
        )
    return "\n".join(rows)
