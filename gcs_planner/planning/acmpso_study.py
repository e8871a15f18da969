"""Seed 001's Table 3 as a sweep task: one run of BPSO, LPSO or ACMPSO, its track re-checked densely.

studies/acmpso_table3.toml names it, and benchmarks/acmpso_table3.py runs that study. A run's
generator is seeded ``[base_seed, variant, algorithm, run]`` (indices in VARIANTS and
TABLE_ORDER), so every run, and the README's table, is the same on any worker in any order.
"""

from __future__ import annotations

import functools
import json
from pathlib import Path
from typing import Any

import numpy as np

from gcs_planner.planning import load_scenario
from gcs_planner.planning.acmpso import VARIANTS, Config, TrackProblem, problem_from_scenario, solve
from gcs_planner.planning.threat_env import ThreatEnv, validate_path

__all__ = ["KINDS", "TABLE_ORDER", "table3_run"]

TABLE_ORDER = ("bpso", "lpso", "acmpso")  # the paper's column order; the algorithm's seed index
KINDS = ("radar", "obstacle", "terrain")  # the dense re-check's violation kinds
RECHECK_SPACING_M = 100.0  # 10 samples per km of the 100-node track (the paper checks nodes only)


@functools.lru_cache(maxsize=8)
def _problem(path: Path, collision: str) -> tuple[TrackProblem, ThreatEnv, float]:
    """The scenario's first vehicle's problem with the paper's Table 2 settings (built once per worker)."""
    scenario = load_scenario(path)
    config = Config(collision=collision)
    problem, env_m = problem_from_scenario(scenario, scenario.vehicles[0], config)
    return problem, env_m, config.length_unit_m


def table3_run(scenario_path: Path, params: dict[str, Any], seed: int) -> dict[str, Any]:
    """Run ``seed`` of ``params["algorithm"]`` in ``params["variant"]`` (``collision``, ``base_seed``
    optional): final fitness, solver CPU time, evaluations, the best-so-far history (JSON) and,
    per violation kind, whether the optimised track violates it and how deep [m]."""
    algorithm, variant = params["algorithm"], params["variant"]
    problem, env_m, unit_m = _problem(Path(scenario_path), params.get("collision", "literal"))
    base = int(params.get("base_seed", 0))
    rng = np.random.default_rng([base, VARIANTS.index(variant), TABLE_ORDER.index(algorithm), seed])
    result = solve(problem, algorithm, rng, variant)
    violations = validate_path(env_m, result.nodes * unit_m, spacing=RECHECK_SPACING_M).violations
    out = {
        "fitness": result.fitness,
        "cpu_seconds": result.cpu_seconds,
        "evaluations": result.pso.evaluations,
        "history": json.dumps(result.pso.history.tolist()),
    }
    for kind in KINDS:
        depths = [v.depth for v in violations if v.kind == kind]
        out[f"{kind}_violated"] = bool(depths)
        out[f"{kind}_depth_m"] = max(depths, default=0.0)
    return out
