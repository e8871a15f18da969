"""Every registered planner meets the contract of gcs_planner.planning (docs/planners.md): a typed
config that refuses misspelt keys, a Plan that holds its invariants, the same plan for the same
seed, a JSON round trip. The example planner of docs/planners.md is run through the same checks."""

from __future__ import annotations

import json
import math
import re
import sys
from pathlib import Path

import msgspec
import numpy as np
import pytest

from gcs_planner import planning
from gcs_planner.core.config import parse
from gcs_planner.core.errors import UserError
from gcs_planner.model.plan import Plan
from gcs_planner.model.scenario import SECTIONS, VEHICLE_KEYS, ScenarioError
from gcs_planner.planning import (
    PLANNERS,
    WORLD,
    PlannerConfig,
    Traits,
    config_of,
    ignored_tables,
    load_scenario,
    parse_scenario,
    plan_scenario,
)

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "planners.md"

# planner -> (a mission, [planner] overrides that make it small)
SMALL = {
    "straight": ("straight_4uav", {}),
    "priority_swarm": ("swarm_small", {"particles": 6, "iterations": 4, "rounds": 1, "rrt_iterations": 60}),
    "acmpso": ("acmpso_paper", {"particles": 6, "iterations": 5}),
    "coalition": ("coalition_paper", {"t_end_s": 60.0}),
    "deconflict_4d": ("deconflict_4uav", {"particles": 6, "iterations": 5}),
    "cruise": ("straight_4uav", {"cruise_alt_m": 40.0}),  # the docs' example planner
}


@pytest.fixture(scope="module")
def with_example(tmp_path_factory):
    """The docs' example planner saved as a module and registered: one module, one registry line."""
    code = re.search(r"```python\n(.*?)```", DOC.read_text(), re.S)[1]
    folder = tmp_path_factory.mktemp("example")
    (folder / "cruise_example.py").write_text(code)
    sys.path.insert(0, str(folder))
    PLANNERS["cruise"] = "cruise_example"
    yield
    del PLANNERS["cruise"]
    sys.path.remove(str(folder))
    sys.modules.pop("cruise_example", None)


def _small(name: str):
    mission, overrides = SMALL[name]
    scenario = load_scenario(ROOT / "missions" / f"{mission}.toml")
    known = {f.name for f in msgspec.structs.fields(planning.planner(name).Config)}
    borrowed = {k: v for k, v in scenario.planner.items() if k in known}  # a mission of another planner
    scenario.planner.clear()
    scenario.planner.update({**borrowed, **overrides, "name": name})
    return scenario


def test_every_registered_planner_has_a_small_case():
    assert set(PLANNERS) == set(SMALL) - {"cruise"}


@pytest.mark.usefixtures("with_example")
@pytest.mark.parametrize("name", sorted(SMALL))
def test_config_is_typed_tagged_and_refuses_misspelt_keys(name):
    module = planning.planner(name)
    assert name == module.NAME and issubclass(module.Config, PlannerConfig)
    default = planning.config_of(_small(name))
    assert isinstance(default, module.Config)
    for field in msgspec.structs.fields(module.Config):
        misspelt = field.name[:-1] + "_x" if len(field.name) > 3 else field.name + "x"
        with pytest.raises(UserError, match=rf"unknown key '{misspelt}'; did you mean '{field.name}'\?"):
            parse(module.Config, {"name": name, misspelt: 1}, "planner")


@pytest.mark.usefixtures("with_example")
@pytest.mark.parametrize("name", sorted(SMALL))
def test_a_small_scenario_plans_to_a_valid_plan(name):
    scenario = _small(name)
    fractions: list[float] = []
    plan = plan_scenario(scenario, seed=4, progress=lambda f, _m: fractions.append(f))
    assert plan.planner == name
    assert [(v.vehicle_id, v.sysid) for v in plan.vehicles] == [(v.id, v.sysid) for v in scenario.vehicles]
    for vp in plan.vehicles:
        assert len(vp.waypoints) >= 2 and np.isfinite(vp.waypoints).all()
        assert np.all(np.diff(vp.times_s) >= 0) and np.all(np.diff(vp.path_times_s) >= -1e-9)
        assert np.all(vp.speeds_mps[1:] > 0) and np.isfinite(vp.speeds_mps).all()
        assert len(vp.path) >= 2 and np.isfinite(vp.path).all()
        assert math.isfinite(vp.takeoff_delay_s) and vp.takeoff_delay_s >= 0
    assert all(0.0 <= f <= 1.0 + 1e-9 for f in fractions)
    assert fractions == sorted(fractions)


