"""Priority swarm against independent library optimisers on the same cost, checker and counted budget.

    pip install -e ".[bench]" && pip install --no-deps mealpy==3.0.3 opfunu==1.0.4 pandas
    nice python benchmarks/planner_peers.py --scenarios swarm40_open swarm40_cylinders --seeds 0 1 2 3 4

For each scenario and seed the method (priority_swarm.plan) runs first; its counted evaluations
(metrics["evaluations"]: every CostModel row, repairs included) divided by the UAVs is every peer's
budget per UAV. A peer optimises the same CostModel UAV by UAV in scenario order against the
timed traffic of those before it (as gcs_planner/planning/baselines.py), from a uniform population
or, "+RRT*", from the method's own start (its RRT* path, resampled, plus the noisy copies of
seed_swarm); its plan goes through the same independent checker, without repair. The peers are
imported, not rewritten: scipy.optimize.differential_evolution, pyswarms GlobalBestPSO
(constriction parameters), cma (CMA-ES, bounds handled by cma), mealpy OriginalGWO. mealpy pins
numpy <= 1.26 while rerun-sdk needs numpy >= 2; it runs on numpy 2, hence --no-deps.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import msgspec
import numpy as np

from gcs_planner.planning import config_of, load_scenario
from gcs_planner.planning.priority_swarm import (
    CostModel,
    Traffic,
    initial_paths,
    prepare,
    repair_and_check,
    seed_swarm,
    timed_samples,
)
from gcs_planner.planning.priority_swarm import plan as plan_method

MISSIONS = Path(__file__).resolve().parent.parent / "missions"
CONSTRICTION = {"c1": 1.49618, "c2": 1.49618, "w": 0.7298}  # Clerc & Kennedy 2002


def scipy_de(cost, lower, upper, pop, budget, seed, init):
    from scipy.optimize import differential_evolution

    start = init if init is not None else np.random.default_rng(seed).uniform(lower, upper, (pop, len(lower)))
    res = differential_evolution(
        lambda xs: cost(xs.T), list(zip(lower, upper)), maxiter=max(0, budget // pop - 1), init=start,
        vectorized=True, updating="deferred", polish=False, tol=0.0, seed=seed,
    )  # fmt: skip
    return res.x


def pyswarms_pso(cost, lower, upper, pop, budget, seed, init):
    import logging

    import pyswarms

    logging.getLogger("pyswarms").setLevel(logging.ERROR)
    np.random.seed(seed)  # pyswarms draws from numpy's global generator
    opt = pyswarms.single.GlobalBestPSO(pop, len(lower), CONSTRICTION, bounds=(lower, upper), init_pos=init)
    _, x = opt.optimize(cost, iters=max(1, budget // pop), verbose=False)
    return x


def cma_es(cost, lower, upper, pop, budget, seed, init):
    import cma

    span = upper - lower
    x0 = init[0] if init is not None else (lower + upper) / 2
    opts = {"popsize": pop, "bounds": [list(lower), list(upper)], "maxfevals": budget, "seed": seed + 1,
            "CMA_stds": list(0.3 * span), "verbose": -9}  # fmt: skip
    es = cma.CMAEvolutionStrategy(list(x0), 1.0, opts)
    used = 0
    while not es.stop() and used + pop <= budget:
        xs = es.ask()
        es.tell(xs, list(cost(np.asarray(xs))))
        used += pop
    return np.asarray(es.result.xbest)


def mealpy_gwo(cost, lower, upper, pop, budget, seed, init):
    from mealpy import GWO, FloatVar

    problem = {"obj_func": lambda x: float(cost(x[None, :])[0]), "bounds": FloatVar(lb=lower, ub=upper),
               "minmax": "min", "log_to": None}  # fmt: skip
    model = GWO.OriginalGWO(epoch=max(1, budget // pop - 1), pop_size=pop)
    best = model.solve(problem, seed=seed, starting_solutions=None if init is None else list(init))
    return best.solution


PEERS = {"scipy_de": scipy_de, "pyswarms_pso": pyswarms_pso, "cma_es": cma_es, "mealpy_gwo": mealpy_gwo}


def plan_peer(scenario, seed: int, peer: str, budget: int, seeded: bool):
    """Every UAV by ``peer`` in scenario order behind the method's cost; checked without repair."""
    cfg = msgspec.structs.replace(config_of(scenario), repairs=0)
    rng = np.random.default_rng(seed)
    problems, obstacles, lo, hi = prepare(scenario, cfg)
    starts = initial_paths(problems, obstacles, lo, hi, cfg, rng)[0] if seeded else None
    traffic, xs, evaluations = Traffic(cfg.dt_s), {}, 0
    for n, prob in enumerate(problems):
        model = CostModel(prob, obstacles, traffic, cfg)
        init = seed_swarm(prob, starts[n], None, cfg, rng) if seeded else None
        if init is not None and len(init) < cfg.particles:  # the random rest, as the engine adds
            extra = rng.uniform(prob.lower, prob.upper, (cfg.particles - len(init), len(prob.lower)))
            init = np.vstack([init, extra])
        x = PEERS[peer](model, prob.lower, prob.upper, cfg.particles, budget, seed * 1000 + n, init)
        evaluations += model.evaluations
        xs[prob.index] = np.clip(x, prob.lower, prob.upper)
        slices, pos = timed_samples(prob, xs[prob.index], cfg)
        traffic.add(slices, pos, prob.vehicle.separation_m, prob.vehicle.speed_mps)
    metrics = {"evaluations": int(evaluations)}
    order = list(range(len(problems)))
    return repair_and_check(scenario, problems, obstacles, cfg, rng, xs, order, peer, metrics), evaluations


