"""Time-parametrised trajectories, inter-vehicle separation and the independent plan checker.

Trajectories are piecewise linear in time between their samples (a plan's ``path`` /
``path_times_s``, seconds from the mission start with any take-off delay already included, as
VehiclePlan documents). A vehicle occupies the airspace only while it
flies, from its first to its last sample time: before take-off it is on the ground at its start,
after arrival it has landed (a choice: the scenario's goals are landing spots, not hover points).
A scenario entry may say how ``fly`` flies the vehicle instead (``Trajectory.from_plan``): with
``landing_mps`` a vehicle whose mission ends with a landing hovers at its goal for its
``landing_stop_s`` (the stop before a landing) and then occupies the column above its goal while it
descends at that rate; with ``waits_airborne`` it hovers at its start from route time 0
until its delayed departure.

Separation check (``find_conflicts``), exact for the piecewise-linear motion sampled every
``step_s`` (<= 0.5 s): on each time slice a cKDTree over the flying vehicles finds candidate
pairs within ``max separation + 2 v_max step_s`` (nothing farther can close the gap before the
next slice); for each candidate the closest approach of the two linearly moving points over the
slice interval is solved analytically. Between samples of the *plan* the true path is an arc, not a
chord; a 0.5 s sample step at 20 m/s on a 20 m radius arc has a chord error of 0.6 m, which the
planner covers with its separation margin.

``check_plan`` is the one safety checker (like OMPL's StateValidityChecker): ``plan_scenario``
runs every planner's plan through ``certify``, so ``VehiclePlan.feasible`` is its verdict and its
findings are the vehicle's notes; conformance measures flown tracks with the same functions.
It checks obstacle clearance (segments between path samples, buffers reported but not fatal), separation,
turn radius (circumradius of consecutive xy samples after inserting points so no segment exceeds
R/4: arcs sampled at <= R/4 are measured exactly, a polyline corner shows as a tiny radius),
climb angle, speed along the timed path and the altitude band. Vertical
take-off/landing columns directly above the start/goal are exempt from the band and climb limits.
A planner whose vehicle model is its own (``kinematics=False``) is not held to the turn radius and
speed; ``floor`` adds a planner's ground (terrain + its safe height) and
``hard_buffers`` makes cylinder buffers keep-out zones (a planner's ``check_options``,
gcs_planner.planning).
On a scenario with a ``[site]`` it also proves every path stays in the site's area, out of its
no-fly zones (their exact polygons and altitude bands) and above the DEM by the terrain clearance
(gcs_planner.model.sites.checks).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from gcs_planner.geometry.obstacles import Obstacles, altitude_violation
from gcs_planner.model.plan import Plan
from gcs_planner.model.scenario import Scenario

__all__ = [
    "CheckReport",
    "Conflict",
    "Trajectory",
    "certify",
    "check_plan",
    "closest_approach_m",
    "find_conflicts",
    "positions_at",
    "turn_radii",
]

MAX_STEP_S = 0.5


@dataclass(frozen=True)
class Trajectory:
    """One vehicle's timed path: times_s (M,) increasing, positions_m (M, 3)."""

    vehicle_id: str
    times_s: np.ndarray
    positions_m: np.ndarray
    separation_m: float = 0.0

    @property
    def t0(self) -> float:
        return float(self.times_s[0])

    @property
    def t_end(self) -> float:
        return float(self.times_s[-1])

    @property
    def max_speed_mps(self) -> float:
        dt = np.diff(self.times_s)
        dist = np.linalg.norm(np.diff(self.positions_m, axis=0), axis=1)
        ok = dt > 0
        return float((dist[ok] / dt[ok]).max()) if ok.any() else 0.0

    def position_at(self, t_s: np.ndarray) -> np.ndarray:
        """Positions (n, 3) at times t_s (n,); NaN where the vehicle is not flying."""
        t = np.atleast_1d(np.asarray(t_s, dtype=float))
        out = np.column_stack([np.interp(t, self.times_s, self.positions_m[:, k]) for k in range(3)])
        out[(t < self.t0) | (t > self.t_end)] = np.nan
        return out

    @classmethod
    def from_plan(
        cls,
        vp,
        separation_m: float = 0.0,
        landing_mps: float = 0.0,
        waits_airborne: bool = False,
        landing_stop_s: float = 0.0,
    ) -> Trajectory:
        """Trajectory of a VehiclePlan (path_times_s are seconds from the mission start, delay
        included), with its final landing descended at landing_mps (> 0) when it lands, after
        hovering landing_stop_s at its goal, and with waits_airborne its wait for a delayed
        departure hovered at its start."""
        times = np.asarray(vp.path_times_s, dtype=float)
        path = np.asarray(vp.path, dtype=float)
        if waits_airborne and times[0] > 0:
            times, path = np.insert(times, 0, 0.0), np.vstack([path[:1], path])
        if landing_mps > 0 and vp.final_action == "land" and path[-1, 2] > 0:
            goal = path[-1]
            stop = [times[-1] + landing_stop_s] if landing_stop_s > 0 else []
            times = np.concatenate([times, stop, [times[-1] + landing_stop_s + goal[2] / landing_mps]])
            path = np.vstack([path, np.repeat(goal[None], len(stop), axis=0), [goal[0], goal[1], 0.0]])
        return cls(vp.vehicle_id, times, path, separation_m)


