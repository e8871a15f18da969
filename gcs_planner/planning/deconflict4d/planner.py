"""The staged deconfliction method of seed 004: joint PSO, delayed take-off, waypoint insertion.

Stages (paper, steps 3-6), each stopping as soon as the fleet is conflict-free:
1. Joint PSO over every UAV's 4-D waypoints (the shared engine, gcs_planner.planning.pso).
   Particle = for each UAV the positions of its interior waypoints and the durations of its legs
   (durations > 0 keep times monotone). Cost F = J + w_c f_c + w_a f_a + w_v f_v (+ turn radius
   and time-error-limit penalties), J = sum of path lengths + w_e * sum of arrival time errors.
   f_c = number of conflicts + their depth (separation shortfall / separation, or 1 - whitened
   distance for manned zones) so the swarm sees a slope as well as the 0/1 indicator C_ij.
2. Delayed take-off: while conflicts remain, delay the take-off of the UAV with the most conflicts
   (ties: lowest index; UAVs at ``max_delay_s`` are skipped) by ``delay_step_s`` and re-check.
   The whole trajectory shifts (the paper's "shortens the time to arrival" would need faster
   flight; here the arrival time error grows instead and counts in J).
3. Waypoint insertion: on the most-conflicting UAV insert a waypoint where its earliest conflict
   happens, then PSO over that UAV's interior waypoints (the new one included; freeing only the
   new one stalled on short flights whose corner blends need room) and its leg durations
   (segment parameters), the other UAVs fixed. The current trajectory is particle 0, so a step never makes
   the cost worse. Repeat.
4. Conflicts left: back to stage 1, warm-started from the current trajectories, at most
   ``max_rounds`` rounds; then the remaining conflicts are reported explicitly.

Open choices (documented): synchronous gbest (vectorised swarm; the paper updates gbest after
each particle); linear inertia 0.9 -> 0.4 (paper's schedule), c1 = c2 = 1.5; the swarm starts at
the current trajectories plus Gaussian spread; a PSO stage stops at the first iteration whose
best particle is conflict-free and within all limits (``early_stop``; Table 1 counts exactly this
iteration); conflicts inside the optimiser are checked on the waypoint polylines with every
UAV's corner-cutting margin added (trajectory.py), which is conservative for the flown (blended)
path; the final verdict re-checks the densely sampled blended paths. Iterations are counted as
PSO iterations (stages 1 and 3) plus delay steps (stage 2).
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field, replace
from typing import Annotated

import numpy as np
from msgspec import Meta

from gcs_planner.core.config import Count, Distance, Duration, Fraction, NonNegative, TimeStep
from gcs_planner.planning import PlannerConfig, Progress
from gcs_planner.planning.deconflict4d.conflicts import (
    candidate_pairs,
    conflict_counts,
    pair_closest_approach,
    zone_closest_approach,
)
from gcs_planner.planning.deconflict4d.manned import Zone
from gcs_planner.planning.deconflict4d.trajectory import (
    Dynamics,
    blend_times,
    corner_deviation,
    limit_violations,
    sample_path,
)
from gcs_planner.planning.pso import PSOConfig, minimize

__all__ = [
    "Config",
    "Outcome",
    "Problem",
    "Search",
    "Track",
    "UavSpec",
    "initial_tracks",
    "joint_search",
    "run",
    "swarm_config",
]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class UavSpec:
    """One UAV's flight plan: start / goal [m ENU], planned take-off and arrival [s], limits."""

    id: str
    sysid: int
    vehicle_type: str
    start: np.ndarray
    goal: np.ndarray
    takeoff_s: float
    arrival_s: float
    separation_m: float
    dyn: Dynamics
    z_min_m: float
    z_max_m: float


class Config(PlannerConfig, tag="deconflict_4d"):
    """Method parameters: the scenario's [planner] table, with the manned-traffic zone settings."""

    particles: Count = 40
    iterations: Count = 150  # the paper's maxiteration
    interior_waypoints: Count = 1
    c1: NonNegative = 1.5
    c2: NonNegative = 1.5
    w_max: NonNegative = 0.9
    w_min: NonNegative = 0.4
    init_spread_m: Distance = 3.0
    insert_spread_m: Distance = 2.0
    insert_radius_m: Distance = 10.0
    zone_step_s: TimeStep = 5.0
    early_stop: bool = True
    w_conflict: NonNegative = 1000.0
    w_accel: NonNegative = 1000.0
    w_speed: NonNegative = 1000.0
    w_turn: NonNegative = 10.0
    w_time: NonNegative = 1.0
    w_time_limit: NonNegative = 100.0
    use_delay: bool = True
    delay_step_s: TimeStep = 1.0
    delay_max_steps: Annotated[int, Meta(ge=0, le=1_000_000)] = 200
    max_delay_s: Duration = 60.0
    use_waypoints: bool = True
    insert_max_steps: Annotated[int, Meta(ge=0, le=1_000_000)] = 40
    insert_particles: Count = 20
    insert_iterations: Count = 50
    max_waypoints: Count = 8
    max_rounds: Count = 3
    confidence: Annotated[float, Meta(gt=0.0, lt=1.0)] = 0.95  # manned-traffic zones (manned.py)
    safety_m: Distance = 5.0
    min_mode_weight: Fraction = 0.01
    # UAV pairs keep their separation under any relative schedule error up to this [s]; 0 is the
    # paper's exact timing; flown plans set the measured error (docs/timing-separation.md)
    timing_error_s: Annotated[float, Meta(ge=0.0, le=60.0)] = 0.0


