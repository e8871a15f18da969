"""Conflict-free 4-D trajectories among manned traffic (seed 004), planner name ``deconflict_4d``.

Reads the scenario, builds the problem (UAV flight plans with timed take-off / arrival, dynamics
per vehicle type, manned aircraft tracks -> predicted no-fly zones), runs the staged method of
planner.py and returns a Plan whose vehicles carry the timed waypoints, per-leg speeds (for
DO_CHANGE_SPEED), the take-off delay and the densely sampled flown path.

On a ``[site]`` (gcs_planner.model.sites) the DEM is a flat floor under the UAVs (``_over_site``); the
planner does not route round static obstacles or no-fly zones, which the plan checker reports.

Scenario keys (besides the common ones of gcs_planner.model.scenario):
    [planner]      name = "deconflict_4d", seed, any Config field (planner.py), and
                   confidence (0.95), safety_m (manned safety distance, 5.0), min_mode_weight (0.01)
    [[vehicles]]   takeoff_s (planned take-off, 0), arrival_s (planned arrival at the goal; default
                   take-off + climb + straight distance / speed_mps), v_max_mps, a_max_mps2,
                   climb_mps, descent_mps, takeoff_settle_s, min_turn_radius_m, max_time_error_s,
                   limit ("axis"|"norm")
                   override the vehicle type's Dynamics (trajectory.DYNAMICS)
    [[manned]]     id, dt_s, and either track = [[t_s, x, y, z], ...] (observed, last at planning
                   time or before) or position_m + velocity_mps + observed_s (a constant-velocity
                   track observed for observed_s up to t = 0);
                   [[manned.modes]] name, velocity_mps, sigma_mps, strength, weight (prior per mode)
                   or history = [[[x, y, z], ...], ...] (tracks to fit the prior from)
"""

from __future__ import annotations

import dataclasses
import logging
import math
from typing import Any

import numpy as np

from gcs_planner.core.validation import (
    MAX_DURATION_S,
    MAX_RADIUS_M,
    MAX_SPEED_MPS,
    MIN_SPEED_MPS,
    InputError,
    number,
)
from gcs_planner.model.plan import Plan, VehiclePlan
from gcs_planner.model.scenario import Extensions, Scenario, ScenarioError
from gcs_planner.planning import Progress, Traits
from gcs_planner.planning.deconflict4d.manned import (
    MannedTrack,
    predict_zones,
    prior_from_history,
    prior_from_velocity,
)
from gcs_planner.planning.deconflict4d.planner import Config, Outcome, Problem, UavSpec, full_polyline, run
from gcs_planner.planning.deconflict4d.trajectory import DYNAMICS

__all__ = ["NAME", "TRAITS", "Config", "build_problem", "plan", "to_plan"]

NAME = "deconflict_4d"
log = logging.getLogger(__name__)
MIN_ACCEL_MPS2 = 0.01  # a vehicle slower to reach its speed is no vehicle
MAX_ACCEL_MPS2 = 1000.0  # 100 g
# a vehicle's dynamics keys with their ranges (core/validation.py: a rate below its floor makes a
# flight longer than a week, which the planner samples in time); "limit" is checked by Dynamics
_DYN_RANGES = {
    "v_max_mps": (MIN_SPEED_MPS, MAX_SPEED_MPS),
    "a_max_mps2": (MIN_ACCEL_MPS2, MAX_ACCEL_MPS2),
    "climb_mps": (MIN_SPEED_MPS, MAX_SPEED_MPS),
    "takeoff_settle_s": (0.0, MAX_DURATION_S),
    "descent_mps": (MIN_SPEED_MPS, MAX_SPEED_MPS),
    "min_turn_radius_m": (0.0, MAX_RADIUS_M),
    "max_time_error_s": (0.0, MAX_DURATION_S),
}
_DYN_KEYS = (*_DYN_RANGES, "limit")
# a vehicle's schedule (take-off and arrival times) and dynamics
TRAITS = Traits(
    separation=True,
    reads=("obstacles", "bounds", "manned", "site"),
    extensions=Extensions(vehicle_keys=("takeoff_s", "arrival_s", *_DYN_KEYS)),
)