@dataclass(frozen=True)
class Conflict:
    """Closest approach of two vehicles below the required separation."""

    i: int
    j: int
    t_s: float
    distance_m: float
    required_m: float


def positions_at(trajs: list[Trajectory], t_s: float) -> np.ndarray:
    """Positions (V, 3) of every trajectory at time t_s; NaN rows for vehicles not flying."""
    return np.vstack([tr.position_at(np.array([t_s])) for tr in trajs])


def _slice_approaches(trajs: list[Trajectory], step_s: float, radius_m: float | None):
    """Per time slice (<= step_s, every take-off and landing a boundary), the closest approach of
    each pair of vehicles flying all of it, solved exactly for their linear motion over the slice:
    yields (i, j, t, dist) arrays. ``radius_m`` prunes pairs farther apart at the slice start
    (cKDTree); None keeps every pair."""
    if step_s > MAX_STEP_S:
        raise ValueError(f"step_s must be <= {MAX_STEP_S} s, got {step_s}")
    if len(trajs) < 2:
        return
    t0 = min(tr.t0 for tr in trajs)
    t1 = max(tr.t_end for tr in trajs)
    ends = [tr.t0 for tr in trajs] + [tr.t_end for tr in trajs]
    times = np.union1d(np.append(np.arange(t0, t1, step_s), t1), ends)
    # every take-off and landing time is a slice boundary, so a vehicle flies all of a slice or none
    pos = np.full((len(times), len(trajs), 3), np.nan)  # (T, V, 3): NaN where a vehicle is not flying
    for v, tr in enumerate(trajs):  # interpolated over its flight only (Trajectory.position_at)
        w = slice(np.searchsorted(times, tr.t0, "left"), np.searchsorted(times, tr.t_end, "right"))
        for c in range(3):
            pos[w, v, c] = np.interp(times[w], tr.times_s, tr.positions_m[:, c])
    for k in range(len(times) - 1):
        flying = np.flatnonzero(~np.isnan(pos[k, :, 0]) & ~np.isnan(pos[k + 1, :, 0]))
        if len(flying) < 2:
            continue
        if radius_m is None:
            pairs = np.column_stack(np.triu_indices(len(flying), 1))
        else:
            pairs = cKDTree(pos[k, flying]).query_pairs(radius_m, output_type="ndarray")
        if not len(pairs):
            continue
        i, j = flying[pairs[:, 0]], flying[pairs[:, 1]]
        d0 = pos[k, j] - pos[k, i]
        dv = (pos[k + 1, j] - pos[k + 1, i]) - d0
        vv = np.sum(dv * dv, axis=1)
        tau = np.clip(-np.sum(d0 * dv, axis=1) / np.where(vv > 0, vv, 1.0), 0.0, 1.0)
        yield i, j, times[k] + tau * (times[k + 1] - times[k]), np.linalg.norm(d0 + tau[:, None] * dv, axis=1)


