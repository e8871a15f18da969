"""ACMPSO 3-D track planning over terrain, radars and obstacles (seed 001, Wu et al. 2021).

One UAV's track from start to goal: a particle is n = 8 free waypoints; start, waypoints and goal
are smoothed by a cubic spline into N = 100 nodes, nodes below terrain + h_safe are lifted, and
the fitness F = phi1 f_L + phi2 f_R + phi3 f_C + phi4 f_H (eqs. 4-10) is evaluated for the whole
swarm at once. BPSO (constant w), LPSO (linear w) and ACMPSO (exponential w, eq. 17, plus
adaptive Cauchy mutation, eqs. 20-21) run on the shared engine gcs_planner.planning.pso.

Units: the fitness is computed in ``length_unit_m`` (1000: the paper's km, so F and its lower
bound 37.339 compare directly with the paper); scenarios and plans are in metres.

Choices where the paper is open (all documented, "literal" = our closest reading):
- Encoding: waypoint-major (x1, y1, z1, ..., x8, y8, z8); bounds = the scenario's box (the
  paper's 100 x 100 x 10 km space), positions clamped (step 7), |v| <= Vmax = 10 per coordinate.
- Spline: not-a-knot cubic through the 10 control points, uniform in point index, sampled at 100
  uniform parameter values (a fixed linear map: the whole swarm is smoothed by one matmul);
  repair applies to the nodes only, the particle itself is not changed.
- f_R: B = (delta / D)^4 when D <= R_k (3-D distance to the radar centre), delta = 10 km.
- f_C: eqs. 8-9 read literally: a node inside cylinder i (horizontal distance d < R_i and z at
  most the obstacle height) adds d, i.e. the penalty shrinks towards the axis. ``collision =
  "depth"`` adds R_i - d instead (monotone). Threats are checked at nodes only; the validator
  re-checks the flown path on a dense resample.
- f_H: population standard deviation of node altitudes (eq. 10).
- PSO: r1, r2 per particle and dimension; initial velocity zero; pbest on strict improvement;
  BPSO w = 0.9 constant (the paper gives no value); LPSO w 0.9 -> 0.4 over t = 1..Tmax; one
  iteration = one swarm evaluation (Tmax x S = 5000 evaluations per run).
- Mutation (literal): steps 4-7 order: after the bests are updated every particle's position is
  mutated, P' = P + P * CM * exp((1 - t) beta), CM standard Cauchy per coordinate, clamped to the
  space, not evaluated; the velocity update then starts from P'.

Variants (``variant``):
- "literal": particles initialised uniformly in the whole space (the paper says "random").
  Cannot reach the paper's Table 3 (ACMPSO about 39.5, variance about 1.8, see docs/acmpso.md).
- "tuned": every algorithm starts from the straight start-goal line plus Gaussian noise of
  ``init_noise`` x the space span per coordinate (the same initialisation for all three), and
  ACMPSO mutates only the global best with greedy acceptance (one extra evaluation per
  iteration, evaluated with the next swarm, 2 % of the budget, counted), the classic adaptive
  Cauchy-mutation PSO form. With it ACMPSO meets the paper's mean and variance, but ties LPSO.

From track to mission (not in the paper, see ``follow_terrain``): the 100-node track is resampled
every ``validate_spacing_m``, pushed clear of domes, cylinders and terrain + h_safe with
``margin_m``, climb-limited to ``max_climb_deg`` and thinned to waypoints; the paper's node track
and the flown waypoints are both validated on a dense resample and both reports go into the Plan.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Annotated, Any, Literal

import numpy as np
from msgspec import Meta
from scipy.interpolate import CubicSpline

from gcs_planner.core.config import (
    MAX_COUNT,
    Count,
    Distance,
    DistanceStep,
    NonNegative,
    Positive,
    PositiveDistance,
)
from gcs_planner.core.validation import MAX_ALT_M
from gcs_planner.model.plan import Plan, VehiclePlan
from gcs_planner.model.scenario import Scenario, ScenarioError, Vehicle
from gcs_planner.planning import PlannerConfig, Progress, Traits
from gcs_planner.planning.pso import CauchyMutation, PSOConfig, PSOResult, minimize
from gcs_planner.planning.threat_env import ThreatEnv, ValidationReport, resample_path, validate_path

__all__ = [
    "TRAITS",
    "ALGORITHMS",
    "NAME",
    "Config",
    "TrackProblem",
    "TrackResult",
    "Weights",
    "algorithm_config",
    "follow_terrain",
    "limit_gradient",
    "line_init",
    "plan",
    "problem_from_scenario",
    "solve",
]

logger = logging.getLogger(__name__)
MAX_LEG = 64  # longest mission leg, in dense samples (6.4 km at 100 m)
NAME = "acmpso"
TRAITS = Traits(reads=("obstacles", "bounds", "terrain", "site"))
ALGORITHMS = ("acmpso", "lpso", "bpso")
VARIANTS = ("literal", "tuned", "safe")
# The safe fitness samples the flown polyline at most SAFETY_SPACING_M apart and keeps
# SAFETY_MARGIN_M clear: a chord of length s between two clear samples cuts at most s^2 / (8 R)
# into a convex volume of radius R (5.6 m for the paper's 2 km cylinders, 1.9 m for its 6 km
# domes; less for its peaks), so the track itself is clear everywhere, not only at samples.
SAFETY_SPACING_M = 300.0
SAFETY_MARGIN_M = 15.0
SAFETY_WEIGHT = 1000.0  # per fitness unit of depth: any violation outweighs the whole of F
COLLISION_TERMS = ("literal", "depth")


@dataclass(frozen=True)
class Weights:
    """phi_1..phi_4 of eq. 4 (paper Table 2)."""

    length: float = 0.3
    radar: float = 4.85
    collision: float = 4.85
    height: float = 0.07


@dataclass(frozen=True)
class TrackProblem:
    """The track-planning fitness of eqs. 4-10 over a swarm of waypoint vectors.

    A particle is ``n_waypoints`` free (x, y, z) waypoints (3 n variables, flattened waypoint-major);
    start and goal are fixed. Lengths are in the fitness unit (km for the paper): the env, start,
    goal, bounds and radar_strength (delta) must already be in it.
    """

    env: ThreatEnv
    start: np.ndarray
    goal: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    n_waypoints: int = 8
    n_nodes: int = 100
    weights: Weights = field(default_factory=Weights)
    radar_strength: float = 10.0
    collision: str = "literal"
    length_unit_m: float = 1.0  # metres per length unit
    safety_spacing: float = 0.0  # > 0: the "safe" fitness, checked on samples at most this far apart
    safety_margin: float = 0.0  # clearance the safe fitness adds to every threat and the floor

    def __post_init__(self) -> None:
        for name in ("start", "goal", "lower", "upper"):
            object.__setattr__(self, name, np.asarray(getattr(self, name), dtype=float).reshape(3))
        if self.collision not in COLLISION_TERMS:
            raise ValueError(f"collision must be one of {COLLISION_TERMS}, got {self.collision!r}")
        if self.n_waypoints < 1 or self.n_nodes < 2:
            raise ValueError(
                f"need n_waypoints >= 1 and n_nodes >= 2, got {self.n_waypoints}, {self.n_nodes}"
            )

    @cached_property
    def spline_matrix(self) -> np.ndarray:
        """(N, n + 2): not-a-knot cubic spline through the control points, uniform in index.

        Spline interpolation is linear in the data, so smoothing the whole swarm is one matmul.
        """
        k = self.n_waypoints + 2
        knots = np.arange(k, dtype=float)
        return CubicSpline(knots, np.eye(k), axis=0, bc_type="not-a-knot")(
            np.linspace(0.0, k - 1.0, self.n_nodes)
        )

    @property
    def dim(self) -> int:
        return 3 * self.n_waypoints

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return np.tile(self.lower, self.n_waypoints), np.tile(self.upper, self.n_waypoints)

    def control_points(self, x: np.ndarray) -> np.ndarray:
        """(P, n + 2, 3): start, the particle's waypoints, goal."""
        x = np.atleast_2d(x)
        w = x.reshape(len(x), self.n_waypoints, 3)
        ends = np.broadcast_to(self.start, (len(x), 1, 3)), np.broadcast_to(self.goal, (len(x), 1, 3))
        return np.concatenate([ends[0], w, ends[1]], axis=1)

    @cached_property
    def _spline_parts(self) -> tuple[np.ndarray, np.ndarray]:
        """(n, N) weights of the free waypoints and (N, 3) fixed contribution of start and goal."""
        m = self.spline_matrix
        return np.ascontiguousarray(m[:, 1:-1].T), np.outer(m[:, 0], self.start) + np.outer(
            m[:, -1], self.goal
        )

    def _node_xyz(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Smoothed, altitude-repaired node coordinates as three (P, N) arrays (fast layout)."""
        x = np.atleast_2d(x)
        mid, fixed = self._spline_parts
        nx = x[:, 0::3] @ mid + fixed[:, 0]
        ny = x[:, 1::3] @ mid + fixed[:, 1]
        nz = np.maximum(x[:, 2::3] @ mid + fixed[:, 2], self.env.floor(nx, ny))
        if self.safety_spacing:  # safe: the interior nodes clear the margin too, and so do the chords
            inner = self.env.floor(nx[:, 1:-1], ny[:, 1:-1]) + self.safety_margin
            nz[:, 1:-1] = np.maximum(nz[:, 1:-1], inner)
            nz = self._lift_chords(nx, ny, nz)
        return nx, ny, nz

    def _lift_chords(self, nx: np.ndarray, ny: np.ndarray, nz: np.ndarray) -> np.ndarray:
        """The safe variant's repair of eq. 3 between nodes: both ends of a segment whose chord
        passes below terrain + h_safe + margin at one of its samples are raised by the largest
        shortfall, so the whole chord rises by it (a node takes the larger of its two segments'; the
        start and the goal stay where the scenario puts them)."""
        u = self._chord_samples(nx, ny, nz)
        sx = nx[:, :-1, None] + np.diff(nx, axis=1)[..., None] * u
        sy = ny[:, :-1, None] + np.diff(ny, axis=1)[..., None] * u
        sz = nz[:, :-1, None] + np.diff(nz, axis=1)[..., None] * u
        need = np.maximum(self.env.floor(sx, sy) + self.safety_margin - sz, 0.0).max(axis=-1)  # (P, N - 1)
        raise_by = np.zeros_like(nz)
        np.maximum(raise_by[:, :-1], need, out=raise_by[:, :-1])
        np.maximum(raise_by[:, 1:], need, out=raise_by[:, 1:])
        raise_by[:, [0, -1]] = 0.0
        return nz + raise_by

    def _chord_samples(self, nx: np.ndarray, ny: np.ndarray, nz: np.ndarray) -> np.ndarray:
        """Sample positions u in [0, 1) along each node segment, at most ``safety_spacing`` apart."""
        legs = np.diff(nx, axis=1) ** 2 + np.diff(ny, axis=1) ** 2 + np.diff(nz, axis=1) ** 2
        longest = float(np.sqrt(legs.max()))
        samples = max(1, math.ceil(longest / self.safety_spacing))
        return np.arange(samples) / samples

    def nodes(self, x: np.ndarray) -> np.ndarray:
        """(P, N, 3): the smoothed track of each particle, altitude-repaired above terrain."""
        return np.stack(self._node_xyz(x), axis=-1)

    def terms(self, x: np.ndarray) -> dict[str, np.ndarray]:
        """Unweighted f_L, f_R, f_C, f_H (eqs. 5-10), each (P,)."""
        return self._terms(*self._node_xyz(x))

    def _terms(self, nx: np.ndarray, ny: np.ndarray, nz: np.ndarray) -> dict[str, np.ndarray]:
        dx, dy, dz = np.diff(nx, axis=1), np.diff(ny, axis=1), np.diff(nz, axis=1)
        f_l = np.sqrt(dx * dx + dy * dy + dz * dz).sum(axis=1)
        env = self.env
        f_r = np.zeros(len(nx))
        delta4 = self.radar_strength**4
        for (cx, cy, cz), r in zip(env.radar_xyz, env.radar_r, strict=True):
            d2 = _sq_dist(nx, cx) + _sq_dist(ny, cy)
            d2 += _sq_dist(nz, cz)
            inside = d2 <= r * r
            if inside.any():
                np.maximum(d2, 1e-300, out=d2)
                f_r += np.where(inside, delta4 / (d2 * d2), 0.0).sum(axis=1)
        f_c = np.zeros(len(nx))
        for (cx, cy), r, z0, z1 in zip(env.cyl_xy, env.cyl_r, env.cyl_zmin, env.cyl_zmax, strict=True):
            d2 = _sq_dist(nx, cx) + _sq_dist(ny, cy)
            inside = d2 < r * r
            if inside.any():
                inside &= (nz <= z1) & (nz >= z0)
                d = np.sqrt(d2)
                f_c += np.where(inside, d if self.collision == "literal" else r - d, 0.0).sum(axis=1)
        f_h = nz.std(axis=1)
        return {"length": f_l, "radar": f_r, "collision": f_c, "height": f_h}

    def objective(self, x: np.ndarray) -> np.ndarray:
        """F of eq. 4 for each particle, (P,)."""
        return self._objective(self.terms(x))

    def _objective(self, t: dict[str, np.ndarray]) -> np.ndarray:
        w = self.weights
        f = w.length * t["length"] + w.radar * t["radar"] + w.collision * t["collision"]
        return f + w.height * t["height"]

    def fitness(self, x: np.ndarray) -> np.ndarray:
        """What the swarm minimises: F, plus the safety penalty in the safe variant (the nodes,
        the hot path, are built once for both)."""
        xyz = self._node_xyz(x)
        f = self._objective(self._terms(*xyz))
        return f + self._penalty(np.stack(xyz, axis=-1)) if self.safety_spacing else f

    def safety_penalty(self, x: np.ndarray) -> np.ndarray:
        """(P,): how far the flown track (the node polyline, sampled at most ``safety_spacing``
        apart) enters a radar dome, a cylinder or terrain + h_safe, each grown by
        ``safety_margin``: SAFETY_WEIGHT x the summed depth plus 1 per sample inside. The paper
        checks its threats at the nodes only, so its optimum may cut through them in between."""
        return self._penalty(self.nodes(x))

    def _penalty(self, nodes: np.ndarray) -> np.ndarray:
        u = self._chord_samples(nodes[..., 0], nodes[..., 1], nodes[..., 2])
        seg = nodes[:, :-1, None, :] + (nodes[:, 1:, None, :] - nodes[:, :-1, None, :]) * u[:, None]
        pts = np.concatenate([seg.reshape(len(nodes), -1, 3), nodes[:, -1:]], axis=1)
        m = self.safety_margin
        depth = np.maximum(self.env.floor(pts[..., 0], pts[..., 1]) + m - pts[..., 2], 0.0)
        if len(self.env.radar_r):
            depth += np.maximum(self.env.radar_depth(pts) + m, 0.0).sum(axis=-1)
        if len(self.env.cyl_r):
            depth += np.maximum(self.env.cylinder_depth(pts) + m, 0.0).sum(axis=-1)
        return SAFETY_WEIGHT * depth.sum(axis=1) + (depth > 0).sum(axis=1)


def _sq_dist(a: np.ndarray, c: float) -> np.ndarray:
    d = a - c
    d *= d
    return d


def algorithm_config(
    algorithm: str, variant: str = "literal", particles: int = 50, iterations: int = 100, v_max: float = 10.0
) -> PSOConfig:
    """PSOConfig of BPSO / LPSO / ACMPSO with the paper's Table 2 parameters."""
    if algorithm not in ALGORITHMS:
        raise ValueError(f"algorithm must be one of {ALGORITHMS}, got {algorithm!r}")
    if variant not in VARIANTS:
        raise ValueError(f"variant must be one of {VARIANTS}, got {variant!r}")
    inertia = {"bpso": "constant", "lpso": "linear", "acmpso": "exponential"}[algorithm]
    mutation = CauchyMutation(beta=0.5) if algorithm == "acmpso" else None
    return PSOConfig(
        particles=particles,
        iterations=iterations,
        c1=1.5,
        c2=1.5,
        inertia=inertia,
        w_max=0.9,
        w_min=0.4,
        alpha=0.03,
        v_max=v_max,
        mutation=mutation,
        mutation_stage="before_velocity" if variant == "literal" else "gbest_greedy",
    )


def line_init(problem: TrackProblem, particles: int, noise: float, rng: np.random.Generator) -> np.ndarray:
    """(P, 3 n) waypoints evenly on the start-goal line plus N(0, (noise x span)^2), clamped."""
    frac = np.arange(1, problem.n_waypoints + 1) / (problem.n_waypoints + 1)
    base = (problem.start + frac[:, None] * (problem.goal - problem.start)).reshape(-1)
    lower, upper = problem.bounds()
    return np.clip(
        base + rng.normal(0.0, 1.0, (particles, problem.dim)) * noise * (upper - lower), lower, upper
    )


@dataclass
class TrackResult:
    """Best track of one run: x (3 n,), nodes (N, 3), F, its terms, the PSO result, wall and CPU time [s]."""

    x: np.ndarray
    nodes: np.ndarray
    fitness: float
    terms: dict[str, float]
    pso: PSOResult
    seconds: float
    cpu_seconds: float


def solve(
    problem: TrackProblem,
    algorithm: str,
    rng: np.random.Generator,
    variant: str = "literal",
    particles: int = 50,
    iterations: int = 100,
    v_max: float = 10.0,
    init_noise: float = 0.05,
    progress: Progress | None = None,
) -> TrackResult:
    """One independent run of ``algorithm`` on ``problem`` (times the initialisation and the swarm)."""
    cfg = algorithm_config(algorithm, variant, particles, iterations, v_max)
    lower, upper = problem.bounds()
    optimised = problem
    if variant == "safe" and not problem.safety_spacing:
        spacing, margin = SAFETY_SPACING_M / problem.length_unit_m, SAFETY_MARGIN_M / problem.length_unit_m
        optimised = replace(problem, safety_spacing=spacing, safety_margin=margin)
    t0, c0 = time.perf_counter(), time.process_time()
    init = line_init(problem, particles, init_noise, rng) if variant != "literal" else None
    res = minimize(optimised.fitness, lower, upper, cfg, rng, init=init, progress=progress)
    seconds, cpu_seconds = time.perf_counter() - t0, time.process_time() - c0
    best = res.best_x[None, :]
    terms = {k: float(v[0]) for k, v in optimised.terms(best).items()}
    if optimised.safety_spacing:
        terms["safety"] = float(optimised.safety_penalty(best)[0])
    f = float(optimised.objective(best)[0])  # eq. 4 of the track found (without the safety penalty)
    return TrackResult(res.best_x, optimised.nodes(best)[0], f, terms, res, seconds, cpu_seconds)


class Config(PlannerConfig, tag=NAME):
    """The [planner] table (all lengths in metres; defaults = the paper's Table 2)."""

    algorithm: Literal["acmpso", "lpso", "bpso"] = "acmpso"
    variant: Literal["literal", "tuned", "safe"] = "safe"
    particles: Count = 50
    iterations: Count = 100
    n_waypoints: Count = 8
    n_nodes: Annotated[int, Meta(ge=2, le=MAX_COUNT)] = 100  # nodes of the path polyline: both ends
    length_unit_m: PositiveDistance = 1000.0
    h_safe_m: Annotated[float, Meta(gt=0.0, le=MAX_ALT_M)] = 500.0
    radar_strength_m: Positive = 10000.0
    v_max_m: Positive = 10000.0
    weights: tuple[NonNegative, NonNegative, NonNegative, NonNegative] = (0.3, 4.85, 4.85, 0.07)
    collision: Literal["literal", "depth"] = "literal"
    init_noise: Positive = 0.05
    validate_spacing_m: DistanceStep = 100.0
    follow_tolerance_m: PositiveDistance = 50.0
    max_climb_deg: Annotated[float, Meta(gt=0.0, le=90.0)] = 10.0
    margin_m: Distance = 25.0


def problem_from_scenario(
    scenario: Scenario, vehicle: Vehicle, params: Config
) -> tuple[TrackProblem, ThreatEnv]:
    """The vehicle's TrackProblem in fitness units and the environment in metres."""
    missing = [axis for axis in "xyz" if axis not in scenario.bounds]
    if missing:
        raise ScenarioError(f"{scenario.name}: bounds.{missing[0]} is required by the acmpso planner")
    env_m = ThreatEnv.from_scenario(scenario, params.h_safe_m)
    k = 1.0 / params.length_unit_m
    lower = np.array([scenario.bounds[a][0] for a in "xyz"]) * k
    upper = np.array([scenario.bounds[a][1] for a in "xyz"]) * k
    problem = TrackProblem(
        env=env_m.scaled(k),
        start=np.asarray(vehicle.start) * k,
        goal=np.asarray(vehicle.goal) * k,
        lower=lower,
        upper=upper,
        n_waypoints=params.n_waypoints,
        n_nodes=params.n_nodes,
        weights=Weights(*params.weights),
        radar_strength=params.radar_strength_m * k,
        collision=params.collision,
        length_unit_m=params.length_unit_m,
    )
    return problem, env_m


def follow_terrain(
    env: ThreatEnv,
    track: np.ndarray,
    spacing_m: float,
    tolerance_m: float,
    margin_m: float = 5.0,
    max_climb_deg: float | None = None,
) -> np.ndarray:
    """Mission waypoints (K, 3) [m] that fly ``track`` clear of terrain, radars and obstacles.

    The track is resampled every ``spacing_m``; samples are pushed out of radar domes and
    cylinders and lifted to terrain + h_safe, each with ``margin_m`` to spare (the paper repairs and
    checks only its 100 nodes, ~1.3 km apart, so the legs between them can cut into convex slopes
    or graze a dome). Waypoints are then thinned greedily: a leg grows while it stays within
    ``tolerance_m`` of the cleaned track and its own resample (every spacing_m / 2) keeps
    ``margin_m / 2`` clear of every volume (a straight leg between two clear points can still cut a
    convex dome, cylinder or slope; the half margin covers the sag between the check samples), or
    is no deeper than the samples it replaces where those could not be cleaned.

    ``max_climb_deg`` (the paper has no vehicle limit) caps the climb and descent angle: samples are
    only ever raised - climbs start early enough, descents end late enough - alternating with the
    push-out so the raised profile stays clear (three rounds; what remains is left to the validator).
    Descending legs are then also checked as an autopilot without glide slope flies them (see
    ``_longest_leg``).
    """
    dense = env.push_out(resample_path(track, spacing_m), margin_m)
    gradient = None if max_climb_deg is None else float(np.tan(np.radians(max_climb_deg)))
    if gradient is not None:
        for _ in range(3):
            dense[:, 2] = limit_gradient(dense, gradient)
            dense = env.push_out(dense, margin_m)
        dense[:, 2] = limit_gradient(dense, gradient)  # exact limit last; it only raises points
    own = np.max(
        np.column_stack(
            [
                env.radar_depth(dense),
                env.cylinder_depth(dense),
                env.floor(dense[:, 0], dense[:, 1]) - dense[:, 2],
                np.zeros(len(dense)),
            ]
        ),
        axis=1,
    )
    keep = [0]
    while keep[-1] < len(dense) - 1:
        keep.append(_longest_leg(env, dense, own, keep[-1], tolerance_m, margin_m / 2, gradient))
    return dense[keep]


def limit_gradient(points: np.ndarray, gradient: float) -> np.ndarray:
    """Altitudes of the (M, 3) polyline raised (never lowered) so |dz| <= gradient x horizontal step.

    Backward pass: z_i >= z_{i+1} - g ds (climb early); forward pass: z_i >= z_{i-1} - g ds
    (descend late). Raising a point only eases the climb into it, so after both passes every
    step satisfies the limit, and the result is the lowest such profile above the input.
    """
    z = points[:, 2].copy()
    ds = np.linalg.norm(np.diff(points[:, :2], axis=0), axis=1) * gradient
    for i in range(len(z) - 2, -1, -1):
        z[i] = max(z[i], z[i + 1] - ds[i])
    for i in range(1, len(z)):
        z[i] = max(z[i], z[i - 1] - ds[i - 1])
    return z


def _longest_leg(
    env: ThreatEnv,
    dense: np.ndarray,
    own: np.ndarray,
    i: int,
    tolerance_m: float,
    clearance_m: float,
    dive_gradient: float | None,
) -> int:
    """End j of the longest leg i -> j (at most MAX_LEG samples) whose every shorter leg also passes.

    All candidate legs are checked at once: each is sampled at twice the track's resolution. With
    ``dive_gradient`` a descending leg is checked as flown by an autopilot that goes for the next
    altitude at once (no glide slope, like the mock fixed wing): max(z_j, z_i - g s), which lies
    below the straight line whenever the descent is no steeper than g.
    """
    js = np.arange(i + 1, min(i + MAX_LEG, len(dense) - 1) + 1)
    lengths = js - i
    steps = np.arange(2 * lengths[-1] + 1)
    frac = np.minimum(steps[None, :] / (2.0 * lengths[:, None]), 1.0)  # (m, S), padded with the end point
    chord = dense[i] + frac[..., None] * (dense[js] - dense[i])[:, None, :]
    if dive_gradient is not None:
        h = np.linalg.norm(dense[js, :2] - dense[i, :2], axis=1)
        steep = np.abs(dense[js, 2] - dense[i, 2]) > dive_gradient * h + 1e-9
        run = frac * h[:, None]
        dive = np.maximum(dense[js, 2][:, None], dense[i, 2] - dive_gradient * run)
        chord[..., 2] = np.minimum(chord[..., 2], dive)
    track = dense[np.minimum(i + np.arange(lengths[-1] + 1)[None, :], js[:, None])]
    deviation = np.max(np.abs(chord[:, ::2] - track), axis=(1, 2))
    depth = np.max(env.floor(chord[..., 0], chord[..., 1]) - chord[..., 2], axis=1)
    if len(env.radar_r):
        depth = np.maximum(depth, env.radar_depth(chord).max(axis=(1, 2)))
    if len(env.cyl_r):
        depth = np.maximum(depth, env.cylinder_depth(chord).max(axis=(1, 2)))
    allowed = np.maximum.accumulate(np.maximum(own[js], own[i])) - clearance_m
    ok = (deviation <= tolerance_m) & (depth <= allowed)
    if dive_gradient is not None:
        ok &= ~steep  # a chord is shorter than the path it replaces: its slope can exceed the limit
    ok[0] = True  # adjacent samples are always joined: nothing finer to fly
    return int(js[np.argmin(ok) - 1] if not ok.all() else js[-1])


def check_options(scenario: Scenario, config: Config) -> dict:
    """The one checker holds ACMPSO's plans to its climb limit, its safe height over the
    scenario's terrain and its cylinders' buffers as keep-out (as its own validation does); not to
    a turn radius: its plans are waypoint polylines whose corners the autopilot rounds."""
    env = ThreatEnv.from_scenario(scenario, config.h_safe_m)
    return {
        "max_climb_rad": math.radians(config.max_climb_deg),
        "floor": env.floor,
        "hard_buffers": True,
        "kinematics": False,
    }


def plan(
    scenario: Scenario, params: Config, rng: np.random.Generator, progress: Progress | None = None
) -> Plan:
    """Plan every vehicle's track independently with the scenario's [planner] parameters."""
    vehicles = []
    metrics: dict[str, Any] = {"algorithm": params.algorithm, "variant": params.variant}
    n = len(scenario.vehicles)
    for idx, vehicle in enumerate(scenario.vehicles):
        problem, env_m = problem_from_scenario(scenario, vehicle, params)

        def step(fraction: float, message: str, idx: int = idx, vid: str = vehicle.id) -> None:
            if progress is not None:
                progress((idx + fraction) / n, f"{vid}: {message}")

        result = solve(
            problem,
            params.algorithm,
            rng,
            params.variant,
            params.particles,
            params.iterations,
            params.v_max_m / params.length_unit_m,
            params.init_noise,
            step,
        )
        nodes_m = result.nodes * params.length_unit_m
        waypoints = follow_terrain(
            env_m,
            nodes_m,
            params.validate_spacing_m,
            params.follow_tolerance_m,
            margin_m=params.margin_m,
            max_climb_deg=params.max_climb_deg,
        )
        node_report = validate_path(env_m, nodes_m, params.validate_spacing_m)
        flown_report = validate_path(env_m, waypoints, params.validate_spacing_m)
        vehicles.append(_vehicle_plan(vehicle, waypoints, result, node_report, flown_report, params))
        metrics[vehicle.id] = {
            "fitness": result.fitness,
            "seconds": result.seconds,
            "evaluations": result.pso.evaluations,
            "iterations_to_1pct": result.pso.iterations_to_within(0.01),
            "history": result.pso.history.round(6).tolist(),
        }
        logger.info(
            "%s: F = %.4f in %.3f s, %d waypoints", vehicle.id, result.fitness, result.seconds, len(waypoints)
        )
    return Plan(origin=scenario.origin, planner=NAME, vehicles=vehicles, metrics=metrics)


def _vehicle_plan(
    vehicle: Vehicle,
    waypoints: np.ndarray,
    result: TrackResult,
    node_report: ValidationReport,
    flown_report: ValidationReport,
    params: Config,
) -> VehiclePlan:
    seg = np.linalg.norm(np.diff(waypoints, axis=0), axis=1)
    times = np.concatenate([[0.0], np.cumsum(seg) / vehicle.speed_mps])
    path = resample_path(waypoints, params.validate_spacing_m)
    path_seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
    path_times = np.concatenate([[0.0], np.cumsum(path_seg) / vehicle.speed_mps])
    cost = {"fitness": result.fitness, **{f"f_{k}": v for k, v in result.terms.items()}}
    cost["length_m"] = float(seg.sum())
    cost.update({f"nodes_{k}": v for k, v in node_report.summary().items()})
    cost.update({f"flown_{k}": v for k, v in flown_report.summary().items()})
    d = np.diff(waypoints, axis=0)
    climb_deg = np.degrees(np.arctan2(np.abs(d[:, 2]), np.hypot(d[:, 0], d[:, 1])))
    cost["max_climb_deg"] = float(climb_deg.max(initial=0.0))
    climb_ok = cost["max_climb_deg"] <= params.max_climb_deg + 1e-6
    notes = [
        f"{params.algorithm} ({params.variant}): F = {result.fitness:.4f} (paper units, length unit"
        f" {params.length_unit_m:g} m), {len(waypoints)} terrain-following waypoints,"
        " z = metres above the origin",
    ]
    notes += [
        f"flown path violation: {v.kind} {v.index} samples {v.first}-{v.last} depth {v.depth:.1f} m"
        for v in flown_report.violations
    ]
    if not climb_ok:
        notes.append(
            f"climb angle {cost['max_climb_deg']:.1f} deg exceeds max_climb_deg {params.max_climb_deg:g}"
        )
    goal_z = float(vehicle.goal[2])
    if waypoints[-1, 2] > goal_z + 1.0:
        notes.append(
            f"goal altitude raised from {goal_z:.0f} m to {waypoints[-1, 2]:.0f} m"
            " (terrain, threats or climb limit)"
        )
    notes += [
        f"smoothed nodes (paper track) violation: {v.kind} {v.index} depth {v.depth:.1f} m"
        for v in node_report.violations
    ]
    return VehiclePlan(
        vehicle_id=vehicle.id,
        sysid=vehicle.sysid,
        vehicle_type=vehicle.type,
        waypoints=waypoints,
        times_s=times,
        speeds_mps=np.full(len(times), vehicle.speed_mps),
        path=path,
        path_times_s=path_times,
        turn_radius_m=vehicle.turn_radius_m,
        final_action="loiter" if vehicle.type == "fixed_wing" else "land",
        acceptance_radius_m=max(2.0, min(params.follow_tolerance_m, 0.5 * float(seg.min(initial=1e9)))),
        cost=cost,
        feasible=flown_report.ok and climb_ok,
        notes=notes,
    )
