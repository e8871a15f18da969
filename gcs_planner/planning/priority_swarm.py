"""Priority swarm planner (seed 000): RRT* initial paths, prioritised PSO with restarts, Dubins paths.

Pipeline (D. Galinskyi, "Models and method of planning the motion of a swarm of UAVs ... taking
into account the priority of tasks"; the same method as PPSwarm, Drones 2024; docs/priority-swarm.md):

1. Level 1: one RRT* path per UAV among the static obstacles; priorities from the task priority
   (``Vehicle.priority``, higher first) and the path difficulty.
2. Level 2: in priority order, one PSO swarm per UAV (a particle = the UAV's ``waypoints``
   interior waypoints, 3 coordinates each) seeded with its RRT* path, the previous round's elites
   and random particles, minimising F = b1 F1 + b2 F2 + b3 F3 + b4 F4 + F5 (eqs. 3-14) against the
   static obstacles and the timed trajectories of the UAVs planned before it (the "global
   obstacle list").
3. Restart rounds: infeasible UAVs are promoted to the front and the round repeats; a UAV whose
   previous path is still feasible against the new higher-priority set keeps it.
4. The final Dubins paths are timed, checked by the independent checker
   (gcs_planner.safety.separation.check_plan, 0.5 s sampling); a UAV in conflict is re-planned
   against everybody else, then delayed on the ground in ``delay_step_s`` steps; what still fails
   is reported infeasible in its VehiclePlan (``feasible=False`` + notes), never silently.

Choices where the paper is open (all settable under [planner] in the scenario file):
- Path model: the polyline start -> waypoints -> goal is flown as planar Dubins paths between
  consecutive waypoints with the vehicle's minimum turn radius, heading at each interior waypoint
  = bisector of the in/out legs, start/goal heading = first/last leg; altitude linear along each
  leg's arc length. So the PSO optimises the *flown, smoothed* path: Dubins smoothing is part of the
  decoding, and the turn-radius constraint holds by construction.
- Timing: constant speed ``speed_mps`` along the 3-D path from t = take-off delay; a UAV occupies
  the airspace from take-off to arrival (goals are landing spots). Start/goal altitudes outside
  the vehicle's band get a vertical take-off/landing column (clamped into the band).
- F1 length = flown 3-D length / straight start-goal distance. F2 threat (eqs. 5-6) on the path
  sampled every ``dt_s`` (point-to-axis distance, obstacles inflated by ``obstacle_margin_m``, which
  covers the chord between samples; a grid of the cylinder axes keeps the 4 nearest in reach
  per sample, enough when at most 4 buffers overlap): soft part = depth into the buffer / buffer
  width, integrated along the path and divided by the straight distance; inside radius = HARD +
  depth. F3 altitude (eqs. 7-8, the digest's reading): mean |z - band middle| / half band, HARD
  outside. F4 (eqs. 9-11) = a1 sum(turn angles) + a2 sum(|climb-angle changes|) of the polyline,
  each divided by pi (W - 2); climb angle above ``max_climb_deg`` = HARD + excess. F5 (eqs. 12-13):
  on the shared 0.5 s time grid a spatial hash per slice (planning/traffic.py) finds
  higher-priority samples near each particle sample; the closest approach of the two linear
  motions over the slice, under any relative schedule error up to ``timing_error_s`` (the time
  errors flown, docs/timing-separation.md), must exceed max(separation_i, separation_j) +
  ``separation_margin_m``, else HARD + shortfall. HARD =
  1e4 replaces the paper's infinity (violations still rank by size).
- A ``[site]`` (gcs_planner.model.sites) adds a hard term at the same samples: below the DEM ground +
  terrain clearance + margin, or outside the site's area less the margin; the start and goal are
  lifted to that floor (a vertical column like the band's). No-fly zones and obstacles arrive as
  cylinders.
- Weights b1..b4 = 1, 1, 0.1, 0.2 and a1 = a2 = 0.5 (the paper gives none).
- PSO: the shared engine (gcs_planner.planning.pso), linear inertia ``w_max`` 0.9 -> ``w_min``
  0.4, ``c1`` = ``c2`` = 1.5, v_max = ``v_max_fraction`` 0.2 of the bound span. Initial swarm:
  the RRT* path resampled to W points by arc length,
  ``elite_fraction`` of the swarm = the UAV's best particles of the previous round, ``noise``
  particles = RRT* path + Gaussian noise (sigma = max(turn radius, 5 % of the xy span), 10 % of the
  band in z), ``random_fraction`` uniform in the bounds. Bounds: the scenario [bounds] box, else
  the box of all starts, goals and obstacles padded by ``pad_m``; z = the vehicle's band.
- Priorities: sort by (-priority, -difficulty, index) with difficulty = RRT* length / straight
  distance (constrained UAVs choose first). A UAV without an RRT* path starts from the straight line.
- Rounds stop when every UAV is feasible or after ``rounds``; the best round (most feasible UAVs,
  then lowest total cost) is kept.
- Mission waypoints: the Dubins path decimated so every chord is within ``waypoint_tol_m`` of the
  arc (plus every segment junction), so a waypoint-to-waypoint autopilot reproduces it; the dense
  path (``Plan.path``) is sampled every min(dt_s * v, R / 4) for the checker.
"""

from __future__ import annotations

import contextvars
import functools
import logging
import math
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Annotated

import numpy as np
from msgspec import Meta
from scipy.spatial import cKDTree

from gcs_planner.core.compiled import compiled
from gcs_planner.core.config import (
    Count,
    Distance,
    DistanceStep,
    Fraction,
    NonNegative,
    PositiveDistance,
    TimeStep,
)
from gcs_planner.core.errors import UserError
from gcs_planner.core.geo import wrap_pi
from gcs_planner.core.heap import keep_heap_slack
from gcs_planner.core.validation import MIN_TIME_STEP_S
from gcs_planner.geometry.dubins import segment_starts, shortest_batch
from gcs_planner.geometry.nearest import keep_nearest
from gcs_planner.geometry.obstacles import HARD_PENALTY, Obstacles
from gcs_planner.model.plan import Plan, VehiclePlan
from gcs_planner.model.scenario import Scenario, Vehicle
from gcs_planner.planning import PlannerConfig, Progress, Traits
from gcs_planner.planning.pso import PSOConfig, minimize
from gcs_planner.planning.rrt_star import RRTConfig, rrt_star
from gcs_planner.planning.traffic import TIMING_ERROR_S, Traffic
from gcs_planner.safety.separation import check_plan