def find_conflicts(trajs: list[Trajectory], step_s: float = MAX_STEP_S) -> list[Conflict]:
    """Worst conflict per vehicle pair (closest approach < max of the two separations)."""
    if len(trajs) < 2:
        return []
    sep = np.array([tr.separation_m for tr in trajs])
    vmax = max(tr.max_speed_mps for tr in trajs)
    radius = sep.max() + 2.0 * vmax * step_s + 1e-9  # nothing farther can close the gap in a slice
    worst: dict[tuple[int, int], Conflict] = {}
    for i, j, t, dist in _slice_approaches(trajs, step_s, radius):
        need = np.maximum(sep[i], sep[j])
        for m in np.flatnonzero(dist < need):
            key = (int(i[m]), int(j[m]))
            if key not in worst or dist[m] < worst[key].distance_m:
                worst[key] = Conflict(key[0], key[1], float(t[m]), float(dist[m]), float(need[m]))
    return sorted(worst.values(), key=lambda c: (c.i, c.j))


def closest_approach_m(trajs: list[Trajectory], step_s: float = MAX_STEP_S) -> np.ndarray:
    """Each vehicle's closest approach [m] (V,) to any other over their common flying time (inf
    when it never flies beside another): the same slices and exact solution as find_conflicts."""
    out = np.full(len(trajs), np.inf)
    for i, j, _, dist in _slice_approaches(trajs, step_s, None):
        np.minimum.at(out, i, dist)
        np.minimum.at(out, j, dist)
    return out


def turn_radii(xy: np.ndarray) -> np.ndarray:
    """Circumradius [m] (M-2,) of each three consecutive xy points (inf when collinear)."""
    a, b, c = xy[:-2], xy[1:-1], xy[2:]
    ab = np.linalg.norm(b - a, axis=1)
    bc = np.linalg.norm(c - b, axis=1)
    ca = np.linalg.norm(a - c, axis=1)
    cross = np.abs((b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0])
    with np.errstate(divide="ignore", invalid="ignore"):
        r = ab * bc * ca / (2.0 * cross)
    return np.where(cross > 1e-9 * np.maximum(ab * bc, 1e-12), r, np.inf)


@dataclass
class CheckReport:
    """Per-vehicle findings of the independent checker; ``ok`` when nothing hard is violated."""

    collisions: dict[str, float] = field(default_factory=dict)  # vehicle -> min clearance [m] (< 0)
    buffer_intrusions: dict[str, float] = field(default_factory=dict)  # soft: min buffer clearance
    conflicts: list[tuple[str, str, float, float, float]] = field(default_factory=list)
    turn_radius: dict[str, float] = field(default_factory=dict)  # vehicle -> smallest radius [m]
    altitude: dict[str, float] = field(default_factory=dict)  # vehicle -> worst band excess [m]
    climb: dict[str, float] = field(default_factory=dict)  # vehicle -> worst climb angle [rad]
    timing: dict[str, float] = field(default_factory=dict)  # vehicle -> worst speed excess [m/s]
    outside_area: dict[str, tuple[float, float]] = field(default_factory=dict)  # site: where it leaves
    no_fly: dict[str, list[str]] = field(default_factory=dict)  # site: the zones it enters
    terrain: dict[str, float] = field(default_factory=dict)  # site or planner floor: worst shortfall [m]
    hard_buffers: bool = False  # buffer intrusions are violations (a planner's keep-out buffers)

    def bad_vehicles(self) -> set[str]:
        bad = set(self.collisions) | set(self.turn_radius) | set(self.altitude) | set(self.climb)
        bad |= set(self.timing) | set(self.outside_area) | set(self.no_fly) | set(self.terrain)
        bad |= set(self.buffer_intrusions) if self.hard_buffers else set()
        for a, b, *_ in self.conflicts:
            bad |= {a, b}
        return bad

    @property
    def ok(self) -> bool:
        return not self.bad_vehicles()

    def summary(self) -> str:
        if self.ok:
            return "all checks passed"
        parts = []
        for name in (
            "collisions",
            *(["buffer_intrusions"] if self.hard_buffers else []),
            "turn_radius",
            "altitude",
            "climb",
            "timing",
            "outside_area",
            "no_fly",
            "terrain",
        ):
            if getattr(self, name):
                parts.append(f"{name}: {sorted(getattr(self, name))}")
        if self.conflicts:
            parts.append(f"separation conflicts: {[(a, b, round(t, 1)) for a, b, t, *_ in self.conflicts]}")
        return "; ".join(parts)

    def findings(self, vehicle_id: str) -> list[str]:
        """What the checker found wrong with one vehicle, one phrase each (empty: it passed)."""
        v = vehicle_id
        out = [f"enters an obstacle by {-self.collisions[v]:.1f} m"] if v in self.collisions else []
        if self.hard_buffers and v in self.buffer_intrusions:
            out.append(f"enters an obstacle's buffer by {-self.buffer_intrusions[v]:.1f} m")
        out += [
            f"separation {d:.1f} m < {need:.1f} m from {b if a == v else a} at {t:.1f} s"
            for a, b, t, d, need in self.conflicts
            if v in (a, b)
        ]
        phrases = {
            "turn_radius": "turns at radius {:.1f} m, under its limit",
            "altitude": "leaves its altitude band by {:.1f} m",
            "climb": "climbs at {:.3f} rad, over the limit",
            "timing": "exceeds its speed by {:.1f} m/s (or times do not increase)",
            "terrain": "{:.1f} m under its terrain clearance",
        }
        out += [
            text.format(getattr(self, name)[v]) for name, text in phrases.items() if v in getattr(self, name)
        ]
        if v in self.outside_area:
            out.append("leaves the site's area at ({:.0f}, {:.0f}) m".format(*self.outside_area[v]))
        out += [f"enters no-fly zone {zone!r}" for zone in self.no_fly.get(v, [])]
        return out