def _row(plan, scenario: str, method: str, seed: int, evaluations: int, cpu_s: float) -> dict:
    costs = [min(v.cost["total"], 1e4) for v in plan.vehicles]
    return {"scenario": scenario, "method": method, "seed": seed, "cost": float(np.mean(costs)),
            "feasible": sum(v.feasible for v in plan.vehicles), "vehicles": len(plan.vehicles),
            "evaluations": int(evaluations), "cpu_s": cpu_s}  # fmt: skip


def run(args) -> list[dict]:
    rows = json.loads(args.out.read_text()) if args.out.exists() else []
    done = {(r["scenario"], r["method"], r["seed"]) for r in rows}
    for seed in args.seeds:
        for name in args.scenarios:
            scenario = load_scenario(MISSIONS / f"{name}.toml")
            scenario.planner.update(particles=args.particles, iterations=args.iterations, rounds=args.rounds,
                                    rrt_iterations=args.rrt_iterations)  # fmt: skip
            key = (name, "priority_swarm", seed)
            if key not in done:
                cpu = time.process_time()
                plan = plan_method(scenario, config_of(scenario), np.random.default_rng(seed))
                rows.append(_row(plan, name, "priority_swarm", seed, plan.metrics["evaluations"],
                                 time.process_time() - cpu))  # fmt: skip
                args.out.write_text(json.dumps(rows, indent=1))
            method_row = next(r for r in rows if (r["scenario"], r["method"], r["seed"]) == key)
            budget = method_row["evaluations"] // method_row["vehicles"]
            for peer in args.peers:
                for seeded in (False, True):
                    label = peer + ("+RRT*" if seeded else "")
                    if (name, label, seed) in done:
                        continue
                    cpu = time.process_time()
                    plan, used = plan_peer(scenario, seed, peer, budget, seeded)
                    rows.append(_row(plan, name, label, seed, used, time.process_time() - cpu))
                    args.out.write_text(json.dumps(rows, indent=1))
                    print(json.dumps(rows[-1]), flush=True)
    return rows


def table(rows: list[dict]) -> None:
    pairs = {(r["scenario"], r["method"]) for r in rows}
    keys = sorted(pairs, key=lambda k: (k[0], k[1] != "priority_swarm", k))
    print(
        "| scenario | method | seeds | cost per UAV, mean (std) | feasible UAVs | evaluations / UAV | CPU s |"
    )  # noqa: E501
    print("|---|---|---|---|---|---|---|")
    for sc, method in keys:
        sel = [r for r in rows if (r["scenario"], r["method"]) == (sc, method)]
        cost = np.array([r["cost"] for r in sel])
        feasible = 100 * np.mean([r["feasible"] / r["vehicles"] for r in sel])
        per_uav = np.mean([r["evaluations"] / r["vehicles"] for r in sel])
        print(f"| {sc} | {method} | {len(sel)} | {cost.mean():.1f} ({cost.std():.1f}) | {feasible:.1f} % |"
              f" {per_uav:.0f} | {np.mean([r['cpu_s'] for r in sel]):.1f} |")  # fmt: skip


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenarios", nargs="+", default=["swarm40_open", "swarm40_cylinders"])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    ap.add_argument("--peers", nargs="+", default=list(PEERS), choices=list(PEERS))
    ap.add_argument("--particles", type=int, default=10)
    ap.add_argument("--iterations", type=int, default=15)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--rrt-iterations", type=int, default=200)
    ap.add_argument("--out", type=Path, default=Path("bench_peers.json"), help="results, resumed if present")
    args = ap.parse_args()
    table(run(args))
    return 0


if __name__ == "__main__":
    sys.exit(main())