def check_options(scenario: Scenario, config: Config) -> dict:
    """The one checker skips the scenario vehicles' turn radius, speed and climb angle: the 4-D
    planner's own dynamics (v_max, a_max, climb rates) hold its paths. Obstacles, separation,
    band and site hold."""
    del scenario, config
    return {"kinematics": False, "max_climb_rad": math.pi / 2}


def plan(
    scenario: Scenario, config: Config, rng: np.random.Generator, progress: Progress | None = None
) -> Plan:
    problem = build_problem(scenario, config)
    return to_plan(scenario, problem, run(problem, rng, progress))


def _uav(scenario: Scenario, i: int) -> UavSpec:
    v = scenario.vehicles[i]
    raw = scenario.raw.get("vehicles", [])[i]
    where = f"{scenario.name}: vehicles[{i}]"
    try:
        overrides = {k: number(raw[k], f"{where}.{k}", *_DYN_RANGES[k]) for k in _DYN_RANGES if k in raw}
        takeoff = number(raw.get("takeoff_s", 0.0), f"{where}.takeoff_s", 0.0, MAX_DURATION_S)
        given_arrival = raw.get("arrival_s")
        if given_arrival is not None:
            given_arrival = number(given_arrival, f"{where}.arrival_s", 0.0, MAX_DURATION_S)
    except InputError as exc:
        raise ScenarioError(str(exc)) from None
    if "limit" in raw:
        overrides["limit"] = raw["limit"]
    if v.type == "fixed_wing" and "min_turn_radius_m" not in overrides:
        overrides["min_turn_radius_m"] = v.turn_radius_m
    try:
        dyn = dataclasses.replace(DYNAMICS[v.type], **overrides)
    except (TypeError, ValueError) as exc:
        raise ScenarioError(f"{where}: {exc}") from None
    start, goal = np.asarray(v.start, dtype=float), np.asarray(v.goal, dtype=float)
    if dyn.vertical_takeoff and (start[2] <= 0 or goal[2] <= 0):
        raise ScenarioError(
            f"{where}: start/goal z must be > 0 (the climb is planned), got {v.start} / {v.goal}"
        )
    climb = start[2] / dyn.climb_mps + dyn.takeoff_settle_s if dyn.vertical_takeoff else 0.0
    arrival = given_arrival
    if arrival is None:
        arrival = takeoff + climb + float(np.linalg.norm(goal - start)) / v.speed_mps
        if arrival > MAX_DURATION_S:
            raise ScenarioError(f"{where}: the flight ends after {arrival / 86_400:.3g} days (at most 7)")
    if not arrival > takeoff + climb:
        raise ScenarioError(
            f"{where}: arrival_s must be after take-off + climb ({takeoff + climb:.1f} s), got {arrival}"
        )
    return UavSpec(
        id=v.id,
        sysid=v.sysid,
        vehicle_type=v.type,
        start=start,
        goal=goal,
        takeoff_s=takeoff,
        arrival_s=arrival,
        separation_m=v.separation_m,
        dyn=dyn,
        z_min_m=v.min_alt_m,
        z_max_m=v.max_alt_m,
    )


def _manned_track(d: dict[str, Any], where: str) -> MannedTrack:
    dt = float(d.get("dt_s", 1.0))
    if "track" in d:
        arr = np.asarray(d["track"], dtype=float)
        if arr.ndim != 2 or arr.shape[1] != 4:
            raise ScenarioError(f"{where}: track must be [[t_s, x, y, z], ...], got shape {arr.shape}")
        times, pos = arr[:, 0], arr[:, 1:]
    else:
        try:
            p0 = np.asarray(d["position_m"], dtype=float)
            vel = np.asarray(d["velocity_mps"], dtype=float)
            observed = float(d.get("observed_s", 10.0))
        except KeyError as exc:
            raise ScenarioError(
                f"{where}: needs track or position_m + velocity_mps (missing {exc})"
            ) from None
        times = np.arange(-round(observed / dt), 1) * dt
        pos = p0 + times[:, None] * vel
    modes = []
    for k, m in enumerate(d.get("modes", [])):
        name = str(m.get("name", f"mode{k}"))
        if "history" in m:
            prior = prior_from_history([np.asarray(t, dtype=float) for t in m["history"]], dt)
        else:
            try:
                prior = prior_from_velocity(
                    m["velocity_mps"], m["sigma_mps"], float(m.get("strength", 10.0)), dt
                )
            except KeyError as exc:
                raise ScenarioError(
                    f"{where}: modes[{k}] needs velocity_mps and sigma_mps (missing {exc})"
                ) from None
        modes.append((name, prior, float(m.get("weight", 1.0))))
    if not modes:
        raise ScenarioError(f"{where}: needs at least one [[manned.modes]] prior")
    try:
        return MannedTrack(str(d.get("id", where)), times, pos, dt, tuple(modes))
    except ValueError as exc:
        raise ScenarioError(f"{where}: {exc}") from None