if TYPE_CHECKING:  # shapely is imported only when a scenario has a [site]
    from gcs_planner.model.sites.world import Site

__all__ = ["NAME", "TRAITS", "Config", "Traffic", "VehicleProblem", "build_plan", "plan", "prepare"]

log = logging.getLogger(__name__)


NAME = "priority_swarm"
TRAITS = Traits(separation=True, reads=("obstacles", "bounds", "site"))


class Config(PlannerConfig, tag=NAME):
    """The [planner] table; see the module docstring for what each parameter means."""

    waypoints: Count = 5
    particles: Count = 30
    iterations: Count = 60
    rounds: Count = 3
    elite_fraction: Fraction = 0.15
    random_fraction: Fraction = 0.25
    dt_s: Annotated[float, Meta(ge=MIN_TIME_STEP_S, le=0.5)] = 0.5
    separation_margin_m: Distance = 2.0
    timing_error_s: Annotated[float, Meta(ge=0.0, le=60.0)] = TIMING_ERROR_S  # docs/timing-separation.md
    obstacle_margin_m: Distance = 1.5
    max_climb_deg: Annotated[float, Meta(gt=0.0, le=90.0)] = 20.0
    b1: NonNegative = 1.0
    b2: NonNegative = 1.0
    b3: NonNegative = 0.1
    b4: NonNegative = 0.2
    a1: Fraction = 0.5
    c1: NonNegative = 1.5  # PSO cognitive and social factors
    c2: NonNegative = 1.5
    w_max: NonNegative = 0.9  # linear inertia schedule w_max -> w_min
    w_min: NonNegative = 0.4
    v_max_fraction: Annotated[float, Meta(gt=0.0, le=1.0)] = 0.2  # of the bound span per iteration
    pad_m: Distance = 100.0
    rrt_step_m: DistanceStep = 60.0
    rrt_iterations: Count = 500
    rrt_extra_iterations: Annotated[int, Meta(ge=0, le=1_000_000)] = 150
    delay_step_s: TimeStep = 5.0
    repairs: Annotated[int, Meta(ge=0, le=1000)] = 4
    waypoint_tol_m: PositiveDistance = 1.0
    acceptance_radius_m: PositiveDistance = 2.0
    rrt_start: bool = True  # ablation switches: False starts every swarm from the straight line,
    priority_order: bool = True  # and plans the UAVs in scenario order (rounds=1: no restarts,
    # elite_fraction=0: no elites, repairs=0: no repair)

    def __post_init__(self) -> None:
        if self.elite_fraction + self.random_fraction > 1:
            raise ValueError(
                "elite_fraction + random_fraction must be <= 1,"
                f" got {self.elite_fraction!r} + {self.random_fraction!r}"
            )


@dataclass
class VehicleProblem:
    """One UAV's optimisation problem: fixed ends inside its band, bounds, timing."""

    index: int
    vehicle: Vehicle
    start: np.ndarray  # (3,) first point inside the band
    goal: np.ndarray  # (3,) last point inside the band
    lower: np.ndarray  # (D,)
    upper: np.ndarray
    n_wp: int
    delay_s: float = 0.0
    site: Site | None = None  # a [site]: terrain clearance and the area, as a hard cost term

    @property
    def pre(self) -> np.ndarray:
        """Take-off column below the start (0 or 1 point)."""
        s = np.asarray(self.vehicle.start, dtype=float)
        return s[None, :] if abs(s[2] - self.start[2]) > 1e-9 else np.empty((0, 3))

    @property
    def post(self) -> np.ndarray:
        g = np.asarray(self.vehicle.goal, dtype=float)
        return g[None, :] if abs(g[2] - self.goal[2]) > 1e-9 else np.empty((0, 3))

    @property
    def t_offset(self) -> float:
        """Time [s] at which the Dubins part starts (delay + take-off column)."""
        return self.delay_s + abs(self.vehicle.start[2] - self.start[2]) / self.vehicle.speed_mps

    @property
    def straight_m(self) -> float:
        return max(float(np.linalg.norm(self.goal - self.start)), 1e-6)


@dataclass
class Decoded:
    """Particles decoded into Dubins legs (P particles, W waypoints)."""

    pts: np.ndarray  # (P, W, 3)
    word: np.ndarray  # (P*(W-1),)
    seg: np.ndarray  # (P*(W-1), 3)
    lh: np.ndarray  # (P, W-1) horizontal leg lengths
    l3: np.ndarray  # (P, W-1) 3-D leg lengths
    cum: np.ndarray  # (P, W)
    starts: np.ndarray  # (P*(W-1), 3, 3) start pose of each Dubins segment
    kappa: np.ndarray  # (P*(W-1), 3) signed curvature of each segment
    seg_end: np.ndarray  # (P*(W-1), 3) horizontal length from a leg's start to each segment's end

    @property
    def total(self) -> np.ndarray:
        return self.cum[:, -1]

    @functools.cached_property
    def segments(self) -> tuple[np.ndarray, ...]:
        """Per segment (index leg * 3 + k), flat: start x, y, heading, its sine and cosine,
        curvature; per leg: the three segment ends. Contiguous columns, gathered by sampling."""
        st = self.starts.reshape(-1, 3)
        h = st[:, 2].copy()
        ends = self.seg_end.T.copy()
        return st[:, 0].copy(), st[:, 1].copy(), h, np.sin(h), np.cos(h), self.kappa.ravel(), *ends


