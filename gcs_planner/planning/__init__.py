"""Planners behind one contract: a Scenario and the planner's typed config in, a Plan out.

A planner is a module with ``NAME``, ``Config`` (a :class:`PlannerConfig` tagged with ``NAME``:
every ``[planner]`` key it reads, with its bounds), ``TRAITS`` (:class:`Traits`: what it is and
reads) and ``plan(scenario, config, rng, progress) -> Plan``, where ``rng`` is a seeded numpy
Generator (no global random state) and ``progress(fraction, message)`` may be None. ``PLANNERS``
names the modules; the scenario's ``[planner] name`` picks one, so methods are swapped in the file
(docs/planners.md shows how to add one).

``plan_scenario`` runs every plan through the one safety checker
(gcs_planner.safety.separation.certify): ``VehiclePlan.feasible`` is its verdict, never the
planner's. A planner may define ``check_options(scenario, config) -> dict``, the checker's
keyword arguments for its plans (e.g. its sample step, climb limit, ``kinematics=False`` where its
vehicle model is its own); the checks of obstacles, separation, altitude band and site always run.
"""

from __future__ import annotations

import difflib
from collections.abc import Callable
from dataclasses import dataclass, field
from importlib import import_module
from pathlib import Path
from typing import Protocol

import numpy as np

from gcs_planner.core.config import Config, Seed, parse
from gcs_planner.core.errors import UserError
from gcs_planner.core.heap import keep_heap_slack
from gcs_planner.core.validation import InputError
from gcs_planner.model.plan import Plan
from gcs_planner.model.scenario import Extensions, Scenario, ScenarioError
from gcs_planner.model.scenario import load_scenario as read_scenario
from gcs_planner.model.scenario import parse_scenario as parse_tables
from gcs_planner.safety.separation import certify

__all__ = [
    "PLANNERS", "WORLD", "Planner", "PlannerConfig", "Progress", "Traits", "certify_plan", "check_options",
    "config_of", "ignored_tables", "load_scenario", "parse_scenario", "plan_scenario", "planner",
]  # fmt: skip

Progress = Callable[[float, str], None]

# [planner] name -> the module that implements it
PLANNERS: dict[str, str] = {
    "straight": "gcs_planner.planning.straight",
    "priority_swarm": "gcs_planner.planning.priority_swarm",
    "acmpso": "gcs_planner.planning.acmpso",
    "coalition": "gcs_planner.planning.coalition",
    "deconflict_4d": "gcs_planner.planning.deconflict4d",
}


class PlannerConfig(Config, tag_field="name"):
    """The ``[planner]`` table: ``name`` picks the planner (the tag), ``seed`` its generator."""

    seed: Seed = 0


# the scenario's world, as tables a planner may read
WORLD = ("obstacles", "bounds", "terrain", "manned", "site")


@dataclass(frozen=True)
class Traits:
    """What a planner is, declared beside its Config."""

    online: bool = False  # decides tasks in flight: flown by fly-coalition's online strategy
    separation: bool = False  # its plans keep the vehicles apart in space and time by construction
    reads: tuple[str, ...] = ()  # the world tables (WORLD) it plans with
    extensions: Extensions = field(default_factory=Extensions)  # its own tables and [[vehicles]] keys


class Planner(Protocol):
    """What a planner module provides."""

    NAME: str
    Config: type[PlannerConfig]
    TRAITS: Traits

    def plan(
        self, scenario: Scenario, config: PlannerConfig, rng: np.random.Generator, progress: Progress | None
    ) -> Plan: ...


def planner(name: str) -> Planner:
    """The planner module registered as ``name``; UserError naming the nearest one otherwise."""
    if name not in PLANNERS:
        near = difflib.get_close_matches(str(name), PLANNERS, n=1)
        hint = f"; did you mean {near[0]!r}?" if near else ""
        raise UserError(f"planner.name {name!r} is not one of {sorted(PLANNERS)}{hint}")
    return import_module(PLANNERS[name])


def config_of(scenario: Scenario) -> PlannerConfig:
    """The scenario's ``[planner]`` table as its planner's typed config (every key checked)."""
    try:
        return parse(planner(scenario.planner_name).Config, scenario.planner, "planner")
    except InputError as exc:
        raise ScenarioError(f"{scenario.path or scenario.name}: {exc}") from None


def _extensions_of(name: str) -> Extensions:
    """The tables and [[vehicles]] keys planner ``name`` adds (none for a name not registered:
    config_of says so)."""
    return planner(name).TRAITS.extensions if name in PLANNERS else Extensions()


def load_scenario(path: str | Path) -> Scenario:
    """A scenario file with its planner's own tables and keys, its ``[planner]`` table checked
    against the planner's config."""
    scenario = read_scenario(path, _extensions_of)
    config_of(scenario)
    return scenario


def parse_scenario(data: dict, where: str = "scenario") -> Scenario:
    """A scenario's TOML tables with its planner's own tables and keys (model.scenario.parse_scenario)."""
    return parse_tables(data, where, _extensions_of)


def ignored_tables(scenario: Scenario) -> list[str]:
    """The world tables the scenario gives that its planner does not plan with (obstacles, manned
    traffic, ...): the plan does not avoid them, which the user should hear before flying it."""
    reads = planner(scenario.planner_name).TRAITS.reads
    return [t for t in WORLD if scenario.raw.get(t) and t not in reads]


def check_options(scenario: Scenario, config: PlannerConfig) -> dict:
    """The one checker's keyword arguments for the scenario's planner (its ``check_options``)."""
    declared = getattr(planner(scenario.planner_name), "check_options", None)
    return declared(scenario, config) if declared else {}


def certify_plan(plan: Plan, scenario: Scenario, kinematics: bool = True) -> None:
    """Give ``plan`` the one checker's verdict for ``scenario`` with its planner's options: the last
    step of plan_scenario, and what ``fly`` does to a plan file, whose flags are whatever wrote it.
    ``kinematics=False`` leaves out the turn radius and speed, which a plan file's rounding blurs
    (docs/architecture.md, "The one safety checker")."""
    options = check_options(scenario, config_of(scenario))
    certify(plan, scenario, **options | ({} if kinematics else {"kinematics": False}))
    plan.metrics["feasible_count"] = sum(vp.feasible for vp in plan.vehicles)  # the verdict's count


def plan_scenario(scenario: Scenario, seed: int | None = None, progress: Progress | None = None) -> Plan:
    """Run the scenario's planner with a seeded generator (seed defaults to the file's) and give
    its plan the one checker's verdict (``certify``)."""
    keep_heap_slack()  # the planners' numpy temporaries reuse freed pages (gcs_planner/core/heap.py)
    config = config_of(scenario)
    module = planner(scenario.planner_name)
    rng = np.random.default_rng(config.seed if seed is None else seed)
    plan = module.plan(scenario, config, rng, progress)
    certify_plan(plan, scenario)
    if scenario.site is not None:  # homes on their own ground: the missions give altitudes AMSL
        for vp in plan.vehicles:
            vp.altitude_frame = "amsl"
    return plan