def build_problem(scenario: Scenario, config: Config) -> Problem:
    """Scenario -> Problem (settings, UAV specs, manned no-fly zones, waypoint box)."""
    settings = config
    if not scenario.vehicles:
        raise ScenarioError(f"{scenario.name}: deconflict_4d needs at least one [[vehicles]] entry")
    uavs = [_uav(scenario, i) for i in range(len(scenario.vehicles))]
    ends = np.array([p for u in uavs for p in (u.start, u.goal)])
    extent = ends.max(axis=0) - ends.min(axis=0)
    pad = np.maximum(20.0, 0.25 * extent.max())
    lower, upper = ends.min(axis=0) - pad, ends.max(axis=0) + pad
    for k, axis in enumerate("xy"):
        if axis in scenario.bounds:
            lo, hi = scenario.bounds[axis]
            if scenario.site is not None:  # a site's area box holds the UAVs' own box (and its floor)
                if lower[k] > hi or upper[k] < lo:
                    raise ScenarioError(
                        f"{scenario.name}: the vehicles' starts and goals ({axis} {lower[k] + pad:.0f}.."
                        f"{upper[k] - pad:.0f} m) are outside the site's area ({axis} {lo:.0f}..{hi:.0f} m)"
                    )
                lower[k], upper[k] = max(lower[k], lo), min(upper[k], hi)
            else:
                lower[k], upper[k] = lo, hi
    if scenario.site is not None:
        uavs = _over_site(scenario, uavs, lower, upper)
    # zones must cover the latest instant any UAV can be airborne
    horizon = max(
        u.arrival_s + settings.max_delay_s + 3.0 * (u.arrival_s - u.takeoff_s) + u.goal[2] / u.dyn.descent_mps
        for u in uavs
    )
    zones = []
    for j, d in enumerate(scenario.raw.get("manned", [])):
        track = _manned_track(d, f"{scenario.name}: manned[{j}]")
        zones += predict_zones(
            track,
            j,
            horizon,
            config.safety_m,
            config.confidence,
            config.min_mode_weight,
            settings.zone_step_s,
        )
    if scenario.cylinders or scenario.hemispheres:  # said once the input is checked: bad input is one line
        log.warning(
            "deconflict_4d ignores static obstacles and no-fly zones (cylinders / hemispheres) in %s;"
            " the plan checker reports any it crosses",
            scenario.name,
        )
    return Problem(uavs=uavs, zones=zones, settings=settings, lower_m=lower, upper_m=upper)


def _over_site(
    scenario: Scenario, uavs: list[UavSpec], lower: np.ndarray, upper: np.ndarray
) -> list[UavSpec]:
    """A site's terrain as a flat floor: each UAV's lowest altitude is raised to the highest DEM
    ground in the waypoint box + clearance + margin (the planner has no terrain model); a start or
    goal below that floor is refused."""
    site = scenario.site
    if site.terrain is None:
        return uavs
    step = abs(site.terrain.geotransform[1]) / 2
    gx, gy = np.meshgrid(
        np.arange(lower[0], upper[0] + step, step), np.arange(lower[1], upper[1] + step, step)
    )
    floor = float(site.ground(gx, gy).max()) + site.clearance_m + site.margin_m
    out = []
    for u in uavs:
        low = min(u.start[2], u.goal[2])
        if low < floor or floor > u.z_max_m:
            raise ScenarioError(
                f"{scenario.name}: vehicle {u.id}: start / goal z {low:g} m is under the site's terrain floor"
                f" for deconflict_4d, {floor:.1f} m (highest ground in its box + clearance + margin)"
            )
        out.append(dataclasses.replace(u, z_min_m=max(u.z_min_m, floor)))
    return out


