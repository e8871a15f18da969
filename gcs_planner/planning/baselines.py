"""Baselines for the priority swarm planner: standard PSO, differential evolution, grey wolf optimiser.

Each baseline optimises the *same* per-UAV cost (priority_swarm.CostModel: eqs. 3-14 on the same
Dubins path encoding, separation from the UAVs planned before it), UAV by UAV in scenario order,
with the *same evaluation budget* per UAV (``evaluations_per_vehicle``, default particles x
iterations of the scenario's [planner] table; the benchmark passes the method's measured budget).
What they lack is what the method adds: RRT* initial paths, priority ordering, restart rounds with
elites, and repair. Populations start uniform in the bounds. The final plan goes through the same
independent checker (no repair), so an infeasible UAV is flagged, never hidden.

- ``pso``: the shared engine with the standard constriction parameters (w = 0.7298 constant,
  c1 = c2 = 1.49618; Clerc & Kennedy 2002).
- ``de``: DE/rand/1/bin, F = 0.5, CR = 0.9, greedy selection (Storn & Price 1997); out-of-bounds
  mutants are clipped.
- ``gwo``: grey wolf optimiser (Mirjalili et al. 2014), a decreasing linearly 2 -> 0, the mean of
  the three moves towards alpha, beta and delta; positions clipped to the bounds.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import msgspec
import numpy as np

from gcs_planner.model.plan import Plan
from gcs_planner.model.scenario import Scenario
from gcs_planner.planning import config_of, load_scenario
from gcs_planner.planning.priority_swarm import (
    CostModel,
    Traffic,
    plan,
    prepare,
    repair_and_check,
    timed_samples,
)
from gcs_planner.planning.pso import PSOConfig, minimize

__all__ = ["METHODS", "compare_run", "differential_evolution", "grey_wolf", "plan_baseline"]

METHODS = ("pso", "de", "gwo")


def differential_evolution(cost, lower, upper, pop: int, budget: int, rng, f: float = 0.5, cr: float = 0.9):
    """DE/rand/1/bin within ``budget`` cost rows; returns (best x, best cost, history per generation)."""
    dim = len(lower)
    x = rng.uniform(lower, upper, (pop, dim))
    fx = cost(x)
    used = pop
    history = [float(fx.min())]
    while used + pop <= budget:
        idx = np.array([rng.choice(np.delete(np.arange(pop), i), 3, replace=False) for i in range(pop)])
        mutant = np.clip(x[idx[:, 0]] + f * (x[idx[:, 1]] - x[idx[:, 2]]), lower, upper)
        cross = rng.random((pop, dim)) < cr
        cross[np.arange(pop), rng.integers(0, dim, pop)] = True
        trial = np.where(cross, mutant, x)
        ft = cost(trial)
        used += pop
        better = ft <= fx
        x[better], fx[better] = trial[better], ft[better]
        history.append(float(fx.min()))
    best = int(np.argmin(fx))
    return x[best], float(fx[best]), np.array(history)


def grey_wolf(cost, lower, upper, pop: int, budget: int, rng):
    """Grey wolf optimiser within ``budget`` cost rows; returns (best x, best cost, history)."""
    dim = len(lower)
    x = rng.uniform(lower, upper, (pop, dim))
    fx = cost(x)
    used = pop
    order = np.argsort(fx)
    leaders = x[order[:3]].copy()
    lead_f = fx[order[:3]].copy()
    history = [float(lead_f[0])]
    iterations = max(1, budget // pop - 1)
    t = 0
    while used + pop <= budget:
        a = 2.0 - 2.0 * t / iterations
        moves = []
        for leader in leaders:
            big_a = a * (2.0 * rng.random((pop, dim)) - 1.0)
            c = 2.0 * rng.random((pop, dim))
            moves.append(leader - big_a * np.abs(c * leader - x))
        x = np.clip(np.mean(moves, axis=0), lower, upper)
        fx = cost(x)
        used += pop
        t += 1
        pool_x = np.vstack([leaders, x])
        pool_f = np.concatenate([lead_f, fx])
        top = np.argsort(pool_f, kind="stable")[:3]
        leaders, lead_f = pool_x[top].copy(), pool_f[top].copy()
        history.append(float(lead_f[0]))
    return leaders[0], float(lead_f[0]), np.array(history)


def plan_baseline(
    scenario: Scenario,
    rng: np.random.Generator,
    method: str,
    evaluations_per_vehicle: int | None = None,
    progress=None,
) -> Plan:
    """Plan every UAV in scenario order with ``method`` in METHODS behind the priority-swarm cost."""
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    t_start = time.perf_counter()
    cfg = config_of(scenario)
    problems, obstacles, _, _ = prepare(scenario, cfg)
    budget = int(evaluations_per_vehicle or cfg.particles * cfg.iterations)
    traffic = Traffic(cfg.dt_s)
    xs, to_1pct, evaluations = {}, [], 0
    for n, prob in enumerate(problems):
        model = CostModel(prob, obstacles, traffic, cfg)
        if method == "pso":
            pso_cfg = PSOConfig(
                particles=cfg.particles,
                iterations=max(1, budget // cfg.particles),
                inertia="constant",
                w_max=0.7298,
                c1=1.49618,
                c2=1.49618,
                max_evaluations=budget,
            )
            res = minimize(model, prob.lower, prob.upper, pso_cfg, rng)
            x, history = res.best_x, res.history
        elif method == "de":
            x, _, history = differential_evolution(model, prob.lower, prob.upper, cfg.particles, budget, rng)
        else:
            x, _, history = grey_wolf(model, prob.lower, prob.upper, cfg.particles, budget, rng)
        final = history[-1]
        to_1pct.append(int(np.argmax(history <= final + 0.01 * abs(final))) + 1)
        evaluations += model.evaluations
        xs[prob.index] = x
        slices, pos = timed_samples(prob, x, cfg)
        traffic.add(slices, pos, prob.vehicle.separation_m, prob.vehicle.speed_mps)
        if progress:
            progress((n + 1) / len(problems), prob.vehicle.id)
    cfg_check = msgspec.structs.replace(cfg, repairs=0)
    order = list(range(len(problems)))
    metrics = {"evaluations": int(evaluations), "method": method}
    result = repair_and_check(
        scenario, problems, obstacles, cfg_check, rng, xs, order, f"baseline_{method}", metrics
    )
    result.metrics["cost_total"] = float(sum(min(v.cost["total"], 1e4) for v in result.vehicles))
    result.metrics["feasible_count"] = sum(v.feasible for v in result.vehicles)
    result.metrics["iterations_to_1pct"] = float(np.mean(to_1pct))
    result.metrics["wall_time_s"] = time.perf_counter() - t_start
    return result


def compare_run(scenario_path: Path, params: dict[str, Any], seed: int) -> dict[str, Any]:
    """A sweep task for seed 000's comparison (studies/priority_swarm_compare.toml): the method,
    then every baseline of ``params["baselines"]`` (comma-separated, default all of METHODS) with
    the method's counted evaluations per UAV on the same seed; the rest of ``params`` go to
    [planner]. Metrics per method, nested under its name ("pso.cost_total"), with its CPU time."""
    params = dict(params)
    methods = [m.strip() for m in str(params.pop("baselines", ",".join(METHODS))).split(",") if m.strip()]
    unknown = sorted(set(methods) - set(METHODS))
    if unknown:
        raise ValueError(f"baselines: {unknown[0]!r} is not one of {', '.join(METHODS)}")
    scenario = load_scenario(scenario_path)
    scenario.planner.update(params)
    cpu = time.process_time()
    result = plan(scenario, config_of(scenario), np.random.default_rng(seed))
    out = {"priority_swarm": _compared(result, time.process_time() - cpu)}
    budget = result.metrics["evaluations"] // len(scenario.vehicles)
    for method in methods:
        cpu = time.process_time()
        result = plan_baseline(scenario, np.random.default_rng(seed), method, budget)
        out[method] = _compared(result, time.process_time() - cpu)
    return out


def _compared(result: Plan, cpu_s: float) -> dict[str, Any]:
    return {**result.metrics, "feasible_fraction": result.metrics["feasible_count"] / len(result.vehicles),
            "cpu_s": cpu_s}  # fmt: skip