@pytest.mark.usefixtures("with_example")
@pytest.mark.parametrize("name", sorted(SMALL))
def test_same_seed_same_plan_and_json_round_trip(name):
    first = plan_scenario(_small(name), seed=7)
    again = plan_scenario(_small(name), seed=7)
    assert _stable(first) == _stable(again)
    back = Plan.from_dict(json.loads(first.to_json()))
    assert _stable(back) == _stable(first)


def _stable(plan: Plan) -> dict:
    """The plan without its wall-clock measurements (the only thing allowed to differ between runs)."""

    def strip(value):
        if isinstance(value, dict):
            return {k: strip(v) for k, v in value.items() if "wall" not in k and "seconds" not in k}
        return [strip(v) for v in value] if isinstance(value, list) else value

    return strip(json.loads(plan.to_json()))


@pytest.mark.usefixtures("with_example")
@pytest.mark.parametrize("name", sorted(SMALL))
def test_each_planner_declares_what_it_is_and_reads(name):
    traits = planning.planner(name).TRAITS
    assert isinstance(traits, Traits) and set(traits.reads) <= set(WORLD)
    assert not set(traits.extensions.tables) & set(SECTIONS)  # its own tables, not the world's
    assert not set(traits.extensions.vehicle_keys) & set(VEHICLE_KEYS)


def _tables(mission: str) -> dict:
    import tomllib

    return tomllib.loads((ROOT / "missions" / f"{mission}.toml").read_text())


def test_a_planners_own_tables_and_keys_are_known_only_with_that_planner():
    coalition = _tables("coalition_paper")
    assert parse_scenario(coalition).raw["coalition"]["targets"]  # the coalition planner's table
    coalition["planner"] = {"name": "priority_swarm"}
    with pytest.raises(ScenarioError, match="top level: unknown key 'coalition'"):
        parse_scenario(coalition)
    four_d = _tables("deconflict_10uav_manned")
    del four_d["manned"]
    assert parse_scenario(four_d).raw["vehicles"][0]["v_max_mps"] == 6.0  # the 4-D planner's dynamics
    four_d["planner"] = {"name": "straight"}
    with pytest.raises(ScenarioError, match=r"vehicles\[0\]: unknown key '(limit|v_max_mps)'"):
        parse_scenario(four_d)


def test_the_world_tables_a_planner_ignores_are_named():
    manned = _tables("deconflict_10uav_manned")
    assert ignored_tables(parse_scenario(manned)) == []  # the 4-D planner plans around [[manned]]
    for v in manned["vehicles"]:
        for key in planning.planner("deconflict_4d").TRAITS.extensions.vehicle_keys:
            v.pop(key, None)
    manned["planner"] = {"name": "priority_swarm"}
    assert ignored_tables(parse_scenario(manned)) == ["manned"]  # the swarm does not avoid traffic
    assert ignored_tables(load_scenario(ROOT / "missions" / "swarm40_cylinders.toml")) == []


def test_an_unknown_planner_names_the_nearest():
    scenario = _small("straight")
    scenario.planner["name"] = "priority_swarn"
    with pytest.raises(UserError, match="did you mean 'priority_swarm'"):
        config_of(scenario)


def test_scenarios_are_read_through_the_planner_registry():
    """model.scenario knows no planner: a scenario read with it alone refuses a coalition's
    [coalition] table and 4-D [[vehicles]] keys. Every reader outside the planning layer goes
    through gcs_planner.planning (a replay once drew no coalition world, benchmarks crashed)."""
    root = Path(__file__).resolve().parents[1]
    direct = re.compile(r"from gcs_planner\.model\.scenario import [^\n]*\b(load_scenario|parse_scenario)\b")
    offenders = [
        str(p.relative_to(root))
        for folder in ("gcs_planner", "benchmarks", "sitl_mock")
        for p in (root / folder).rglob("*.py")
        if direct.search(p.read_text()) and p != root / "gcs_planner" / "planning" / "__init__.py"
    ]
    assert not offenders
