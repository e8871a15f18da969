"""The one safety checker: every planner's plan goes through it in plan_scenario, its verdict is
``VehiclePlan.feasible`` and its findings are the vehicles' ``check:`` notes; every bundled
scenario's plan passes it; conformance measures flown tracks with the same geometry; ``fly``
refuses an infeasible plan unless told."""

from __future__ import annotations

import copy
import logging
import os
import tomllib
from pathlib import Path

import numpy as np
import pytest

from gcs_planner.cli import main
from gcs_planner.commands.fly import check_feasible
from gcs_planner.model.scenario import Cylinder
from gcs_planner.planning import load_scenario as load_checked
from gcs_planner.planning import parse_scenario, plan_scenario, planner
from gcs_planner.safety.conformance import Track, conformance_report
from gcs_planner.safety.separation import Trajectory, closest_approach_m

MISSIONS = Path(__file__).resolve().parents[1] / "missions"
# planner keys that make a bundled scenario quick to plan (the plan still has to pass)
QUICK = {
    "priority_swarm": {"particles": 8, "iterations": 12, "rounds": 1, "rrt_iterations": 150},
    "acmpso": {"particles": 20, "iterations": 25},
    "deconflict_4d": {"iterations": 20},
}
# these need about the default budget to come out clean: each obstacle maze ~8 s on one core,
# swarm500 about a minute (docs/results/priority_swarm_scale.md)
MAZE = {"particles": 12, "iterations": 20, "rounds": 2}
FULL_BUDGET = {"swarm40_passages": MAZE, "swarm40_urban": MAZE, "swarm500": {}}
ALL = os.environ.get("GCS_PLANNER_ALL_SCENARIOS") == "1"
SKIP = {} if ALL else dict.fromkeys(FULL_BUDGET, "needs the default budget: GCS_PLANNER_ALL_SCENARIOS=1")


def _raw(name: str) -> dict:
    return tomllib.loads((MISSIONS / f"{name}.toml").read_text())


def _scenario(raw: dict, name: str):
    scenario = parse_scenario(raw, name)
    scenario.path = MISSIONS / f"{name}.toml"  # relative world files ([site], [terrain]) resolve
    return scenario


def _check_notes(vp) -> list[str]:
    return [n for n in vp.notes if n.startswith("check: ")]


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(p.stem for p in MISSIONS.glob("*.toml")))
def test_every_bundled_scenario_plan_passes_the_one_checker(name):
    if name in SKIP:
        pytest.skip(SKIP[name])
    scenario = load_checked(MISSIONS / f"{name}.toml")
    scenario.planner.update(FULL_BUDGET.get(name, QUICK.get(scenario.planner_name, {})))
    if scenario.planner_name == "coalition":
        scenario.planner["t_end_s"] = 90.0  # the first targets' phases
    plan = plan_scenario(scenario)
    bad = {v.vehicle_id: _check_notes(v) for v in plan.vehicles if not v.feasible}
    assert plan.feasible, bad
    assert not any(_check_notes(v) for v in plan.vehicles)


def test_straight_through_a_tower_is_infeasible():
    """straight always called its plan feasible; a tower on its line now shows."""
    raw = _raw("straight_4uav")
    raw["obstacles"] = {"cylinders": [{"x": 150.0, "y": 0.0, "radius_m": 10.0, "z_max_m": 100.0}]}
    plan = plan_scenario(_scenario(raw, "straight_4uav"))
    assert not plan.vehicle("uav1").feasible
    assert any("enters an obstacle" in n for n in _check_notes(plan.vehicle("uav1")))
    assert all(plan.vehicle(v).feasible for v in ("uav2", "uav3", "uav4"))


def test_deconflict_4d_through_a_tower_is_infeasible(caplog):
    """The 4-D planner ignores static obstacles and called a conflict-free plan feasible."""
    raw = _raw("deconflict_4uav")
    raw["obstacles"] = {"cylinders": [{"x": 0.0, "y": 0.0, "radius_m": 2.0, "z_max_m": 50.0}]}
    with caplog.at_level(logging.WARNING):
        plan = plan_scenario(_scenario(raw, "deconflict_4uav"))
    assert plan.metrics["conflict_free"]  # what the planner itself saw
    bad = [v for v in plan.vehicles if not v.feasible]
    assert bad and all(any("enters an obstacle" in n for n in _check_notes(v)) for v in bad)