def certify(plan: Plan, scenario: Scenario, **options) -> CheckReport:
    """Run the one checker on ``plan`` and make its verdict the plan's: each vehicle's ``feasible``
    is whether it passed, and each finding is a "check: ..." note. ``options``: check_plan's."""
    report = check_plan(plan, scenario, **options)
    for vp in plan.vehicles:
        found = report.findings(vp.vehicle_id)
        vp.feasible = not found
        vp.notes = [n for n in vp.notes if not n.startswith("check: ")] + [f"check: {f}" for f in found]
    return report


def check_plan(
    plan: Plan,
    scenario: Scenario,
    step_s: float = MAX_STEP_S,
    max_climb_rad: float = math.radians(30.0),
    radius_tol: float = 0.01,
    speed_tol: float = 0.05,
    kinematics: bool = True,
    floor: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
    hard_buffers: bool = False,
) -> CheckReport:
    """Check every vehicle's timed path (at <= step_s sampling) against the scenario's limits.

    kinematics: also hold each path to the scenario vehicle's turn radius and speed (False for a
    planner whose vehicle model is its own); floor(x, y): the lowest altitude allowed there;
    hard_buffers: a cylinder's buffer is keep-out, not only priced.
    """
    # a site's no-fly zones are checked as their polygons, not as the planners' cylinders round them
    cylinders = [c for c in scenario.cylinders if not c.zone]
    obstacles = Obstacles.from_scenario(cylinders, scenario.hemispheres)
    report = CheckReport(hard_buffers=hard_buffers)
    trajs = []
    for vp in plan.vehicles:
        veh = scenario.vehicle(vp.vehicle_id)
        traj = Trajectory.from_plan(vp, veh.separation_m)
        flown = Trajectory.from_plan(
            vp, veh.separation_m, veh.landing_mps, veh.waits_airborne, veh.landing_stop_s
        )
        trajs.append(_resample(flown, step_s))
        p = traj.positions_m
        a, b = p[:-1], p[1:]
        clear, buf = obstacles.clearances(a, b)
        if clear.size and clear.min() < 0:
            report.collisions[vp.vehicle_id] = float(clear.min())
        if buf.size and buf.min() < 0:
            report.buffer_intrusions[vp.vehicle_id] = float(buf.min())
        seg_col = _column_segments(p, veh.start, veh.goal)
        exempt = np.ones(len(p), dtype=bool)  # samples touched only by take-off/landing column segments
        exempt[:-1] &= seg_col
        exempt[1:] &= seg_col
        if floor is not None:
            short = float((floor(p[:, 0], p[:, 1]) - p[:, 2]).max(initial=0.0))
            if short > 1e-6:
                report.terrain[vp.vehicle_id] = max(short, report.terrain.get(vp.vehicle_id, 0.0))
        dxy = np.linalg.norm(np.diff(p[:, :2], axis=0), axis=1)
        climb = np.arctan2(np.abs(np.diff(p[:, 2])), dxy)[~seg_col]
        if climb.size and climb.max() > max_climb_rad + 1e-6:
            report.climb[vp.vehicle_id] = float(climb.max())
        if kinematics:
            _check_kinematics(report, vp, veh, traj, exempt, radius_tol=radius_tol, speed_tol=speed_tol)
        excess = altitude_violation(p[~exempt, 2], veh.min_alt_m, veh.max_alt_m)
        if excess.size and excess.max() > 1e-6:
            report.altitude[vp.vehicle_id] = float(excess.max())
        if scenario.site is not None:
            _check_site(report, scenario.site, vp.vehicle_id, p, seg_col)
    for c in find_conflicts(trajs, step_s):
        report.conflicts.append(
            (trajs[c.i].vehicle_id, trajs[c.j].vehicle_id, c.t_s, c.distance_m, c.required_m)
        )
    return report