def decode(prob: VehicleProblem, x: np.ndarray) -> Decoded:
    """Particles (P, D) -> polyline + Dubins legs with bisector headings."""
    p = len(x)
    pts = np.concatenate(
        [
            np.broadcast_to(prob.start, (p, 1, 3)),
            x.reshape(p, prob.n_wp, 3),
            np.broadcast_to(prob.goal, (p, 1, 3)),
        ],
        axis=1,
    )
    d = np.diff(pts, axis=1)
    theta = np.arctan2(d[..., 1], d[..., 0])  # (P, W-1)
    turn = wrap_pi(theta[:, 1:] - theta[:, :-1])
    heading = np.concatenate([theta[:, :1], theta[:, :-1] + turn / 2, theta[:, -1:]], axis=1)
    q = np.concatenate([pts[..., :2], heading[..., None]], axis=2)
    q0 = q[:, :-1].reshape(-1, 3)
    q1 = q[:, 1:].reshape(-1, 3)
    word, seg, radii = shortest_batch(q0, q1, prob.vehicle.turn_radius_m)
    lh = seg.sum(axis=1).reshape(p, -1)
    l3 = np.hypot(lh, d[..., 2])
    cum = np.concatenate([np.zeros((p, 1)), np.cumsum(l3, axis=1)], axis=1)
    starts, kappa = segment_starts(q0, word, seg, radii)
    return Decoded(pts, word, seg, lh, l3, cum, starts, kappa, np.cumsum(seg, axis=1))


def positions_at_length(dec: Decoded, s: np.ndarray) -> np.ndarray:
    """Positions (P, K, 3) at 3-D arc lengths s (P, K) [m] (clipped to each path).

    Each sample's leg and Dubins segment are found by comparisons with the junctions, then its
    position is integrated from the segment's start (dubins.advance's formulas; the sine and cosine
    of a segment's start heading are computed once per segment, the end heading's only on arcs).
    """
    out = np.empty((*s.shape, 3))
    _positions(dec.cum, dec.l3, dec.lh, dec.pts[..., 2], dec.segments, np.asarray(s, dtype=float), out)
    return out


@compiled
def _positions(cum, l3, lh, pz, segments, s, out) -> None:
    """``positions_at_length`` into ``out``, one sample at a time (compiled: the vectorised form
    spent most of its time on temporaries)."""
    x0, y0, h0, sin0, cos0, kappa, e0, e1, e2 = segments
    n_leg = l3.shape[1]
    for p in range(s.shape[0]):
        for i in range(s.shape[1]):
            si = min(max(s[p, i], 0.0), cum[p, -1])
            leg = 0  # legs ended before si
            while leg < n_leg - 1 and si > cum[p, leg + 1]:
                leg += 1
            f = (si - cum[p, leg]) / l3[p, leg] if l3[p, leg] > 0 else 0.0
            out[p, i, 2] = pz[p, leg] + f * (pz[p, leg + 1] - pz[p, leg])
            at = p * n_leg + leg  # the leg's three segments: at * 3 + 0, 1, 2
            sh = min(f * lh[p, leg], e2[at])
            seg, ds = at * 3, sh
            if sh > e1[at]:
                seg, ds = seg + 2, sh - e1[at]
            elif sh > e0[at]:
                seg, ds = seg + 1, sh - e0[at]
            kap = kappa[seg]
            if kap == 0.0:
                out[p, i, 0] = x0[seg] + ds * cos0[seg]
                out[p, i, 1] = y0[seg] + ds * sin0[seg]
            else:
                h = h0[seg] + kap * ds
                out[p, i, 0] = x0[seg] + (np.sin(h) - sin0[seg]) / kap
                out[p, i, 1] = y0[seg] - (np.cos(h) - cos0[seg]) / kap


@dataclass(frozen=True)
class _AxisGrid:
    """Square cells (``cell_m``, from ``lo``) and, per cell, the cylinders whose axis may lie within
    ``reach`` of a point in it (CSR: ``cand[start[c]:start[c + 1]]``): a sample reads its own cell."""

    lo: np.ndarray
    cell_m: float
    shape: tuple[int, int]
    start: np.ndarray
    cand: np.ndarray


@functools.lru_cache(maxsize=16)
def _axis_grid(cx: bytes, cy: bytes, reach: float) -> _AxisGrid:
    """The grid of the cylinder axes (x, y as bytes: a cache key) within ``reach``."""
    axes = np.column_stack([np.frombuffer(cx), np.frombuffer(cy)])
    cell = max(reach / 4.0, 1.0)
    lo = axes.min(axis=0) - reach - cell
    n = np.ceil((axes.max(axis=0) + reach + cell - lo) / cell).astype(int) + 1
    centre = lo + cell * (np.stack(np.meshgrid(np.arange(n[0]), np.arange(n[1]), indexing="ij"), -1) + 0.5)
    # a cell's corner is cell / sqrt 2 from its centre
    near = cKDTree(axes).query_ball_point(centre.reshape(-1, 2), reach + cell, return_sorted=True)
    start = np.concatenate([[0], np.cumsum([len(c) for c in near])])
    cand = np.concatenate([np.asarray(c, dtype=np.int64) for c in near])
    return _AxisGrid(lo, cell, (int(n[0]), int(n[1])), start, cand)


@compiled
def _cylinder_sums(mid, ds, grid, cyl, margin_m, reach_m, soft, hard) -> None:
    """F2 per particle into ``soft`` / ``hard`` (P,): at each sample mid (P, K, 3) the four nearest
    cylinder axes within ``reach_m`` (nearest first), in their altitude band: the depth into the
    buffer (times the sample's length ds (P, K)) and HARD + the depth inside the radius."""
    lo, cell, (nx, ny), start, cand = grid
    cx, cy, radius, buffer, z_min, z_max = cyl
    js, d2s = np.empty(4, dtype=np.int64), np.empty(4)
    for p in range(mid.shape[0]):
        for k in range(mid.shape[1]):
            x, y, z = mid[p, k, 0], mid[p, k, 1], mid[p, k, 2]
            fx, fy = np.floor((x - lo[0]) / cell), np.floor((y - lo[1]) / cell)
            if not (0 <= fx < nx and 0 <= fy < ny):  # NaN too
                continue
            c = np.int64(fx) * ny + np.int64(fy)
            n = 0  # the four nearest within reach
            for j in cand[start[c] : start[c + 1]]:
                d2 = (x - cx[j]) ** 2 + (y - cy[j]) ** 2
                if d2 < reach_m**2:
                    n = keep_nearest(js, d2s, n, j, d2)
            for m in range(n):
                j = js[m]
                if not z_min[j] <= z <= z_max[j]:
                    continue
                d, r, buf = np.sqrt(d2s[m]), radius[j] + margin_m, buffer[j]
                soft[p] += min(max((r + buf - d) / max(buf, 1e-9), 0.0), 1.0) * ds[p, k]
                if r - d > 0:
                    hard[p] += HARD_PENALTY + (r - d)


