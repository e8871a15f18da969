"""The priority-swarm planner's evaluation count, the budget the benchmark gives its peers, is
every cost evaluation it made: each swarm, each inherited-path check and each repair."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gcs_planner.planning import config_of, load_scenario, priority_swarm

SCENARIO = Path(__file__).resolve().parents[1] / "missions" / "swarm_small.toml"


def test_evaluations_count_every_cost_call(monkeypatch):
    seen = [0]
    call = priority_swarm.CostModel.__call__

    def counting(self, x):
        seen[0] += len(x)
        return call(self, x)

    monkeypatch.setattr(priority_swarm.CostModel, "__call__", counting)
    repairs = []
    original = priority_swarm.optimise

    def tracked(*args, **kwargs):
        repairs.append(1)
        return original(*args, **kwargs)

    monkeypatch.setattr(priority_swarm, "optimise", tracked)
    scenario = load_scenario(SCENARIO)
    scenario.planner.update(particles=8, iterations=6, rounds=2)
    plan = priority_swarm.plan(scenario, config_of(scenario), np.random.default_rng(0))
    assert plan.metrics["evaluations"] == seen[0] > 0
    assert len(repairs) >= len(scenario.vehicles)
