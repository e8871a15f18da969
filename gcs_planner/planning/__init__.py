"""Planners behind one interface: a Scenario in, a Plan out.

Each planner module exposes ``plan(scenario, rng, progress) -> Plan`` where ``rng`` is a seeded
numpy Generator (no global random state) and ``progress(fraction, message)`` may be None.
The scenario's ``[planner] name`` picks the module, so methods are swapped in the file.
"""

from __future__ import annotations

from collections.abc import Callable
from importlib import import_module

import numpy as np

from gcs_planner.errors import UserError
from gcs_planner.plan import Plan
from gcs_planner.scenario import Scenario

__all__ = ["PLANNERS", "Progress", "plan_scenario"]

Progress = Callable[[float, str], None]

# name in the scenario file -> module exposing plan(scenario, rng, progress)
PLANNERS: dict[str, str] = {
    "straight": "gcs_planner.planning.straight",
    "priority_swarm": "gcs_planner.planning.priority_swarm",
    "acmpso": "gcs_planner.planning.acmpso",
    "coalition": "gcs_planner.planning.coalition",
    "deconflict_4d": "gcs_planner.planning.deconflict4d",
}


def plan_scenario(scenario: Scenario, seed: int | None = None, progress: Progress | None = None) -> Plan:
    """Run the scenario's planner with a seeded generator (seed defaults to the file's)."""
    name = scenario.planner_name
    if name not in PLANNERS:
        raise UserError(f"planner.name {name!r} is not one of {sorted(PLANNERS)}")
    if seed is None:
        seed = int(scenario.planner.get("seed", 0))
    module = import_module(PLANNERS[name])
    return module.plan(scenario, np.random.default_rng(seed), progress)