# Every cost evaluation of one plan() call (swarms, inherited-path checks, repairs), for a budget
# the benchmark can give the peers; the report-only ``terms`` calls do not count.
EVALUATIONS: contextvars.ContextVar[list[int] | None] = contextvars.ContextVar("evaluations", default=None)


class CostModel:
    """Eqs. 3-14 for one UAV, vectorised over a swarm (P, D) -> (P,), with a term breakdown."""

    def __init__(self, prob: VehicleProblem, obstacles: Obstacles, traffic: Traffic, cfg: Config) -> None:
        self.prob, self.obs, self.traffic, self.cfg = prob, obstacles, traffic, cfg
        self.evaluations = 0
        self._reach = (
            float(np.max(obstacles.radius_m + obstacles.buffer_m, initial=0.0)) + cfg.obstacle_margin_m
        )
        self._axes = None
        if len(obstacles.cx):
            grid = _axis_grid(obstacles.cx.tobytes(), obstacles.cy.tobytes(), self._reach)
            self._axes = (grid.lo, grid.cell_m, grid.shape, grid.start, grid.cand)
            obs = obstacles
            self._cyl = (obs.cx, obs.cy, obs.radius_m, obs.buffer_m, obs.z_min_m, obs.z_max_m)

    def grid(self, dec: Decoded) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Samples of every particle on the shared time grid: slices (K,), pos (P, K, 3), valid (P, K), s."""
        v, dt, t0 = self.prob.vehicle.speed_mps, self.cfg.dt_s, self.prob.t_offset
        k0 = math.ceil(t0 / dt - 1e-9)
        k1 = math.ceil((t0 + float(dec.total.max()) / v) / dt + 1e-9)
        slices = np.arange(k0, k1 + 1)
        s = np.empty((len(dec.total), len(slices) + 2))  # C order: what follows is row-wise
        s[:, 0] = 0.0
        s[:, 1:-1] = v * (slices * dt - t0)
        s[:, -1] = dec.total
        valid = s[:, 1:-1] <= dec.total[:, None] + 1e-9
        pos = positions_at_length(dec, s)
        return slices, pos, valid, s

    def terms(self, x: np.ndarray) -> dict[str, np.ndarray]:
        cfg, prob, veh = self.cfg, self.prob, self.prob.vehicle
        dec = decode(prob, np.atleast_2d(x))
        slices, pos, valid, s = self.grid(dec)
        ref = prob.straight_m
        f1 = dec.total / ref
        # F2 threat at the samples (obstacles inflated by the margin); ds = path length per sample
        ds = np.diff(s, axis=1)
        mid = 0.5 * (pos[:, 1:] + pos[:, :-1])
        soft = np.zeros(len(f1))
        hard = np.zeros(len(f1))
        if self._axes is not None:
            _cylinder_sums(
                mid, ds, self._axes, self._cyl, self.cfg.obstacle_margin_m, self._reach, soft, hard
            )
            soft = soft / ref
        if len(self.obs.dome_radius_m):
            dd = np.linalg.norm(mid[..., None, :] - self.obs.dome_centre, axis=-1)
            depth = np.maximum(0.0, self.obs.dome_radius_m + cfg.obstacle_margin_m - dd)
            hard = hard + (depth > 0).sum(axis=(1, 2)) * HARD_PENALTY + depth.sum(axis=(1, 2))
        # F3 altitude band (waypoints are bounded to the band, so HARD only guards the ends)
        z = dec.pts[..., 2]
        mid_z = 0.5 * (veh.min_alt_m + veh.max_alt_m)
        half = max(0.5 * (veh.max_alt_m - veh.min_alt_m), 1e-6)
        f3 = np.mean(np.abs(z - mid_z), axis=1) / half
        out_band = np.maximum(0.0, np.maximum(veh.min_alt_m - z, z - veh.max_alt_m))
        hard = hard + (out_band > 1e-9).sum(axis=1) * HARD_PENALTY + out_band.sum(axis=1)
        if prob.site is not None:  # below terrain + clearance, or out of the site's area
            off = prob.site.violations(pos)
            hard = hard + (off > 1e-9).sum(axis=1) * HARD_PENALTY + off.sum(axis=1)
        # F4 smoothness: turn angles and climb-angle changes of the polyline
        d = np.diff(dec.pts, axis=1)
        a, b = d[:, :-1], d[:, 1:]
        phi = np.arctan2(np.linalg.norm(np.cross(a, b), axis=2), np.sum(a * b, axis=2))
        psi = np.arctan2(d[..., 2], np.maximum(dec.lh, 1e-9))
        n_turn = max(prob.n_wp, 1) * math.pi
        f4 = (
            cfg.a1 * phi.sum(axis=1) / n_turn
            + (1 - cfg.a1) * np.abs(np.diff(psi, axis=1)).sum(axis=1) / n_turn
        )
        climb_excess = np.maximum(0.0, np.abs(psi) - math.radians(cfg.max_climb_deg))
        hard = hard + (climb_excess > 0).sum(axis=1) * HARD_PENALTY + climb_excess.sum(axis=1)
        # F5 separation from higher-priority UAVs on the shared time grid
        limits = (veh.separation_m, cfg.separation_margin_m, cfg.timing_error_s)
        depth, count = self.traffic.violations(slices, pos[:, 1:-1], valid, *limits)
        for k, col, on in arrival_tail(prob, prob.t_offset + dec.total / veh.speed_mps, cfg.dt_s):
            tail_depth, tail_count = self.traffic.violations(k, col, on, *limits)  # its landing too
            depth, count = depth + tail_depth, count + tail_count
        f5 = count * HARD_PENALTY + depth
        total = cfg.b1 * f1 + cfg.b2 * soft + cfg.b3 * f3 + cfg.b4 * f4 + hard + f5
        return {"F1": f1, "F2": soft, "F3": f3, "F4": f4, "F5": f5, "hard": hard, "total": total}

    def __call__(self, x: np.ndarray) -> np.ndarray:
        self.evaluations += len(x)
        tally = EVALUATIONS.get()
        if tally is not None:
            tally[0] += len(x)
        return self.terms(x)["total"]


def prepare(
    scenario: Scenario, cfg: Config
) -> tuple[list[VehicleProblem], Obstacles, np.ndarray, np.ndarray]:
    """Vehicle problems, obstacle arrays and the xy box (lo, hi) shared by all planners of this cost."""
    if not scenario.vehicles:
        raise UserError(f"scenario {scenario.name!r} has no vehicles")
    obstacles = Obstacles.from_scenario(scenario.cylinders, scenario.hemispheres)
    pts = np.array([v.start for v in scenario.vehicles] + [v.goal for v in scenario.vehicles])[:, :2]
    obs_xy = np.column_stack([obstacles.cx, obstacles.cy]).reshape(-1, 2)
    allxy = np.vstack([pts, obs_xy])
    lo = allxy.min(axis=0) - cfg.pad_m
    hi = allxy.max(axis=0) + cfg.pad_m
    if "x" in scenario.bounds:
        lo[0], hi[0] = scenario.bounds["x"]
    if "y" in scenario.bounds:
        lo[1], hi[1] = scenario.bounds["y"]
    problems = []
    for i, v in enumerate(scenario.vehicles):
        if not (v.min_alt_m < v.max_alt_m):
            raise UserError(
                f"vehicle {v.id}: min_alt_m must be < max_alt_m, got {v.min_alt_m} and {v.max_alt_m}"
            )
        if v.turn_radius_m <= 0:
            raise UserError(f"vehicle {v.id}: turn_radius_m must be > 0, got {v.turn_radius_m}")
        start = np.array(v.start, dtype=float)
        goal = np.array(v.goal, dtype=float)
        start[2] = np.clip(start[2], v.min_alt_m, v.max_alt_m)
        goal[2] = np.clip(goal[2], v.min_alt_m, v.max_alt_m)
        if scenario.site is not None:  # climb / descend vertically to terrain + clearance + margin
            site = scenario.site
            for p in (start, goal):
                floor = float(site.ground(p[0], p[1])) + site.clearance_m + site.margin_m
                p[2] = max(p[2], min(floor, v.max_alt_m))
                if site.violations(p)[()] > 1e-9:
                    raise UserError(
                        f"vehicle {v.id}: {tuple(np.round(p, 1))} is outside the site's area less its"
                        f" {site.margin_m:g} m margin, or under terrain + clearance within the band"
                    )
        for name, p in (("start", start), ("goal", goal)):
            if not (lo[0] <= p[0] <= hi[0] and lo[1] <= p[1] <= hi[1]):
                raise UserError(f"vehicle {v.id}: {name} {tuple(p[:2])} is outside the scenario bounds")
            if obstacles.contains(p[None, :])[0]:
                raise UserError(f"vehicle {v.id}: {name} {tuple(p)} is inside an obstacle")
        lower = np.tile([lo[0], lo[1], v.min_alt_m], cfg.waypoints)
        upper = np.tile([hi[0], hi[1], v.max_alt_m], cfg.waypoints)
        problems.append(VehicleProblem(i, v, start, goal, lower, upper, cfg.waypoints, site=scenario.site))
    return problems, obstacles, lo, hi


def resample_polyline(path: np.ndarray, n: int) -> np.ndarray:
    """n points equally spaced by arc length along a polyline (ends included)."""
    seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    s = np.linspace(0.0, cum[-1], n)
    return np.column_stack([np.interp(s, cum, path[:, k]) for k in range(3)])


def initial_paths(problems, obstacles, lo, hi, cfg: Config, rng: np.random.Generator):
    """Level 1: RRT* path per UAV, resampled to the particle encoding; difficulty = length ratio."""
    init, difficulty = [], []
    for prob in problems:
        v = prob.vehicle
        res = rrt_star(
            prob.start,
            prob.goal,
            obstacles,
            np.array([lo[0], lo[1], v.min_alt_m]),
            np.array([hi[0], hi[1], v.max_alt_m]),
            rng,
            RRTConfig(
                step_m=cfg.rrt_step_m, max_iterations=cfg.rrt_iterations, margin_m=cfg.obstacle_margin_m
            ),
        )
        path = res.path if res.path is not None else np.vstack([prob.start, prob.goal])
        init.append(resample_polyline(path, cfg.waypoints + 2)[1:-1].ravel())
        difficulty.append(res.cost_m / prob.straight_m if res.path is not None else math.inf)
    return init, np.array(difficulty)


def seed_swarm(
    prob: VehicleProblem, base: np.ndarray, elites: np.ndarray | None, cfg: Config, rng
) -> np.ndarray:
    """Initial particles: the inherited path, elites, noisy copies; the engine adds the random rest."""
    n_random = int(round(cfg.random_fraction * cfg.particles))
    n_elite = int(round(cfg.elite_fraction * cfg.particles)) if elites is not None else 0
    n_noise = max(0, cfg.particles - n_random - n_elite - 1)
    span = prob.upper - prob.lower
    sigma = np.tile(
        [
            max(prob.vehicle.turn_radius_m, 0.05 * span[0]),
            max(prob.vehicle.turn_radius_m, 0.05 * span[1]),
            0.1 * span[2],
        ],
        prob.n_wp,
    )
    noisy = np.clip(base + rng.normal(size=(n_noise, len(base))) * sigma, prob.lower, prob.upper)
    parts = [base[None, :], noisy]
    if n_elite:
        parts.append(elites[:n_elite])
    return np.vstack(parts)


def optimise(prob, obstacles, traffic, cfg: Config, rng, init: np.ndarray, budget: int | None = None):
    """One PSO run for one UAV; returns (best x, PSOResult, CostModel)."""
    model = CostModel(prob, obstacles, traffic, cfg)
    pso_cfg = PSOConfig(
        particles=cfg.particles,
        iterations=cfg.iterations,
        inertia="linear",
        c1=cfg.c1,
        c2=cfg.c2,
        w_max=cfg.w_max,
        w_min=cfg.w_min,
        v_max_fraction=cfg.v_max_fraction,
        max_evaluations=budget,
    )
    res = minimize(model, prob.lower, prob.upper, pso_cfg, rng, init=init)
    return res.best_x, res, model


def timed_samples(prob: VehicleProblem, x: np.ndarray, cfg: Config) -> tuple[np.ndarray, np.ndarray]:
    """Grid slices (K,) and positions (K, 3) of one UAV's path for the traffic list (columns included)."""
    model = CostModel(prob, Obstacles.from_scenario([]), Traffic(cfg.dt_s), cfg)
    dec = decode(prob, x[None, :])
    slices, pos, valid, _ = model.grid(dec)
    slices, pos = slices[valid[0]], pos[0, 1:-1][valid[0]]
    v = prob.vehicle
    cols = []
    if len(prob.pre):  # the take-off column, climbed at the end of the take-off delay
        k, col, _ = _column(prob.pre[0], prob.start, np.array([prob.delay_s]), v.speed_mps, cfg.dt_s)
        cols.append((k, col[0]))
    if v.waits_airborne and prob.delay_s > 0:  # the delayed departure awaited hovering at the start
        k = np.arange(0, math.ceil(prob.delay_s / cfg.dt_s - 1e-9))
        cols.append((k, np.broadcast_to(np.asarray(v.start, dtype=float), (len(k), 3))))
    t_arrive = prob.t_offset + float(dec.total[0]) / v.speed_mps
    cols += [(k[on[0]], col[0][on[0]]) for k, col, on in arrival_tail(prob, np.array([t_arrive]), cfg.dt_s)]
    if cols:
        ks = np.concatenate([slices] + [c[0] for c in cols])
        ps = np.vstack([pos] + [c[1] for c in cols])
        order = np.argsort(ks, kind="stable")
        ks, ps = ks[order], ps[order]
        keep = np.concatenate([[True], np.diff(ks) > 0])
        slices, pos = ks[keep], ps[keep]
    return slices, pos