def test_acmpso_vehicles_on_one_track_are_infeasible():
    """ACMPSO plans each vehicle alone against the threats: two on one track conflict."""
    raw = _raw("acmpso_paper")
    raw["planner"].update(QUICK["acmpso"])
    twin = copy.deepcopy(raw["vehicles"][0])
    twin.update(id="twin", sysid=2)
    raw["vehicles"].append(twin)
    plan = plan_scenario(_scenario(raw, "acmpso_paper"))
    assert not plan.feasible
    for vp in plan.vehicles:
        assert any(n.startswith("check: separation") for n in _check_notes(vp)), vp.notes


def test_coalition_plan_is_held_to_the_band_and_separation():
    """The coalition's own flag only asked whether each leg was clear of threats: with the paper's
    type layers alone (every plane of a type at one altitude, the default 120 m band), planes of a
    type pass under the separation and every plane flies over its band."""
    raw = _raw("coalition_sitl")
    raw["planner"]["t_end_s"] = 300.0
    for v in raw["vehicles"]:
        v["start"][2] = v["goal"][2] = 120.0 + 60.0 * (v["capabilities"] == "S")
        del v["max_alt_m"]
    plan = plan_scenario(_scenario(raw, "coalition_sitl"))
    notes = [n for v in plan.vehicles for n in _check_notes(v)]
    assert any("separation" in n for n in notes)
    strikers = {r["id"] for r in raw["vehicles"] if r["capabilities"] == "S"}
    assert all(any("altitude band" in n for n in _check_notes(plan.vehicle(v))) for v in strikers)


def test_priority_swarm_flag_is_the_checkers_not_the_planners(monkeypatch):
    """A plan the planner called feasible is judged again: two vehicles made to meet are not."""
    module = planner("priority_swarm")
    own = module.plan

    def meeting(scenario, config, rng, progress):
        plan = own(scenario, config, rng, progress)
        a, b = plan.vehicles[0], plan.vehicles[1]
        assert a.feasible and b.feasible  # the planner's own verdict
        b.path, b.path_times_s = a.path + [0.5, 0.0, 0.0], a.path_times_s.copy()
        return plan

    monkeypatch.setattr(module, "plan", meeting)
    plan = plan_scenario(load_checked(MISSIONS / "swarm_small.toml"))
    a, b = plan.vehicles[0], plan.vehicles[1]
    assert not a.feasible and not b.feasible
    assert any(f"from {b.vehicle_id}" in n for n in _check_notes(a))


def test_conformance_separation_is_the_checkers_closest_approach():
    """Two crossing passes whose closest approach, sqrt(2 x 2.5^2 + 3^2) m, falls between telemetry
    samples: conformance reports the exact value the checker's solution gives."""
    t = np.arange(0.0, 10.01, 1.0)
    east = np.column_stack([10.0 * t - 50.0, np.zeros_like(t), np.full_like(t, 20.0)])
    north = np.column_stack([np.zeros_like(t), 10.0 * t - 55.0, np.full_like(t, 23.0)])
    tracks = {1: Track(t, east, True), 2: Track(t, north, True)}
    expected = closest_approach_m([Trajectory("1", t, east), Trajectory("2", t, north)], 0.1)
    assert expected == pytest.approx([np.sqrt(21.5)] * 2, abs=1e-9)
    plan = plan_scenario(load_checked(MISSIONS / "straight_4uav.toml"))
    plan.vehicles = plan.vehicles[:2]
    plan.vehicles[0].sysid, plan.vehicles[1].sysid = 1, 2
    reports = conformance_report(plan, tracks, {1: 5.0, 2: 5.0}, [Cylinder(0.0, 0.0, 1.0, 100.0)])
    assert [r.min_separation_m for r in reports] == pytest.approx(list(expected))
    assert all("separation 4.6 m < 5.0 m" in r.failures for r in reports)
    assert reports[0].min_obstacle_clearance_m == pytest.approx(-1.0)  # flies over the axis