def to_plan(scenario: Scenario, problem: Problem, out: Outcome) -> Plan:
    """Outcome -> Plan: timed waypoints, per-leg speeds, take-off delay, dense path per UAV."""
    in_conflict = {c["a"] for c in out.remaining} | {c["b"] for c in out.remaining}
    in_conflict |= {c["a"] for c in out.metrics["dense_check"]["conflicts"]}
    vehicles = []
    for u, tr, (path, path_t) in zip(problem.uavs, out.tracks, out.paths, strict=True):
        _, times, goal_idx = full_polyline(u, tr)
        off = 1 if u.dyn.vertical_takeoff else 0
        wp_times = times[off : goal_idx + 1]
        legs = np.linalg.norm(np.diff(tr.waypoints, axis=0), axis=1) / np.diff(wp_times)
        first = u.start[2] / (wp_times[0] - times[0]) if u.dyn.vertical_takeoff else legs[0]
        notes = [f"planned take-off {u.takeoff_s:.1f} s, delayed by {tr.delay_s:.1f} s"] if tr.delay_s else []
        if u.id in in_conflict:
            notes.append("conflicts remain: see plan metrics conflicts_remaining")
        if u.id in out.metrics["limit_violations"]:
            notes.append(f"outside its limits: {out.metrics['limit_violations'][u.id]}")
        vehicles.append(
            VehiclePlan(
                vehicle_id=u.id,
                sysid=u.sysid,
                vehicle_type=u.vehicle_type,
                waypoints=tr.waypoints,
                times_s=wp_times,
                speeds_mps=np.concatenate([[first], legs]),
                path=path,
                path_times_s=path_t,
                turn_radius_m=u.dyn.min_turn_radius_m,
                takeoff_delay_s=float(path_t[0]),
                cost={
                    "length_m": float(np.linalg.norm(np.diff(tr.waypoints, axis=0), axis=1).sum()),
                    "arrival_error_s": float(abs(wp_times[-1] - u.arrival_s)),
                    "delay_s": float(tr.delay_s),
                },
                feasible=u.id not in in_conflict and u.id not in out.metrics["limit_violations"],
                notes=notes,
            )
        )
    metrics = dict(out.metrics)
    metrics["manned"] = _manned_summary(scenario, problem)
    return Plan(origin=scenario.origin, planner=NAME, vehicles=vehicles, metrics=metrics, events=out.events)


def _manned_summary(scenario: Scenario, problem: Problem) -> list[dict]:
    """Per manned aircraft: last observation and the mean velocity of the most likely mode
    (the constant-velocity truth of the scenarios), plus its zones' largest semi-axis."""
    out = []
    for j, d in enumerate(scenario.raw.get("manned", [])):
        track = _manned_track(d, f"manned[{j}]")
        zones = [z for z in problem.zones if z.owner == j]
        best = max(zones, key=lambda z: z.weight)
        vel = (best.centres_m[1] - best.centres_m[0]) / (best.times_s[1] - best.times_s[0])
        out.append(
            {
                "id": track.id,
                "t0_s": float(track.times_s[-1]),
                "position_m": track.positions_m[-1].round(3).tolist(),
                "velocity_mps": vel.round(4).tolist(),
                "zones": [
                    {
                        "name": z.name,
                        "weight": round(z.weight, 4),
                        "max_semi_axis_m": round(float(z.axes_m.max()), 2),
                    }
                    for z in zones
                ],
                "horizon_s": float(best.times_s[-1]),
                "observed_velocity_mps": (track.displacements.mean(axis=0) / track.dt_s).round(4).tolist(),
            }
        )
    return out