def arrival_tail(
    prob: VehicleProblem, t_arrive: np.ndarray, dt_s: float
) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """What each particle flies after its path ends at t_arrive (P,) [s]: the column down to a goal
    below the band, then the mission's landing at the goal (its stop, then ``landing_mps`` down);
    per column, grid slices (K,), positions (P, K, 3) and valid (P, K)."""
    v = prob.vehicle
    cols, t = [], t_arrive
    if len(prob.post):
        cols.append(_column(prob.goal, prob.post[0], t, v.speed_mps, dt_s))
        t = t + abs(prob.post[0, 2] - prob.goal[2]) / v.speed_mps
    end = np.asarray(v.goal, dtype=float)
    if v.landing_mps > 0 and end[2] > 0:
        ground = np.array([end[0], end[1], 0.0])
        cols.append(_column(end, ground, t, v.landing_mps, dt_s, hold_s=v.landing_stop_s))
    return cols


@compiled
def _column(a, b, t_start, speed_mps, dt_s, hold_s=0.0):
    """Grid slices (K,), positions (P, K, 3) and valid (P, K) of vertical climbs or descents from a
    to b that reach a at t_start (P,) [s] and leave it ``hold_s`` later (compiled: the cost calls
    it for every swarm)."""
    dz = abs(b[2] - a[2])
    first = np.ceil(t_start / dt_s - 1e-9).astype(np.int64)
    last = np.floor((t_start + hold_s + dz / speed_mps) / dt_s).astype(np.int64)
    k = np.arange(first.min(), last.max() + 1)
    pos = np.empty((len(t_start), len(k), 3))
    valid = np.empty((len(t_start), len(k)), dtype=np.bool_)
    for p in range(len(t_start)):
        for i in range(len(k)):
            frac = min(max((k[i] * dt_s - (t_start[p] + hold_s)) * speed_mps / max(dz, 1e-9), 0.0), 1.0)
            for c in range(3):
                pos[p, i, c] = a[c] + frac * (b[c] - a[c])
            valid[p, i] = first[p] <= k[i] <= last[p]
    return k, pos, valid