@dataclass
class Track:
    """Decision state of one UAV: waypoints p0..pN (n, 3) [m], leg durations (n-1,) [s], delay [s]."""

    waypoints: np.ndarray
    legs_s: np.ndarray
    delay_s: float = 0.0


@dataclass
class Problem:
    uavs: list[UavSpec]
    zones: list[Zone]
    settings: Config
    lower_m: np.ndarray  # (3,) box for waypoints
    upper_m: np.ndarray
    zone_arrays: tuple[np.ndarray, ...] | None = None  # stacked zones (computed when None)

    def __post_init__(self) -> None:
        if self.zone_arrays is None:
            self.zone_arrays = _stack_zones(self.zones)


@dataclass
class Outcome:
    """Result of :func:`run`: final tracks, per-UAV flown polylines and the report."""

    tracks: list[Track]
    points: np.ndarray  # (U, W, 3) full polylines (with climb / descent)
    times: np.ndarray  # (U, W)
    tau: np.ndarray  # (U, W) blend durations
    paths: list[tuple[np.ndarray, np.ndarray]]  # per UAV dense blended path (M, 3) [m], times (M,) [s]
    conflict_free: bool
    remaining: list[dict]
    metrics: dict
    events: list[dict] = field(default_factory=list)


# ---------------------------------------------------------------------------- tracks and layout


def initial_tracks(problem: Problem) -> list[Track]:
    """Straight flight plans with ``interior_waypoints`` evenly spaced, timed to the planned arrival."""
    n_int = problem.settings.interior_waypoints
    tracks = []
    for u in problem.uavs:
        frac = np.linspace(0.0, 1.0, n_int + 2)
        wps = u.start + frac[:, None] * (u.goal - u.start)
        first = u.takeoff_s + _ground_time(u)[0]
        cruise = max(u.arrival_s - first, 1e-3)
        tracks.append(Track(waypoints=wps, legs_s=np.full(n_int + 1, cruise / (n_int + 1))))
    return tracks


def _ground_time(u: UavSpec) -> tuple[float, float]:
    """Climb and descent leg durations [s] (0 for vehicles that do not take off vertically)."""
    if not u.dyn.vertical_takeoff:
        return 0.0, 0.0
    return u.start[2] / u.dyn.climb_mps + u.dyn.takeoff_settle_s, u.goal[2] / u.dyn.descent_mps


def full_polyline(u: UavSpec, tr: Track) -> tuple[np.ndarray, np.ndarray, int]:
    """Flown polyline (points, times) incl. climb / descent, and the index of the last waypoint."""
    climb, descent = _ground_time(u)
    if u.dyn.vertical_takeoff:
        ground0 = np.array([*tr.waypoints[0, :2], 0.0])
        ground1 = np.array([*tr.waypoints[-1, :2], 0.0])
        pts = np.vstack([ground0, tr.waypoints, ground1])
        dur = np.concatenate([[climb], tr.legs_s, [descent]])
        # the blend from rest at the ground point is centred there: shift so motion starts at take-off
        t0 = u.takeoff_s + tr.delay_s + 0.5 * (u.start[2] / climb) / u.dyn.a_max_mps2
        goal_idx = len(pts) - 2
    else:
        pts, dur, goal_idx = tr.waypoints, tr.legs_s, len(tr.waypoints) - 1
        t0 = u.takeoff_s + tr.delay_s
    return pts, t0 + np.concatenate([[0.0], np.cumsum(dur)]), goal_idx


