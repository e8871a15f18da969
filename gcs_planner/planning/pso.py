"""Vectorised particle swarm optimiser shared by the PSO-based planners (priority swarm, 4-D, ACMPSO).

API (stable; other planners build on it)::

    from gcs_planner.planning.pso import PSOConfig, CauchyMutation, minimize

    cfg = PSOConfig(particles=50, iterations=100, inertia="exponential", w_max=0.9, w_min=0.4,
                    alpha=0.03, c1=1.5, c2=1.5, v_max=10.0, mutation=CauchyMutation(beta=0.5))
    res = minimize(cost, lower, upper, cfg, rng, init=None, progress=None)
    res.best_x (D,), res.best_cost, res.history (iterations,), res.evaluations, res.iterations,
    res.pbest_x (P, D) / res.pbest_cost (P,) sorted best first (elites for the next call),
    res.iterations_to_within(0.01)

- ``cost(X: (P, D)) -> (P,)`` evaluates the whole swarm at once; NaN counts as +inf.
- ``lower``/``upper``: (D,) position bounds; positions are clamped to them after every move.
- ``v_max``: scalar or (D,) velocity bound [same units as x per iteration]; None means
  ``v_max_fraction * (upper - lower)``.
- ``init``: (K, D) particles supplied by the caller (inherited paths, previous elites), K <= P;
  the other P - K particles are drawn uniformly in the bounds (injected random particles).
- ``restarts``: extra rounds after the first; each keeps the ``elite_fraction`` best personal
  bests (position and memory) and re-draws the rest uniformly, velocities reset; gbest persists.
- ``max_evaluations``: stop before a swarm evaluation would exceed this budget (equal budgets
  for baselines); ``res.evaluations`` counts every cost row evaluated.
- ``progress(fraction, message)`` is called once per iteration.

One iteration = evaluate the swarm, update personal/global bests (strict improvement), record
gbest in ``history``, then (unless it is the last iteration) optionally mutate, compute
``v <- w v + c1 r1 (pbest - x) + c2 r2 (gbest - x)``, clamp ``|v| <= v_max`` per dimension,
``x <- x + v`` and clamp to the bounds. ``iterations`` swarm evaluations cost exactly
``iterations * particles`` cost rows, as in the ACMPSO paper (Tmax evaluations of S particles).

Inertia schedules, with t = 1..T (T = iterations per round):
- ``constant``: w = w_max;
- ``linear``: w = w_max - (w_max - w_min) (t - 1) / (T - 1)  (0.9 -> 0.4 exactly at the ends);
- ``exponential`` (ACMPSO eq. 17): w = (w_max - w_min) exp((1 - t) alpha) + w_min.

Mutation hook: any callable ``mutation(x, t, t_max, rng) -> x'`` (x is (P, D), t is 1-based).
``mutation_stage`` says where it runs: ``"before_velocity"`` (ACMPSO's step order: steps 4-5
mutate the evaluated positions, then step 7 moves from the mutated positions; mutated points are
not evaluated themselves) or ``"after_move"`` (mutate the new positions before they are
evaluated) or ``"gbest_greedy"`` (after the bests are updated, mutate a copy of the global best;
it is evaluated as one extra row of the next swarm evaluation - one call, one extra counted cost
row per iteration - and replaces gbest only if strictly better, so acceptance lags one iteration).
:class:`CauchyMutation` implements eqs. 20-21.

Choices where PSO papers are open (documented so runs are reproducible):
r1, r2 are drawn per particle and per dimension by default (``per_dimension_random``); initial
velocities are uniform in ``+-init_velocity * v_max`` (0 = at rest); the random draws happen in
a fixed order from the caller's Generator, so a seed fixes the whole run.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from gcs_planner.planning import Progress

__all__ = ["CauchyMutation", "Mutation", "PSOConfig", "PSOResult", "inertia_weight", "minimize"]

Cost = Callable[[np.ndarray], np.ndarray]
Mutation = Callable[[np.ndarray, int, int, np.random.Generator], np.ndarray]

INERTIA_SCHEDULES = ("constant", "linear", "exponential")
MUTATION_STAGES = ("before_velocity", "after_move", "gbest_greedy")


@dataclass(frozen=True)
class CauchyMutation:
    """Adaptive Cauchy mutation (ACMPSO eqs. 20-21): x' = x + s * CM * exp((1 - t) beta).

    CM = tan(pi (U - 1/2)) is standard Cauchy. ``relative=True`` is the paper's multiplicative form
    (s = x, so the step scales with the coordinate); ``relative=False`` uses s = ``scale`` (a
    scalar or (D,) array, e.g. a fraction of the bound span). ``per_dimension`` draws one CM per
    coordinate (the paper's notation leaves it open; one CM per particle is the alternative).
    """

    beta: float = 0.5
    relative: bool = True
    scale: float | np.ndarray = 1.0
    per_dimension: bool = True

    def __call__(self, x: np.ndarray, t: int, t_max: int, rng: np.random.Generator) -> np.ndarray:
        del t_max
        shape = x.shape if self.per_dimension else (x.shape[0], 1)
        cm = np.tan(np.pi * (rng.random(shape) - 0.5))
        step = math.exp((1 - t) * self.beta) * cm
        return x + (x if self.relative else np.asarray(self.scale, dtype=float)) * step


@dataclass(frozen=True)
class PSOConfig:
    """Swarm size, schedule and bounds handling; see the module docstring for the semantics."""

    particles: int = 50
    iterations: int = 100
    c1: float = 1.5
    c2: float = 1.5
    inertia: str = "linear"
    w_max: float = 0.9
    w_min: float = 0.4
    alpha: float = 0.03
    v_max: float | np.ndarray | None = None
    v_max_fraction: float = 0.2
    init_velocity: float = 0.0
    per_dimension_random: bool = True
    mutation: Mutation | None = None
    mutation_stage: str = "before_velocity"
    restarts: int = 0
    elite_fraction: float = 0.1
    max_evaluations: int | None = None

    def __post_init__(self) -> None:
        if self.particles < 1:
            raise ValueError(f"PSOConfig.particles must be >= 1, got {self.particles!r}")
        if self.iterations < 1:
            raise ValueError(f"PSOConfig.iterations must be >= 1, got {self.iterations!r}")
        if self.inertia not in INERTIA_SCHEDULES:
            raise ValueError(f"PSOConfig.inertia must be one of {INERTIA_SCHEDULES}, got {self.inertia!r}")
        if self.mutation_stage not in MUTATION_STAGES:
            raise ValueError(
                f"PSOConfig.mutation_stage must be one of {MUTATION_STAGES}, got {self.mutation_stage!r}"
            )
        if self.restarts < 0:
            raise ValueError(f"PSOConfig.restarts must be >= 0, got {self.restarts!r}")
        if not 0.0 <= self.elite_fraction <= 1.0:
            raise ValueError(f"PSOConfig.elite_fraction must be in [0, 1], got {self.elite_fraction!r}")
        if self.max_evaluations is not None and self.max_evaluations < 1:
            raise ValueError(f"PSOConfig.max_evaluations must be >= 1, got {self.max_evaluations!r}")


@dataclass
class PSOResult:
    """Outcome of :func:`minimize`.

    history[i] is the global best cost after iteration i + 1 (all rounds concatenated);
    pbest_x / pbest_cost are the final personal bests sorted best first (use the head as elites).
    """

    best_x: np.ndarray
    best_cost: float
    history: np.ndarray
    evaluations: int
    iterations: int
    pbest_x: np.ndarray
    pbest_cost: np.ndarray
    rounds: int = 1
    stopped_by_budget: bool = False
    extra: dict = field(default_factory=dict)

    def iterations_to_within(self, rel: float = 0.01) -> int:
        """First iteration (1-based) whose gbest is within ``rel`` (relative) of the final cost."""
        final = self.history[-1]
        tol = rel * abs(final) if final != 0 else rel
        return int(np.argmax(self.history <= final + tol)) + 1


def inertia_weight(cfg: PSOConfig, t: int, t_max: int) -> float:
    """Inertia weight at 1-based iteration ``t`` of ``t_max`` for the configured schedule."""
    if cfg.inertia == "constant":
        return cfg.w_max
    if cfg.inertia == "linear":
        frac = (t - 1) / (t_max - 1) if t_max > 1 else 1.0
        return cfg.w_max - (cfg.w_max - cfg.w_min) * frac
    return (cfg.w_max - cfg.w_min) * math.exp((1 - t) * cfg.alpha) + cfg.w_min


def minimize(
    cost: Cost,
    lower: np.ndarray,
    upper: np.ndarray,
    cfg: PSOConfig,
    rng: np.random.Generator,
    init: np.ndarray | None = None,
    progress: Progress | None = None,
    stop: Callable[[], bool] | None = None,
) -> PSOResult:
    """Minimise ``cost`` over the box [lower, upper] with a particle swarm (see module docstring);
    ``stop()`` is asked after every swarm evaluation, and True ends the run there."""
    lower, upper = _check_bounds(lower, upper)
    n_p, dim = cfg.particles, lower.size
    span = upper - lower
    v_max = cfg.v_max_fraction * span if cfg.v_max is None else np.broadcast_to(cfg.v_max, (dim,)) * 1.0
    init = _check_init(init, n_p, dim)

    x = _fill(init, n_p, lower, span, rng)
    pbest_x = x.copy()
    pbest_c = np.full(n_p, np.inf)
    gbest_x, gbest_c = x[0].copy(), math.inf
    history: list[float] = []
    evaluations = 0
    rounds = cfg.restarts + 1
    total_iters = rounds * cfg.iterations
    stopped = halted = False
    n_elite = int(round(cfg.elite_fraction * n_p))

    for rnd in range(rounds):
        if rnd > 0:  # restart: keep elites' bests, re-draw the rest, velocities reset
            x, pbest_x, pbest_c = _restart(pbest_x, pbest_c, n_elite, lower, span, rng)
        v = (rng.random((n_p, dim)) * 2.0 - 1.0) * v_max * cfg.init_velocity
        trial = None  # mutated copy of gbest, evaluated with the next swarm (gbest_greedy)
        for t in range(1, cfg.iterations + 1):
            if cfg.max_evaluations is not None and evaluations + n_p > cfg.max_evaluations:
                stopped = True
                break
            c = _evaluate(cost, x if trial is None else np.vstack([x, trial]))
            evaluations += len(c)
            if trial is not None:
                c, trial_c = c[:n_p], float(c[n_p])
            better = c < pbest_c
            pbest_x[better] = x[better]
            pbest_c[better] = c[better]
            i_best = int(np.argmin(pbest_c))
            if pbest_c[i_best] < gbest_c:
                gbest_c = float(pbest_c[i_best])
                gbest_x = pbest_x[i_best].copy()
            if trial is not None and trial_c < gbest_c:
                gbest_c, gbest_x = trial_c, trial[0]
            trial = None
            history.append(gbest_c)
            if progress is not None:
                progress(len(history) / total_iters, f"round {rnd + 1} iteration {t} best {gbest_c:.6g}")
            if stop is not None and stop():
                halted = True
                break
            if t == cfg.iterations:
                break
            if cfg.mutation is not None and cfg.mutation_stage == "gbest_greedy":
                trial = np.clip(cfg.mutation(gbest_x[None, :], t, cfg.iterations, rng), lower, upper)
            x = _move(x, v, pbest_x, gbest_x, cfg, t, rng, (lower, upper, v_max))
        if stopped or halted:
            break

    order = np.argsort(pbest_c, kind="stable")
    return PSOResult(
        best_x=gbest_x,
        best_cost=gbest_c,
        history=np.asarray(history),
        evaluations=evaluations,
        iterations=len(history),
        pbest_x=pbest_x[order].copy(),
        pbest_cost=pbest_c[order].copy(),
        rounds=rnd + 1,
        stopped_by_budget=stopped,
    )


def _check_bounds(lower, upper) -> tuple[np.ndarray, np.ndarray]:
    lower = np.asarray(lower, dtype=float).reshape(-1)
    upper = np.asarray(upper, dtype=float).reshape(-1)
    if lower.shape != upper.shape or not np.all(upper >= lower):
        raise ValueError(f"bounds must have equal shape and upper >= lower, got {lower!r} / {upper!r}")
    return lower, upper


def _restart(pbest_x, pbest_c, n_elite: int, lower, span, rng: np.random.Generator):
    """A restart round's swarm: the elites' bests kept (with their costs), the rest re-drawn."""
    keep = np.argsort(pbest_c, kind="stable")[:n_elite]
    x = _fill(pbest_x[keep], len(pbest_c), lower, span, rng)
    return x, x.copy(), np.concatenate([pbest_c[keep], np.full(len(pbest_c) - keep.size, np.inf)])


def _evaluate(cost: Cost, rows: np.ndarray) -> np.ndarray:
    """The cost of every row, NaN read as +inf; a cost of the wrong shape is an error."""
    c = np.asarray(cost(rows), dtype=float).reshape(-1)
    if c.shape != (len(rows),):
        raise ValueError(f"cost returned shape {c.shape}, expected ({len(rows)},)")
    return np.where(np.isnan(c), np.inf, c) if np.isnan(c).any() else c


def _move(x, v, pbest_x, gbest_x, cfg: PSOConfig, t: int, rng: np.random.Generator, box) -> np.ndarray:
    """One swarm step: mutation (per ``mutation_stage``), v <- w v + c1 r1 (pbest - x) + c2 r2
    (gbest - x) clipped to +-v_max, in place (the hot path), x + v clipped to the bounds."""
    lower, upper, v_max = box
    if cfg.mutation is not None and cfg.mutation_stage == "before_velocity":
        x = np.clip(cfg.mutation(x, t, cfg.iterations, rng), lower, upper)
    r_shape = x.shape if cfg.per_dimension_random else (x.shape[0], 1)
    r1 = rng.random(r_shape)
    r2 = rng.random(r_shape)
    v *= inertia_weight(cfg, t, cfg.iterations)
    v += (cfg.c1 * r1) * (pbest_x - x)
    v += (cfg.c2 * r2) * (gbest_x - x)
    np.minimum(v, v_max, out=v)
    np.maximum(v, -v_max, out=v)
    x = x + v
    if cfg.mutation is not None and cfg.mutation_stage == "after_move":
        x = cfg.mutation(x, t + 1, cfg.iterations, rng)
    np.minimum(x, upper, out=x)
    np.maximum(x, lower, out=x)
    return x


def _check_init(init: np.ndarray | None, n_p: int, dim: int) -> np.ndarray:
    if init is None:
        return np.empty((0, dim))
    init = np.asarray(init, dtype=float)
    if init.ndim == 1:
        init = init[None, :]
    if init.ndim != 2 or init.shape[1] != dim or init.shape[0] > n_p:
        raise ValueError(f"init must be (K, {dim}) with K <= particles={n_p}, got shape {init.shape}")
    return init


def _fill(
    head: np.ndarray, n_p: int, lower: np.ndarray, span: np.ndarray, rng: np.random.Generator
) -> np.ndarray:
    """Swarm positions: ``head`` rows (clamped to the bounds) then uniform random particles."""
    rand = lower + rng.random((n_p - head.shape[0], lower.size)) * span
    return np.clip(np.vstack([head, rand]), lower, lower + span)