def new_traffic(problems: list[VehicleProblem], cfg: Config) -> Traffic:
    """Empty traffic whose hash cells are twice the widest reach of a query: four cells per sample."""
    v_max = max(p.vehicle.speed_mps for p in problems)
    reach = max(p.vehicle.separation_m for p in problems) + cfg.separation_margin_m
    return Traffic(cfg.dt_s, cell_m=2.0 * (reach + (cfg.timing_error_s + 2.0 * cfg.dt_s) * v_max))


def _run_round(problems, obstacles, cfg, rng, order, init, elites, previous, progress, frac0, frac1):
    """Plan every UAV in ``order`` against the ones before it. Returns best x, cost, result per UAV."""
    traffic = new_traffic(problems, cfg)
    best_x, best_cost, results = {}, {}, {}
    for n, i in enumerate(order):
        prob = problems[i]
        kept = False
        if previous is not None and i in previous:
            c = float(CostModel(prob, obstacles, traffic, cfg)(previous[i][None, :])[0])
            if c < HARD_PENALTY:  # still feasible against the new higher-priority set: inherit it
                best_x[i], best_cost[i], kept = previous[i], c, True
        if not kept:
            base = previous[i] if previous is not None and i in previous else init[i]
            x0 = seed_swarm(prob, base, elites.get(i), cfg, rng)
            if previous is not None and i in previous:
                x0 = np.vstack([x0[:1], init[i][None, :], x0[1:]])[: cfg.particles]
            x, res, _ = optimise(prob, obstacles, traffic, cfg, rng, x0)
            best_x[i], best_cost[i], results[i] = x, res.best_cost, res
            elites[i] = res.pbest_x
        slices, pos = timed_samples(prob, best_x[i], cfg)
        traffic.add(slices, pos, prob.vehicle.separation_m, prob.vehicle.speed_mps)
        if progress:
            progress(frac0 + (frac1 - frac0) * (n + 1) / len(order), f"{prob.vehicle.id}")
    return best_x, best_cost, results