class _Layout:
    """Maps a PSO vector to the fleet's polylines: which waypoint coordinates and leg durations move.

    ``free`` maps a UAV index to the indices (into its Track.waypoints) of the waypoints whose
    coordinates are optimised; every leg duration of a free UAV is optimised.
    """

    def __init__(self, problem: Problem, tracks: list[Track], free: dict[int, list[int]]):
        fulls = [full_polyline(u, t) for u, t in zip(problem.uavs, tracks, strict=True)]
        n_u = len(tracks)
        self.width = max(len(p) for p, _, _ in fulls)
        self.base_pts = np.zeros((n_u, self.width, 3))
        self.base_dur = np.zeros((n_u, self.width - 1))
        self.t0 = np.zeros(n_u)
        self.goal_idx = np.zeros(n_u, dtype=int)
        for i, (p, t, g) in enumerate(fulls):
            self.base_pts[i, : len(p)], self.base_pts[i, len(p) :] = p, p[-1]
            self.base_dur[i, : len(t) - 1] = np.diff(t)
            self.t0[i], self.goal_idx[i] = t[0], g
        pos_u, pos_w, dur_u, dur_k, lo, hi, x0 = [], [], [], [], [], [], []
        for i, wp_idx in free.items():
            off = 1 if problem.uavs[i].dyn.vertical_takeoff else 0
            zlo, zhi = problem.uavs[i].z_min_m, problem.uavs[i].z_max_m
            for k in wp_idx:
                pos_u.append(i)
                pos_w.append(k + off)
                lo += [problem.lower_m[0], problem.lower_m[1], zlo]
                hi += [problem.upper_m[0], problem.upper_m[1], zhi]
                x0 += list(tracks[i].waypoints[k])
        self.n_pos = len(pos_u)
        for i in free:
            off = 1 if problem.uavs[i].dyn.vertical_takeoff else 0
            for k, d in enumerate(tracks[i].legs_s):
                dur_u.append(i)
                dur_k.append(k + off)
                lo.append(max(0.1, 0.2 * d))
                hi.append(max(3.0 * d, d + 10.0))
                x0.append(d)
        self.pos_u, self.pos_w = np.array(pos_u, dtype=int), np.array(pos_w, dtype=int)
        self.dur_u, self.dur_k = np.array(dur_u, dtype=int), np.array(dur_k, dtype=int)
        self.lower, self.upper = np.array(lo, dtype=float), np.array(hi, dtype=float)
        self.x0 = np.clip(np.array(x0, dtype=float), self.lower, self.upper)
        self.free = free

    def decode(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(B, D) parameters -> points (B, U, W, 3), times (B, U, W)."""
        n_b = x.shape[0]
        pts = np.broadcast_to(self.base_pts, (n_b, *self.base_pts.shape)).copy()
        dur = np.broadcast_to(self.base_dur, (n_b, *self.base_dur.shape)).copy()
        if self.n_pos:
            pts[:, self.pos_u, self.pos_w, :] = x[:, : 3 * self.n_pos].reshape(n_b, self.n_pos, 3)
        if len(self.dur_u):
            dur[:, self.dur_u, self.dur_k] = x[:, 3 * self.n_pos :]
        times = self.t0[None, :, None] + np.concatenate(
            [np.zeros((n_b, dur.shape[1], 1)), np.cumsum(dur, axis=-1)], axis=-1
        )
        # padding after a UAV's last point repeats it (zero-duration legs)
        return pts, times

    def tracks(self, x: np.ndarray, old: list[Track]) -> list[Track]:
        """Tracks updated from one parameter vector (D,)."""
        new = [Track(t.waypoints.copy(), t.legs_s.copy(), t.delay_s) for t in old]
        pos = x[: 3 * self.n_pos].reshape(-1, 3)
        cursor = 0
        for i, wp_idx in self.free.items():
            for k in wp_idx:
                new[i].waypoints[k] = pos[cursor]
                cursor += 1
        durs = x[3 * self.n_pos :]
        cursor = 0
        for i in self.free:
            n = len(new[i].legs_s)
            new[i].legs_s = durs[cursor : cursor + n].copy()
            cursor += n
        return new


def _stack_zones(zones: list[Zone]) -> tuple[np.ndarray, ...]:
    """Zones padded to a common length: centres (Z, H, 3), times (Z, H), rot, axes, owner (Z,)."""
    if not zones:
        return (
            np.zeros((0, 2, 3)),
            np.zeros((0, 2)),
            np.zeros((0, 3, 3)),
            np.zeros((0, 1, 3)),
            np.zeros(0, int),
        )
    h = max(len(z.times_s) for z in zones)

    def pad(a: np.ndarray, n: int) -> np.ndarray:
        return np.concatenate([a, np.repeat(a[-1:], n - len(a), axis=0)])

    return (
        np.stack([pad(z.centres_m, h) for z in zones]),
        np.stack([pad(z.times_s, h) for z in zones]),
        np.stack([z.rot for z in zones]),
        np.stack([pad(z.axes_m, h - 1) for z in zones]),
        np.array([z.owner for z in zones], dtype=int),
    )


# ---------------------------------------------------------------------------- evaluation

_LIMIT_TERMS = ("speed_excess", "blend_overlap_s", "turn_excess_m", "time_error_excess_s")  # 0 = within


@dataclass
class _Eval:
    cost: np.ndarray  # (B,)
    conflicts: np.ndarray  # (B,) conflicting pairs + UAV-zone entries
    feasible: np.ndarray  # (B,) conflict-free and within every limit
    pairs: np.ndarray
    pair_conflict: np.ndarray
    pair_t: np.ndarray
    pair_d: np.ndarray
    active: np.ndarray
    zone_conflict: np.ndarray  # (B, A, Z)
    zone_t: np.ndarray
    zone_d: np.ndarray
    terms: dict


def evaluate(
    problem: Problem,
    pts: np.ndarray,
    times: np.ndarray,
    goal_idx: np.ndarray,
    active: np.ndarray | None = None,
) -> _Eval:
    """Cost, conflicts and feasibility of B fleet candidates; conflicts only for pairs with an
    ``active`` UAV (all when None)."""
    s = problem.settings
    n_b, n_u = pts.shape[:2]
    a_max = np.array([u.dyn.a_max_mps2 for u in problem.uavs])[:, None]
    norm = np.array([u.dyn.limit == "norm" for u in problem.uavs])[:, None]
    tau = blend_times(pts, times, a_max, norm)
    margin = corner_deviation(pts, times, tau)
    cost, penalty, terms = _own_cost(problem, pts, times, tau, norm, goal_idx)
    act = np.arange(n_u) if active is None else np.asarray(active, dtype=int)
    pts, times = with_rest_ends(pts, times, tau)
    pairs, d, t, pc, f_c = _pair_conflicts(problem, pts, times, margin, active, act)
    zc_pts, zc_t, zc_rot, zc_axes, _ = problem.zone_arrays
    if len(zc_pts):
        dz, tz = zone_closest_approach(
            pts[:, act], times[:, act], zc_pts, zc_t, zc_rot, zc_axes, margin[:, act]
        )
    else:
        dz, tz = np.full((n_b, len(act), 0), np.inf), np.zeros((n_b, len(act), 0))
    zcf = dz < 1.0
    f_c = f_c + zcf.sum(axis=(-1, -2)) + np.maximum(1.0 - dz, 0.0).sum(axis=(-1, -2))
    n_conf = pc.sum(axis=-1) + zcf.sum(axis=(-1, -2))
    limits_ok = penalty.sum(axis=-1) <= 1e-9
    return _Eval(
        cost=cost + s.w_conflict * f_c,
        conflicts=n_conf,
        feasible=(n_conf == 0) & limits_ok,
        pairs=pairs,
        pair_conflict=pc,
        pair_t=t,
        pair_d=d,
        active=act,
        zone_conflict=zcf,
        zone_t=tz,
        zone_d=dz,
        terms=terms,
    )


def _own_cost(problem: Problem, pts, times, tau, norm, goal_idx):
    """Each candidate's cost without conflicts: length, arrival-time error and the limit
    penalties; (cost (B,), penalty (B, U), named terms)."""
    s, uavs = problem.settings, problem.uavs
    n_u = pts.shape[1]
    inflight = np.ones(pts.shape[1:3], dtype=bool)
    for i, u in enumerate(uavs):
        if u.dyn.vertical_takeoff:
            inflight[i, 0] = False
            inflight[i, goal_idx[i] + 1 :] = False
    viol = limit_violations(
        pts,
        times,
        tau,
        np.array([u.dyn.v_max_mps for u in uavs]),
        np.array([u.dyn.min_turn_radius_m for u in uavs]),
        norm,
        inflight,
    )
    length = np.linalg.norm(np.diff(pts, axis=-2), axis=-1).sum(axis=-1)
    t_arr = times[:, np.arange(n_u), goal_idx]
    err = np.abs(t_arr - np.array([u.arrival_s for u in uavs]))
    err_excess = np.maximum(err - np.array([u.dyn.max_time_error_s for u in uavs]), 0.0)
    penalty = (
        s.w_speed * viol["speed"]
        + s.w_accel * viol["blend_overlap"]
        + s.w_turn * viol["turn"]
        + s.w_time_limit * err_excess
    )
    cost = (length + s.w_time * err + penalty).sum(axis=-1)
    terms = {
        "length_m": length,
        "time_error_s": err,
        "speed_excess": viol["speed"],
        "blend_overlap_s": viol["blend_overlap"],
        "turn_excess_m": viol["turn"],
        "time_error_excess_s": err_excess,
    }
    return cost, penalty, terms


def _pair_conflicts(problem: Problem, pts, times, margin, active, act):
    """UAV-UAV conflicts: candidate pairs (with an active UAV), their closest approach, which are
    closer than their separation plus corner margins, and the conflict term of the cost."""
    n_b, n_u = pts.shape[:2]
    timing = problem.settings.timing_error_s
    sep = np.array([u.separation_m for u in problem.uavs])
    speed = [u.dyn.v_max_mps * (1.0 if u.dyn.limit == "norm" else math.sqrt(3.0)) for u in problem.uavs]
    reach = sep / 2 + timing * np.array(speed)  # + how far a schedule error moves a UAV
    pairs = candidate_pairs(pts, times, reach[None, :] + margin)
    if active is not None and len(pairs):
        is_act = np.zeros(n_u, dtype=bool)
        is_act[act] = True
        pairs = pairs[is_act[pairs[:, 0]] | is_act[pairs[:, 1]]]
    d, t = pair_closest_approach(pts, times, pairs, reach + margin.max(axis=0), timing)
    if len(pairs):
        need = (
            np.maximum(sep[pairs[:, 0]], sep[pairs[:, 1]]) + margin[:, pairs[:, 0]] + margin[:, pairs[:, 1]]
        )
    else:
        need = np.zeros((n_b, 0))
    pc = d < need
    f_c = pc.sum(axis=-1) + (np.maximum(need - d, 0.0) / np.where(need > 0, need, 1.0)).sum(axis=-1)
    return pairs, d, t, pc, f_c


def with_rest_ends(pts: np.ndarray, times: np.ndarray, tau: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Polylines extended by the half blends from / to rest at both ends (..., W + 2).

    The blend from rest at the first point starts ``tau_0 / 2`` before its time (the vehicle
    sits there until then) and the stop at the last point ends ``tau_last / 2`` after it, so
    the conflict checks cover the whole time the vehicle moves.
    """
    t_first = (times - tau / 2).min(axis=-1, keepdims=True)
    t_last = (times + tau / 2).max(axis=-1, keepdims=True)
    return (
        np.concatenate([pts[..., :1, :], pts, pts[..., -1:, :]], axis=-2),
        np.concatenate([t_first, times, t_last], axis=-1),
    )


def _fleet_state(problem: Problem, tracks: list[Track]) -> tuple[_Layout, _Eval]:
    layout = _Layout(problem, tracks, {})
    pts, tms = layout.decode(np.zeros((1, 0)))
    return layout, evaluate(problem, pts, tms, layout.goal_idx)


def _counts(problem: Problem, ev: _Eval) -> np.ndarray:
    """Conflicting-aircraft count per UAV for a B = 1 evaluation (all UAVs active)."""
    owner = problem.zone_arrays[4]
    return conflict_counts(len(problem.uavs), ev.pairs, ev.pair_conflict, ev.zone_conflict, owner)[0]


def _earliest_conflict(ev: _Eval, u: int) -> float:
    """Earliest conflict time [s] of UAV u in a B = 1 evaluation with all UAVs active."""
    times = [math.inf]
    if len(ev.pairs):
        mine = ((ev.pairs[:, 0] == u) | (ev.pairs[:, 1] == u)) & ev.pair_conflict[0]
        times += list(ev.pair_t[0, mine])
    times += list(ev.zone_t[0, u, ev.zone_conflict[0, u]])
    return float(min(times))


# ---------------------------------------------------------------------------- PSO wrapper


@dataclass(frozen=True)
class Search:
    """One swarm's search space and cost: the free parameters of ``layout``, conflicts checked for
    the ``active`` UAVs (all when None). Public so that benchmarks can give library optimisers the
    very cost and start the method's PSO sees."""

    problem: Problem
    layout: _Layout
    active: np.ndarray | None = None

    @property
    def lower(self) -> np.ndarray:
        return self.layout.lower

    @property
    def upper(self) -> np.ndarray:
        return self.layout.upper

    def evaluate(self, x: np.ndarray) -> _Eval:
        pts, tms = self.layout.decode(x)
        return evaluate(self.problem, pts, tms, self.layout.goal_idx, self.active)

    def initial_swarm(self, particles: int, rng: np.random.Generator) -> np.ndarray:
        """The current trajectories (particle 0) plus Gaussian spread, clipped to the bounds."""
        s, lay = self.problem.settings, self.layout
        spread_m = s.init_spread_m if self.active is None else s.insert_spread_m
        spread = np.concatenate([np.full(3 * lay.n_pos, spread_m), 0.15 * lay.x0[3 * lay.n_pos :]])
        init = lay.x0 + rng.normal(size=(particles, lay.x0.size)) * spread
        init[0] = lay.x0
        return np.clip(init, lay.lower, lay.upper)


def joint_search(problem: Problem, tracks: list[Track]) -> Search:
    """Stage 1's search: every UAV's interior waypoints and leg durations at once."""
    free = {i: list(range(1, len(t.waypoints) - 1)) for i, t in enumerate(tracks)}
    return Search(problem, _Layout(problem, tracks, free))


def swarm_config(s: Config, particles: int, iterations: int) -> PSOConfig:
    """The paper's PSO settings: linear inertia w_max -> w_min, c1, c2."""
    return PSOConfig(
        particles=particles,
        iterations=iterations,
        c1=s.c1,
        c2=s.c2,
        inertia="linear",
        w_max=s.w_max,
        w_min=s.w_min,
    )


def _pso(
    search: Search, particles: int, iterations: int, rng: np.random.Generator
) -> tuple[np.ndarray, float, int, int | None]:
    """Run the shared engine; returns (best x, best cost, iterations run, first feasible iteration)."""
    s = search.problem.settings
    state = {"it": 0, "cost": math.inf, "x": search.layout.x0.copy(), "feasible": False, "first": None}

    def cost(x: np.ndarray) -> np.ndarray:
        ev = search.evaluate(x)
        state["it"] += 1
        i = int(np.argmin(ev.cost))
        if ev.cost[i] < state["cost"]:
            state.update(cost=float(ev.cost[i]), x=x[i].copy(), feasible=bool(ev.feasible[i]))
        if state["feasible"] and state["first"] is None:
            state["first"] = state["it"]
        return ev.cost

    solved = (lambda: state["first"] is not None) if s.early_stop else None
    init = search.initial_swarm(particles, rng)
    minimize(
        cost, search.lower, search.upper, swarm_config(s, particles, iterations), rng, init=init, stop=solved
    )
    return state["x"], state["cost"], state["it"], state["first"]


# ---------------------------------------------------------------------------- stages


def _stage_pso(problem: Problem, tracks: list[Track], rng: np.random.Generator) -> tuple[list[Track], dict]:
    search = joint_search(problem, tracks)
    s = problem.settings
    x, _, iters, first = _pso(search, s.particles, s.iterations, rng)
    new = search.layout.tracks(x, tracks)
    # a swarm stopped early may leave some UAV outside its limits: keep that UAV's previous
    # trajectory when it was within them (the later stages cannot repair limits)
    before, after = _limit_excess(problem, tracks), _limit_excess(problem, new)
    reverted = [i for i in range(len(tracks)) if after[i] > 0 and before[i] <= 0]
    for i in reverted:
        new[i] = tracks[i]
    return new, {"iterations": iters, "first_conflict_free_iteration": first, "reverted": len(reverted)}


def _limit_excess(problem: Problem, tracks: list[Track]) -> np.ndarray:
    """Sum of the kinematic and time-error limit excesses per UAV (0 = within every limit)."""
    _, ev = _fleet_state(problem, tracks)
    return sum(ev.terms[k][0] for k in _LIMIT_TERMS)


def _stage_delay(problem: Problem, tracks: list[Track], events: list[dict]) -> tuple[list[Track], dict]:
    s = problem.settings
    steps, adjusted = 0, set()
    tracks = [replace(t) for t in tracks]
    layout, ev = _fleet_state(problem, tracks)
    pts, tms = layout.decode(np.zeros((1, 0)))
    for _ in range(s.delay_max_steps):
        counts = _counts(problem, ev)
        if not counts.any():
            break
        order = np.lexsort((np.arange(len(counts)), -counts))
        # a delay may not push the arrival past the time-error limit (nor past max_delay_s)
        slack = np.array([u.dyn.max_time_error_s for u in problem.uavs]) - ev.terms["time_error_s"][0]
        pick = next(
            (
                int(u)
                for u in order
                if counts[u]
                and tracks[u].delay_s + s.delay_step_s <= s.max_delay_s
                and slack[u] >= s.delay_step_s
            ),
            None,
        )
        if pick is None:
            break
        tracks[pick].delay_s += s.delay_step_s
        _delay_row(problem, tms, tracks[pick], pick)
        ev = _changed(problem, ev, pts, tms, layout.goal_idx, pick)
        adjusted.add(pick)
        steps += 1
        events.append(
            {
                "stage": "delay",
                "uav": problem.uavs[pick].id,
                "delay_s": tracks[pick].delay_s,
                "conflicts": int(counts[pick]),
            }
        )
    return tracks, {"iterations": steps, "trajectories_adjusted": len(adjusted)}


def _delay_row(problem: Problem, tms: np.ndarray, track: Track, u: int) -> None:
    """UAV u's row of the B = 1 times ``tms`` after its delay changed, as ``_Layout.decode`` times it."""
    _, t, _ = full_polyline(problem.uavs[u], track)
    dur = np.zeros(tms.shape[-1] - 1)
    dur[: len(t) - 1] = np.diff(t)
    tms[0, u] = t[0] + np.concatenate([[0.0], np.cumsum(dur)])


def _changed(
    problem: Problem, ev: _Eval, pts: np.ndarray, tms: np.ndarray, goal_idx: np.ndarray, u: int
) -> _Eval:
    """The B = 1 fleet evaluation after only UAV u's trajectory changed (pts, tms: the new fleet):
    the pairs and zones with u re-evaluated, the rest of ``ev`` kept (the same numbers a full
    evaluation gives: a pair's closest approach depends on its two UAVs only)."""
    new = evaluate(problem, pts, tms, goal_idx, np.array([u]))
    keep = (ev.pairs[:, 0] != u) & (ev.pairs[:, 1] != u) if len(ev.pairs) else np.zeros(0, dtype=bool)
    zone_conflict, zone_t, zone_d = ev.zone_conflict.copy(), ev.zone_t.copy(), ev.zone_d.copy()
    zone_conflict[:, u], zone_t[:, u] = new.zone_conflict[:, 0], new.zone_t[:, 0]
    zone_d[:, u] = new.zone_d[:, 0]
    pair_conflict = np.concatenate([ev.pair_conflict[:, keep], new.pair_conflict], axis=1)
    n_conf = pair_conflict.sum(axis=-1) + zone_conflict.sum(axis=(-1, -2))
    limits_ok = np.array([all(float(new.terms[k].sum()) <= 1e-9 for k in _LIMIT_TERMS)])
    return _Eval(
        cost=new.cost,  # the pair and zone terms of u only: not a fleet cost
        conflicts=n_conf,
        feasible=(n_conf == 0) & limits_ok,
        pairs=np.concatenate([ev.pairs[keep], new.pairs]),
        pair_conflict=pair_conflict,
        pair_t=np.concatenate([ev.pair_t[:, keep], new.pair_t], axis=1),
        pair_d=np.concatenate([ev.pair_d[:, keep], new.pair_d], axis=1),
        active=ev.active,
        zone_conflict=zone_conflict,
        zone_t=zone_t,
        zone_d=zone_d,
        terms=new.terms,
    )


def _insert_waypoint(problem: Problem, track: Track, u: int, t_c: float) -> tuple[Track, int]:
    """Split the leg flown at time t_c at the position flown then; returns (track, new index)."""
    pts, times, goal_idx = full_polyline(problem.uavs[u], track)
    off = 1 if problem.uavs[u].dyn.vertical_takeoff else 0
    wp_t = times[off : goal_idx + 1]
    t_c = float(np.clip(t_c, wp_t[0], wp_t[-1]))
    k = int(np.clip(np.searchsorted(wp_t, t_c, side="right") - 1, 0, len(track.legs_s) - 1))
    frac = float(np.clip((t_c - wp_t[k]) / track.legs_s[k], 0.25, 0.75))
    new_wp = track.waypoints[k] + frac * (track.waypoints[k + 1] - track.waypoints[k])
    waypoints = np.insert(track.waypoints, k + 1, new_wp, axis=0)
    legs = np.concatenate(
        [track.legs_s[:k], [track.legs_s[k] * frac, track.legs_s[k] * (1 - frac)], track.legs_s[k + 1 :]]
    )
    return Track(waypoints, legs, track.delay_s), k + 1


def _local_problem(
    problem: Problem, tracks: list[Track], u: int, free_wps: np.ndarray, ev: _Eval
) -> tuple[Problem, list[int]]:
    """The waypoint-insertion sub-problem: UAV u (index 0) and the UAVs it could meet.

    The free waypoints may move within ``insert_radius_m`` of their box, so u stays in
    the box of its current polyline grown by that radius; only UAVs whose flown polylines come
    within separation + margins of that box matter (the others are constant in the cost).
    """
    s = problem.settings
    layout = _Layout(problem, tracks, {})
    pts, tms = layout.decode(np.zeros((1, 0)))
    radius = s.insert_radius_m
    lo = np.minimum(pts[0, u].min(axis=0), free_wps.min(axis=0) - radius)
    hi = np.maximum(pts[0, u].max(axis=0), free_wps.max(axis=0) + radius)
    reach = max(v.separation_m for v in problem.uavs) + 2 * float(s.insert_radius_m)
    near = np.all((pts[0].min(axis=1) <= hi + reach) & (pts[0].max(axis=1) >= lo - reach), axis=1)
    near[u] = False
    members = [u] + [int(i) for i in np.nonzero(near)[0]]
    box_lo = np.maximum(problem.lower_m, free_wps.min(axis=0) - radius)
    box_hi = np.minimum(problem.upper_m, free_wps.max(axis=0) + radius)
    sub = Problem(
        uavs=[problem.uavs[m] for m in members],
        zones=problem.zones,
        settings=s,
        lower_m=box_lo,
        upper_m=box_hi,
        zone_arrays=problem.zone_arrays,
    )
    return sub, members


def _stage_waypoints(
    problem: Problem, tracks: list[Track], rng: np.random.Generator, events: list[dict]
) -> tuple[list[Track], dict]:
    """Waypoint insertion on the most-conflicting UAV; once conflict-free, a UAV left outside its
    limits is re-optimised the same local way, without inserting. An insertion whose result
    breaks a limit the UAV kept before is rejected and that UAV skipped for the rest of the
    stage. Each UAV is repaired at most once per stage."""
    s = problem.settings
    iters, added, repaired, stuck = 0, 0, set(), set()
    _, ev = _fleet_state(problem, tracks)
    for _ in range(s.insert_max_steps):
        counts = _counts(problem, ev)
        excess = sum(ev.terms[k][0] for k in _LIMIT_TERMS)
        order = np.lexsort((np.arange(len(counts)), -counts))
        pick = next(
            (
                int(u)
                for u in order
                if counts[u] and len(tracks[u].waypoints) < s.max_waypoints and int(u) not in stuck
            ),
            None,
        )
        if pick is not None:
            new_track, new_idx = _insert_waypoint(problem, tracks[pick], pick, _earliest_conflict(ev, pick))
            free, inserting = list(range(1, len(new_track.waypoints) - 1)), True
        elif not counts.any() and np.any(
            np.where(np.isin(np.arange(len(excess)), list(repaired)), 0, excess) > 0
        ):
            pick = int(np.argmax(np.where(np.isin(np.arange(len(excess)), list(repaired)), 0, excess)))
            new_track = tracks[pick]
            free, inserting = list(range(1, len(new_track.waypoints) - 1)), False
            repaired.add(pick)
        else:
            break
        sub, members = _local_problem(problem, tracks, pick, new_track.waypoints[free or [0]], ev)
        sub_tracks = [new_track] + [tracks[m] for m in members[1:]]
        layout = _Layout(sub, sub_tracks, {0: free})
        x, _, n_it, _ = _pso(Search(sub, layout, np.array([0])), s.insert_particles, s.insert_iterations, rng)
        iters += n_it
        candidate = layout.tracks(x, sub_tracks)
        if excess[pick] <= 0 and _limit_excess(sub, candidate)[0] > 0:
            # the swarm traded a limit for a conflict: keep the old trajectory, try other UAVs
            stuck.add(pick)
            events.append({"stage": "waypoint-rejected", "uav": problem.uavs[pick].id, "iterations": n_it})
            continue
        tracks = list(tracks)
        tracks[pick] = candidate[0]
        layout = _Layout(problem, tracks, {})
        ev = _changed(problem, ev, *layout.decode(np.zeros((1, 0))), layout.goal_idx, pick)
        added += inserting
        events.append(
            {
                "stage": "waypoint" if inserting else "repair",
                "uav": problem.uavs[pick].id,
                "conflicts": int(counts[pick]),
                "waypoints": len(tracks[pick].waypoints),
                "iterations": n_it,
            }
        )
    return tracks, {"iterations": iters, "waypoints_added": added, "repaired": len(repaired)}


# ---------------------------------------------------------------------------- driver


def run(problem: Problem, rng: np.random.Generator, progress: Progress | None = None) -> Outcome:
    """Plan conflict-free 4-D trajectories with the staged method; report what remains."""
    s = problem.settings
    tracks = initial_tracks(problem)
    events: list[dict] = []
    stages: list[dict] = []
    total_iters = 0
    first_free: int | None = None
    t_start = time.perf_counter()
    _, ev = _fleet_state(problem, tracks)
    events.append({"stage": "initial", "conflicts": int(ev.conflicts[0])})
    steps = [("pso", True), ("delay", s.use_delay), ("waypoints", s.use_waypoints)]
    done = bool(ev.feasible[0])
    for rnd in range(s.max_rounds if not done else 0):
        for k, (name, enabled) in enumerate(steps):
            if not enabled:
                continue
            t0 = time.perf_counter()
            if name == "pso":
                tracks, info = _stage_pso(problem, tracks, rng)
            elif name == "delay":
                tracks, info = _stage_delay(problem, tracks, events)
            else:
                tracks, info = _stage_waypoints(problem, tracks, rng, events)
            _, ev = _fleet_state(problem, tracks)
            done = bool(ev.feasible[0])
            info.update(
                round=rnd + 1,
                stage=name,
                conflicts_after=int(ev.conflicts[0]),
                wall_s=round(time.perf_counter() - t0, 3),
            )
            if done and first_free is None:
                first_free = total_iters + (info.get("first_conflict_free_iteration") or info["iterations"])
            total_iters += info["iterations"]
            stages.append(info)
            events.append(dict(info))
            log.info("deconflict round %d %s: %s", rnd + 1, name, info)
            if progress is not None:
                progress(
                    (rnd + (k + 1) / 3) / s.max_rounds,
                    f"round {rnd + 1} {name}: {info['conflicts_after']} conflicts",
                )
            if done:
                break
        if done:
            break
    return _finish(problem, tracks, stages, events, total_iters, first_free, time.perf_counter() - t_start)


def _finish(
    problem: Problem,
    tracks: list[Track],
    stages: list[dict],
    events: list[dict],
    total_iters: int,
    first_free: int | None,
    wall_s: float,
) -> Outcome:
    layout, ev = _fleet_state(problem, tracks)
    pts, tms = layout.decode(np.zeros((1, 0)))
    a_max = np.array([u.dyn.a_max_mps2 for u in problem.uavs])[:, None]
    norm = np.array([u.dyn.limit == "norm" for u in problem.uavs])[:, None]
    tau = blend_times(pts[0], tms[0], a_max, norm)
    dense, samples = dense_check(problem, pts[0], tms[0], tau)
    limits_ok = bool(all(float(ev.terms[k].sum()) <= 1e-9 for k in _LIMIT_TERMS))
    remaining = []
    for (i, j), hit, d, t in zip(ev.pairs, ev.pair_conflict[0], ev.pair_d[0], ev.pair_t[0], strict=True):
        if hit:
            remaining.append(
                {
                    "a": problem.uavs[i].id,
                    "b": problem.uavs[j].id,
                    "distance_m": round(float(d), 3),
                    "time_s": round(float(t), 2),
                }
            )
    owner_names = [z.name for z in problem.zones]
    for i, z in zip(*np.nonzero(ev.zone_conflict[0]), strict=True):
        remaining.append(
            {
                "a": problem.uavs[i].id,
                "b": owner_names[z],
                "whitened_distance": round(float(ev.zone_d[0, i, z]), 3),
                "time_s": round(float(ev.zone_t[0, i, z]), 2),
            }
        )
    conflict_free = not remaining and not dense["conflicts"]
    if not conflict_free:
        log.warning(
            "deconflict_4d: %d conflicts remain (dense check: %d)", len(remaining), len(dense["conflicts"])
        )
    metrics = {
        "conflict_free": conflict_free,
        "iterations_total": total_iters,
        "iterations_to_conflict_free": first_free,
        "stages": stages,
        "conflicts_remaining": remaining,
        "dense_check": dense,
        "wall_s": round(wall_s, 3),
        "limits_ok": limits_ok,
        "limit_violations": {
            u.id: {k: round(float(ev.terms[k][0, i]), 4) for k in _LIMIT_TERMS if ev.terms[k][0, i] > 1e-9}
            for i, u in enumerate(problem.uavs)
            if any(ev.terms[k][0, i] > 1e-9 for k in _LIMIT_TERMS)
        },
        "length_m": float(ev.terms["length_m"].sum()),
        "time_error_s": float(ev.terms["time_error_s"].sum()),
        "delays_s": {u.id: t.delay_s for u, t in zip(problem.uavs, tracks, strict=True) if t.delay_s},
        "uavs_delayed": sum(1 for t in tracks if t.delay_s),
        "waypoints_added": int(
            sum(len(t.waypoints) for t in tracks)
            - sum(problem.settings.interior_waypoints + 2 for _ in tracks)
        ),
    }
    return Outcome(tracks, pts[0], tms[0], tau, samples, conflict_free, remaining, metrics, events)


def dense_check(
    problem: Problem, pts: np.ndarray, tms: np.ndarray, tau: np.ndarray, per_blend: int = 8
) -> tuple[dict, list[tuple[np.ndarray, np.ndarray]]]:
    """Independent verdict on the flown (blended) paths sampled densely: min separations and conflicts.

    The sampled path is within ``a tau^2 / (8 per_blend^2)`` of the blended path; that chord error is
    added to the required separation.
    """
    samples = [sample_path(p, t, ta, per_blend) for p, t, ta in zip(pts, tms, tau, strict=True)]
    width = max(len(t) for _, t in samples)
    n_u = len(samples)
    dp = np.zeros((1, n_u, width, 3))
    dt = np.zeros((1, n_u, width))
    for i, (p, t) in enumerate(samples):
        dp[0, i, : len(t)], dp[0, i, len(t) :] = p, p[-1]
        dt[0, i, : len(t)], dt[0, i, len(t) :] = t, t[-1]
    a_max = np.array([u.dyn.a_max_mps2 for u in problem.uavs])
    chord = a_max * tau.max(axis=-1) ** 2 / (8 * per_blend**2)
    sep = np.array([u.separation_m for u in problem.uavs])
    pairs = candidate_pairs(dp, dt, (sep / 2 + chord)[None])
    d, t = pair_closest_approach(dp, dt, pairs, sep / 2 + chord)
    conflicts = []
    min_sep = math.inf
    for (i, j), dd, tt in zip(pairs, d[0], t[0], strict=True):
        ratio = dd / max(sep[i], sep[j])
        min_sep = min(min_sep, ratio)
        if dd < max(sep[i], sep[j]) + chord[i] + chord[j]:
            conflicts.append(
                {
                    "a": problem.uavs[i].id,
                    "b": problem.uavs[j].id,
                    "distance_m": round(float(dd), 3),
                    "time_s": round(float(tt), 2),
                }
            )
    zc_pts, zc_t, zc_rot, zc_axes, _ = problem.zone_arrays
    min_zone = math.inf
    if len(zc_pts):
        dz, tz = zone_closest_approach(dp, dt, zc_pts, zc_t, zc_rot, zc_axes, chord[None])
        min_zone = float(dz.min())
        for i, z in zip(*np.nonzero(dz[0] < 1.0), strict=True):
            conflicts.append(
                {
                    "a": problem.uavs[i].id,
                    "b": problem.zones[z].name,
                    "whitened_distance": round(float(dz[0, i, z]), 3),
                    "time_s": round(float(tz[0, i, z]), 2),
                }
            )
    report = {
        "conflicts": conflicts,
        "min_separation_ratio": round(float(min_sep), 4) if math.isfinite(min_sep) else None,
        "min_zone_whitened_distance": round(min_zone, 4) if math.isfinite(min_zone) else None,
    }
    return report, samples