def _check_kinematics(
    report: CheckReport, vp, veh, traj: Trajectory, exempt: np.ndarray, *, radius_tol: float, speed_tol: float
) -> None:
    """Turn radius and speed of one vehicle's path against its scenario limits."""
    p = traj.positions_m
    # near-duplicate xy samples (< 1 cm apart) make the circumradius ill-conditioned: drop them
    distinct = np.concatenate([np.linalg.norm(np.diff(p[:, :2], axis=0), axis=1) > 0.01, [True]])
    if veh.turn_radius_m > 0:  # 0: a multirotor that may turn on the spot
        dense, dense_exempt = _densify(p[distinct], exempt[distinct], 0.25 * veh.turn_radius_m)
        radii = turn_radii(dense[:, :2])
        radii = radii[~(dense_exempt[:-2] | dense_exempt[1:-1] | dense_exempt[2:])]
        if radii.size and radii.min() < veh.turn_radius_m * (1 - radius_tol):
            report.turn_radius[vp.vehicle_id] = float(radii.min())
    dt = np.diff(traj.times_s)
    speed = np.linalg.norm(np.diff(p, axis=0), axis=1) / np.where(dt > 0, dt, np.nan)
    fastest = np.inf if np.any(dt <= 0) else np.max(speed, initial=0.0)
    if fastest > veh.speed_mps * (1 + speed_tol):
        report.timing[vp.vehicle_id] = float(fastest - veh.speed_mps)


def _check_site(report: CheckReport, site, vehicle_id: str, p: np.ndarray, columns: np.ndarray) -> None:
    """A site's area, no-fly zones and terrain clearance for one path (gcs_planner.model.sites.checks)."""
    from gcs_planner.model.sites.checks import area_exit, terrain_shortfall, zone_entries

    if (where := area_exit(site, p)) is not None:
        report.outside_area[vehicle_id] = where
    if zones := zone_entries(site, p):
        report.no_fly[vehicle_id] = zones
    if (short := terrain_shortfall(site, p, columns)) > 1e-6:
        report.terrain[vehicle_id] = short


def _resample(traj: Trajectory, step_s: float) -> Trajectory:
    """Add samples so consecutive samples are <= step_s apart (keeps the original ones)."""
    t = traj.times_s
    extra = np.arange(t[0], t[-1], step_s)
    times = np.union1d(t, extra)
    return Trajectory(traj.vehicle_id, times, traj.position_at(times), traj.separation_m)


def _densify(p: np.ndarray, flag: np.ndarray, spacing_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Insert points so no segment is longer than spacing_m in xy; inserted points inherit both ends' flag."""
    seg = np.linalg.norm(np.diff(p[:, :2], axis=0), axis=1)  # horizontal: the turn test is planar
    n = np.maximum(1, np.ceil(seg / (1.01 * spacing_m)).astype(int))
    idx = np.repeat(np.arange(len(seg)), n)
    first = np.cumsum(n) - n  # each segment's first inserted point
    frac = (np.arange(len(idx)) - first[idx]).astype(float) / n[idx]  # k / n_seg, k = 0 .. n_seg - 1
    pts = p[idx] + frac[:, None] * (p[idx + 1] - p[idx])
    flags = np.where(frac == 0, flag[idx], flag[idx] & flag[idx + 1])
    return np.vstack([pts, p[-1:]]), np.append(flags, flag[-1])


def _column_segments(p: np.ndarray, start, goal) -> np.ndarray:
    """Segments (M-1,) on the vertical take-off/landing column exactly above the start or the goal."""
    out = np.zeros(len(p) - 1, dtype=bool)
    for c in (start, goal):
        on = np.hypot(p[:, 0] - c[0], p[:, 1] - c[1]) < 1e-6
        out |= on[:-1] & on[1:]
    return out