def build_vehicle_plan(prob: VehicleProblem, x: np.ndarray, cfg: Config, terms: dict) -> VehiclePlan:
    """Timed dense path, decimated mission waypoints and cost breakdown of one UAV."""
    v = prob.vehicle
    dec = decode(prob, x[None, :])
    n_leg = dec.lh.shape[1]
    r = v.turn_radius_m
    max_angle = 2.0 * math.acos(max(-1.0, 1.0 - cfg.waypoint_tol_m / r))
    dense_step = min(cfg.dt_s * v.speed_mps, 0.95 * r / 4.0)  # the checker measures radii on <= R/4
    wp_s, dense_s = [], []
    for leg in range(n_leg):
        seg = dec.seg[leg]
        bounds = np.concatenate([[0.0], np.cumsum(seg)])
        word = dec.word[leg]
        s_wp = [0.0]
        for k in range(3):
            curved = word < 4 and k != 1 or word >= 4
            n = max(1, math.ceil(seg[k] / r / max_angle)) if curved and seg[k] > 0 else 1
            s_wp.extend(bounds[k] + seg[k] * np.arange(1, n + 1) / n)
        lh = max(dec.lh[0, leg], 1e-12)
        f_wp = np.unique(np.clip(np.array(s_wp) / lh, 0, 1))
        n_dense = max(1, math.ceil(dec.lh[0, leg] / dense_step))
        f_dense = np.union1d(np.linspace(0, 1, n_dense + 1), f_wp)
        wp_s.append(dec.cum[0, leg] + f_wp * dec.l3[0, leg])
        dense_s.append(dec.cum[0, leg] + f_dense * dec.l3[0, leg])
    wp_s = np.unique(np.concatenate(wp_s))
    dense_s = np.unique(np.concatenate(dense_s))
    keep = np.concatenate([[True], np.diff(dense_s) > 1e-3])  # merge float-noise duplicates, keep both ends
    if not keep[-1]:
        keep[np.flatnonzero(keep)[-1]] = len(keep) == 1 or np.flatnonzero(keep)[-1] == 0
        keep[-1] = True
    dense_s = dense_s[keep]
    wp = positions_at_length(dec, wp_s[None, :])[0]
    dense = positions_at_length(dec, dense_s[None, :])[0]
    t_wp = prob.t_offset + wp_s / v.speed_mps
    t_dense = prob.t_offset + dense_s / v.speed_mps
    # drop waypoints closer than 0.5 m to the previous one (junctions that coincide)
    keep = np.concatenate([[True], np.linalg.norm(np.diff(wp, axis=0), axis=1) > 0.5])
    keep[-1] = True
    wp, t_wp = wp[keep], t_wp[keep]
    pre, post = prob.pre, prob.post
    t_end = float(t_dense[-1])
    if len(pre):
        wp, t_wp = np.vstack([pre, wp]), np.concatenate([[prob.delay_s], t_wp])
        dense, t_dense = np.vstack([pre, dense]), np.concatenate([[prob.delay_s], t_dense])
    if len(post):
        t_land = t_end + abs(post[0, 2] - prob.goal[2]) / v.speed_mps
        wp, t_wp = np.vstack([wp, post]), np.concatenate([t_wp, [t_land]])
        dense, t_dense = np.vstack([dense, post]), np.concatenate([t_dense, [t_land]])
    cost = {k: float(np.asarray(val)[0]) for k, val in terms.items()}
    cost["length_m"] = float(dec.total[0])
    return VehiclePlan(
        vehicle_id=v.id,
        sysid=v.sysid,
        vehicle_type=v.type,
        waypoints=wp,
        times_s=t_wp,
        speeds_mps=np.full(len(wp), v.speed_mps),
        path=dense,
        path_times_s=t_dense,
        turn_radius_m=r,
        takeoff_delay_s=prob.delay_s,
        acceptance_radius_m=cfg.acceptance_radius_m,
        cost=cost,
        feasible=cost["total"] < HARD_PENALTY,
    )


def build_plan(
    scenario, problems, obstacles, cfg, xs: dict, planner: str, metrics: dict, built: dict | None = None
) -> Plan:
    """Plan from the chosen particle per UAV (cost terms against all higher-priority UAVs).
    ``built`` keeps each UAV's VehiclePlan for the next call while its path and delay stay."""
    vehicles = []
    built = {} if built is None else built
    for prob in problems:
        x = xs[prob.index]
        key = (x.tobytes(), prob.delay_s)
        if prob.index not in built or built[prob.index][0] != key:
            terms = CostModel(prob, obstacles, Traffic(cfg.dt_s), cfg).terms(x[None, :])
            built[prob.index] = (key, build_vehicle_plan(prob, x, cfg, terms))
        vehicles.append(built[prob.index][1])
    return Plan(origin=scenario.origin, planner=planner, vehicles=vehicles, metrics=metrics)