def test_fly_refuses_an_infeasible_plan_unless_told(tmp_path, capsys):
    raw_path = tmp_path / "tower.toml"
    text = (MISSIONS / "straight_4uav.toml").read_text()
    raw_path.write_text(
        text + "\n[[obstacles.cylinders]]\nx = 150.0\ny = 0.0\nradius_m = 10.0\nz_max_m = 100.0\n"
    )
    assert main(["plan", str(raw_path), "-o", str(tmp_path / "plan.json")]) == 1
    assert "uav1: check: enters an obstacle by" in capsys.readouterr().out
    out = tmp_path / "out"
    assert main(["fly", str(raw_path), "--plan", str(tmp_path / "plan.json"), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "infeasible for ['uav1']" in err and "--allow-infeasible" in err
    assert "enters an obstacle" in err and not out.exists()


def test_allow_infeasible_warns_and_goes_on(capsys):
    raw = _raw("straight_4uav")
    raw["obstacles"] = {"cylinders": [{"x": 150.0, "y": 0.0, "radius_m": 10.0, "z_max_m": 100.0}]}
    plan = plan_scenario(_scenario(raw, "straight_4uav"))
    check_feasible(plan, allow=True)
    assert "flying anyway (--allow-infeasible)" in capsys.readouterr().out
    check_feasible(
        plan_scenario(load_checked(MISSIONS / "straight_4uav.toml")), allow=False
    )  # feasible: quiet
    assert capsys.readouterr().out == ""


def test_fly_rechecks_a_plan_file_against_its_scenario(tmp_path, capsys):
    """A plan file's feasible flags are whatever wrote it: a plan made before a tower was added,
    or edited by hand, is checked again against the scenario it is flown in."""
    plan_path = tmp_path / "plan.json"
    assert main(["plan", str(MISSIONS / "straight_4uav.toml"), "-o", str(plan_path)]) == 0
    tower = tmp_path / "tower.toml"
    tower.write_text(
        (MISSIONS / "straight_4uav.toml").read_text()
        + "\n[[obstacles.cylinders]]\nx = 150.0\ny = 0.0\nradius_m = 10.0\nz_max_m = 100.0\n"
    )
    capsys.readouterr()
    out = tmp_path / "out"
    assert main(["fly", str(tower), "--plan", str(plan_path), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "infeasible for ['uav1']" in err and "enters an obstacle" in err and not out.exists()
    other = MISSIONS / "acmpso_paper.toml"  # its vehicles are not the plan's
    assert main(["fly", str(other), "--plan", str(plan_path), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "are not in scenario" in err and not out.exists()


def test_a_landing_stops_at_its_goal_before_it_descends():
    """A landing vehicle's route ends at full speed; it stops at its goal before it descends,
    R / (2 v) later than the constant-speed plan (braking at its turns' v^2 / R). 'over' crosses
    1.3 m from the goal 6 s after 'lander' arrived: 5.4 m above a descent that began on arrival,
    4.7 m above the one flown after the stop (swarm500's uav32 and uav131 met so, 4.5-4.7 m)."""
    from gcs_planner.core.geo import Origin
    from gcs_planner.model.plan import Plan, VehiclePlan
    from gcs_planner.model.scenario import Scenario, Vehicle
    from gcs_planner.safety.separation import check_plan

    kw = dict(type="multirotor", speed_mps=12.0, turn_radius_m=20.0, min_alt_m=20.0, max_alt_m=60.0)
    lander = Vehicle(
        id="lander", sysid=1, start=(-120.0, 0.0, 40.0), goal=(0.0, 0.0, 40.0), landing_mps=1.0, **kw
    )
    over = Vehicle(id="over", sysid=2, start=(-120.0, 1.3, 39.3), goal=(120.0, 1.3, 39.3), **kw)
    assert lander.landing_stop_s == pytest.approx(20.0 / 24.0) and over.landing_stop_s == 0.0

    def straight(v, t0):
        wp = np.array([v.start, v.goal], dtype=float)
        t = t0 + np.array([0.0, np.linalg.norm(wp[1] - wp[0]) / v.speed_mps])
        return VehiclePlan(v.id, v.sysid, wp, t, [12.0, 12.0], wp, t, turn_radius_m=20.0)

    plan = Plan(Origin(47.4, 8.5, 488.0), "landing", [straight(lander, 0.0), straight(over, 6.0)])
    scenario = Scenario(name="landing", origin=plan.origin, planner={}, vehicles=[lander, over])
    gaps = {}
    for stop_s in (0.0, lander.landing_stop_s):
        trajs = [Trajectory.from_plan(plan.vehicles[0], 5.0, 1.0, landing_stop_s=stop_s),
                 Trajectory.from_plan(plan.vehicles[1], 5.0)]  # fmt: skip
        gaps[stop_s] = float(closest_approach_m(trajs, 0.05).min())
    assert gaps[0.0] > 5.0 > gaps[lander.landing_stop_s]
    report = check_plan(plan, scenario, kinematics=False)
    assert [c[:2] for c in report.conflicts] == [("lander", "over")], report.summary()