def repair_and_check(
    scenario, problems, obstacles, cfg, rng, xs: dict, order: list[int], planner: str, metrics
):
    """Independent check; re-plan then delay conflicting UAVs; flag whatever still fails."""
    rank = {i: n for n, i in enumerate(order)}
    repairs = []
    memo: dict[int, tuple[bytes, float, tuple[np.ndarray, np.ndarray]]] = {}
    built: dict = {}

    def samples(prob: VehicleProblem, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """timed_samples, kept per UAV until its path or delay changes (every repair needs them all)."""
        key, delay = x.tobytes(), prob.delay_s
        if prob.index not in memo or memo[prob.index][:2] != (key, delay):
            memo[prob.index] = (key, delay, timed_samples(prob, x, cfg))
        return memo[prob.index][2]

    for attempt in range(cfg.repairs + 1):
        plan_ = build_plan(scenario, problems, obstacles, cfg, xs, planner, metrics, built)
        report = check_plan(plan_, scenario, step_s=cfg.dt_s, max_climb_rad=math.radians(cfg.max_climb_deg))
        if report.ok or attempt == cfg.repairs:
            break
        ids = {p.vehicle.id: p.index for p in problems}
        in_conflict = {c[0] for c in report.conflicts} | {c[1] for c in report.conflicts}
        losers = {_loser(problems, ids[a], ids[b], t, rank) for a, b, t, *_ in report.conflicts}
        losers |= {ids[v] for v in report.bad_vehicles() - in_conflict}
        for i in sorted(losers, key=lambda i: rank[i]):
            prob = problems[i]
            if attempt > 0:  # re-planning alone did not do it: wait on the ground as well
                prob.delay_s += cfg.delay_step_s
            traffic = new_traffic(problems, cfg)
            traffic.add_many(
                [
                    (*samples(other, xs[other.index]), other.vehicle.separation_m, other.vehicle.speed_mps)
                    for other in problems
                    if other.index != i
                ]
            )
            x0 = seed_swarm(prob, xs[i], None, cfg, rng)
            x, res, _ = optimise(prob, obstacles, traffic, cfg, rng, x0)
            if res.best_cost <= float(CostModel(prob, obstacles, traffic, cfg)(xs[i][None, :])[0]):
                xs[i] = x
            repairs.append(
                {
                    "attempt": attempt,
                    "vehicle": prob.vehicle.id,
                    "delay_s": prob.delay_s,
                    "cost": res.best_cost,
                }
            )
    bad = report.bad_vehicles()
    for vp in plan_.vehicles:
        if vp.vehicle_id in bad:
            vp.feasible = False
            vp.notes.append(f"independent check failed: {report.summary()}")
        elif not vp.feasible:
            vp.notes.append("cost has a hard-constraint term (see cost)")
        if vp.takeoff_delay_s > 0:
            vp.notes.append(f"take-off delayed {vp.takeoff_delay_s:.1f} s to keep separation")
        if vp.feasible:
            vp.notes.append(
                "independent check passed (obstacles, separation at 0.5 s, turn radius, band, climb)"
            )
    plan_.metrics["repairs"] = repairs
    plan_.metrics["check"] = report.summary()
    plan_.metrics["buffer_intrusions"] = report.buffer_intrusions
    return plan_


def _loser(problems, a: int, b: int, t_s: float, rank: dict[int, int]) -> int:
    """Which of two vehicles in conflict at t_s is re-planned: the one passing a vehicle that waits
    at its start (waits_airborne; delaying the waiting one would not help), else the lower priority."""
    for waiting, other in ((a, b), (b, a)):
        if problems[waiting].vehicle.waits_airborne and t_s < problems[waiting].delay_s:
            return other
    return max(a, b, key=lambda i: rank[i])


def check_options(scenario: Scenario, config: Config) -> dict:
    """The one checker samples at the planner's step and holds it to its climb limit."""
    del scenario
    return {"step_s": config.dt_s, "max_climb_rad": math.radians(config.max_climb_deg)}


def plan(
    scenario: Scenario, config: Config, rng: np.random.Generator, progress: Progress | None = None
) -> Plan:
    """Priority swarm planner: see the module docstring."""
    keep_heap_slack()  # its numpy temporaries reuse freed pages, also when called as a library
    t_start = time.perf_counter()
    tally = [0]
    token = EVALUATIONS.set(tally)
    try:
        return _plan(scenario, config, rng, progress, t_start, tally)
    finally:
        EVALUATIONS.reset(token)


def _plan(scenario: Scenario, cfg: Config, rng: np.random.Generator, progress, t_start, tally) -> Plan:
    problems, obstacles, lo, hi = prepare(scenario, cfg)
    if cfg.rrt_start:
        init, difficulty = initial_paths(problems, obstacles, lo, hi, cfg, rng)
    else:
        lines = [np.vstack([p.start, p.goal]) for p in problems]
        init = [resample_polyline(line, cfg.waypoints + 2)[1:-1].ravel() for line in lines]
        difficulty = np.ones(len(problems))
    if progress:
        progress(0.1, "initial paths")
    order = list(range(len(problems)))
    if cfg.priority_order:
        order.sort(key=lambda i: (-problems[i].vehicle.priority, -difficulty[i], i))
    elites: dict[int, np.ndarray] = {}
    previous = None
    best = None
    rounds = []
    convergence = np.zeros(cfg.iterations)  # summed gbest (clipped at HARD) of the first round's swarms
    to_1pct = []
    for r in range(cfg.rounds):
        frac0 = 0.1 + 0.8 * r / cfg.rounds
        xs, costs, results = _run_round(
            problems,
            obstacles,
            cfg,
            rng,
            order,
            init,
            elites,
            previous,
            progress,
            frac0,
            frac0 + 0.8 / cfg.rounds,
        )
        infeasible = [i for i in order if costs[i] >= HARD_PENALTY]
        total = float(sum(min(c, HARD_PENALTY) for c in costs.values()))
        rounds.append(
            {"round": r + 1, "infeasible": [problems[i].vehicle.id for i in infeasible], "cost": total}
        )
        for res in results.values():
            to_1pct.append(res.iterations_to_within(0.01))
            if r == 0:
                h = np.minimum(res.history, HARD_PENALTY)
                convergence[: len(h)] += h
        if best is None or (len(infeasible), total) < (best[0], best[1]):
            best = (len(infeasible), total, dict(xs), list(order))
        log.info("round %d: %d infeasible UAVs, cost %.3f", r + 1, len(infeasible), total)
        if not infeasible:
            break
        order = infeasible + [i for i in order if i not in infeasible]  # promote the infeasible UAVs
        previous = xs
    _, _, xs, order = best
    metrics = {
        "rounds": rounds,
        "priority_order": [problems[i].vehicle.id for i in order],
        "rrt_difficulty": {p.vehicle.id: float(d) for p, d in zip(problems, difficulty)},
    }
    result = repair_and_check(scenario, problems, obstacles, cfg, rng, xs, order, "priority_swarm", metrics)
    result.metrics["evaluations"] = tally[0]  # repair included
    result.metrics["cost_total"] = float(sum(min(v.cost["total"], HARD_PENALTY) for v in result.vehicles))
    result.metrics["feasible_count"] = sum(v.feasible for v in result.vehicles)
    result.metrics["wall_time_s"] = time.perf_counter() - t_start
    result.metrics["convergence"] = convergence.tolist()
    result.metrics["iterations_to_1pct"] = float(np.mean(to_1pct)) if to_1pct else 0.0
    if progress:
        progress(1.0, "checked")
    return result
