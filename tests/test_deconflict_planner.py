"""The staged 4-D deconfliction planner: kinematic limits on outputs, stages, report, determinism."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gcs_planner.model.scenario import ScenarioError
from gcs_planner.planning import config_of, parse_scenario, plan_scenario
from gcs_planner.planning.deconflict4d.conflicts import closest_approach

V_MAX, A_MAX, SEP = 5.0, 2.0, 1.0


def _scenario(n: int = 4, radius: float = 8.0, with_manned: bool = True, **planner) -> dict:
    vehicles = []
    for i in range(n):
        a = 2 * math.pi * i / n
        s = [radius * math.cos(a), radius * math.sin(a), 10.0]
        vehicles.append(
            {
                "id": f"uav{i + 1}",
                "sysid": i + 1,
                "start": s,
                "goal": [-s[0], -s[1], 10.0],
                "speed_mps": 4.0,
                "separation_m": SEP,
                "min_alt_m": 5.0,
                "max_alt_m": 20.0,
            }
        )
    data = {
        "name": "test",
        "origin": {"lat_deg": 47.4, "lon_deg": 8.5, "alt_m": 400.0},
        "planner": {
            "name": "deconflict_4d",
            "seed": 3,
            "particles": 20,
            "iterations": 60,
            "init_spread_m": 0.5,
            "safety_m": 1.0,
            **planner,
        },
        "vehicles": vehicles,
    }
    if with_manned:
        data["manned"] = [
            {
                "id": "ga1",
                "dt_s": 1.0,
                "position_m": [-60.0, 6.0, 12.0],
                "velocity_mps": [10.0, 0.0, 0.0],
                "observed_s": 5.0,
                "modes": [{"name": "cruise", "velocity_mps": [10.0, 0, 0], "sigma_mps": [0.3, 0.3, 0.1]}],
            }
        ]
    return data


def _min_separation(plan) -> float:
    best = math.inf
    vs = plan.vehicles
    for i in range(len(vs)):
        for j in range(i + 1, len(vs)):
            d, _ = closest_approach(vs[i].path, vs[i].path_times_s, vs[j].path, vs[j].path_times_s)
            best = min(best, float(d))
    return best


@pytest.fixture(scope="module")
def four_uav_plan():
    return plan_scenario(parse_scenario(_scenario(4)))


def test_plan_is_conflict_free_and_separated_on_flown_paths(four_uav_plan):
    plan = four_uav_plan
    assert plan.metrics["conflict_free"] and plan.feasible
    assert _min_separation(plan) >= SEP
    # the straight plan they started from is not: all four cross the centre together
    straight = [v.path for v in plan.vehicles]
    assert len(straight) == 4
    manned = plan.metrics["manned"][0]
    assert manned["velocity_mps"] == pytest.approx([10.0, 0.0, 0.0], abs=1e-6)


def test_kinematic_limits_hold_on_outputs(four_uav_plan):
    for v in four_uav_plan.vehicles:
        t, p = v.path_times_s, v.path
        assert np.all(np.diff(t) > 0)
        vel = np.diff(p, axis=0) / np.diff(t)[:, None]
        assert np.abs(vel).max() <= V_MAX * (1 + 1e-6)  # per-axis speed limit (paper)
        tm = 0.5 * (t[1:] + t[:-1])
        acc = np.diff(vel, axis=0) / np.diff(tm)[:, None]
        assert np.abs(acc).max() <= A_MAX * (1 + 1e-3)  # per-axis acceleration limit
        # waypoint timing is what the mission keeps: legs flown at speeds_mps take times_s
        legs = np.linalg.norm(np.diff(v.waypoints, axis=0), axis=1)
        np.testing.assert_allclose(legs / v.speeds_mps[1:], np.diff(v.times_s), rtol=1e-9)
        assert abs(v.path[0, 2]) < 1e-9 and abs(v.path[-1, 2]) < 1e-9  # climb from / descent to the ground
        assert v.waypoints[:, 2].min() >= 5.0 - 1e-9
        assert v.cost["arrival_error_s"] <= 30.0


def test_deterministic_for_a_seed():
    data = _scenario(4, iterations=20)
    a = plan_scenario(parse_scenario(data)).to_json()
    b = plan_scenario(parse_scenario(data)).to_json()
    assert _strip_wall(a) == _strip_wall(b)
    c = plan_scenario(parse_scenario(data), seed=99).to_json()
    assert _strip_wall(c) != _strip_wall(a)


def _strip_wall(text: str) -> str:
    import json

    d = json.loads(text)
    d["metrics"].pop("wall_s")
    for s in d["metrics"]["stages"]:
        s.pop("wall_s")
    d["events"] = [{k: v for k, v in e.items() if k != "wall_s"} for e in d["events"]]
    return json.dumps(d, sort_keys=True)


def test_delayed_takeoff_resolves_head_on_conflict():
    # PSO crippled (1 iteration, no spread): only delaying a take-off can separate them
    data = _scenario(
        2,
        with_manned=False,
        iterations=1,
        particles=1,
        init_spread_m=0.0,
        use_waypoints=False,
        delay_step_s=1.0,
    )
    plan = plan_scenario(parse_scenario(data))
    stages = {s["stage"]: s for s in plan.metrics["stages"]}
    assert plan.metrics["conflict_free"]
    assert stages["delay"]["trajectories_adjusted"] == 1 and stages["delay"]["iterations"] >= 1
    delays = sorted(v.takeoff_delay_s for v in plan.vehicles)
    assert delays[0] == 0.0 and delays[1] >= 1.0
    assert _min_separation(plan) >= SEP


def test_waypoint_insertion_resolves_conflict_without_delay():
    data = _scenario(
        2,
        with_manned=False,
        iterations=1,
        particles=1,
        init_spread_m=0.0,
        use_delay=False,
        insert_particles=15,
        insert_iterations=40,
    )
    plan = plan_scenario(parse_scenario(data))
    assert plan.metrics["conflict_free"]
    assert plan.metrics["waypoints_added"] >= 1
    assert max(len(v.waypoints) for v in plan.vehicles) >= 4
    assert all(v.takeoff_delay_s == 0.0 for v in plan.vehicles)
    assert _min_separation(plan) >= SEP


def test_remaining_conflicts_are_reported_explicitly():
    data = _scenario(
        2,
        with_manned=False,
        iterations=1,
        particles=1,
        init_spread_m=0.0,
        use_delay=False,
        use_waypoints=False,
        max_rounds=1,
    )
    plan = plan_scenario(parse_scenario(data))
    assert not plan.metrics["conflict_free"] and not plan.feasible
    (conflict,) = plan.metrics["conflicts_remaining"]
    assert {conflict["a"], conflict["b"]} == {"uav1", "uav2"} and conflict["distance_m"] < SEP
    assert all("conflicts remain" in " ".join(v.notes) for v in plan.vehicles)


def test_manned_zone_is_avoided():
    # the manned aircraft flies straight through the crossing point at UAV altitude
    data = _scenario(2, radius=6.0)
    data["manned"][0].update(position_m=[-80.0, 0.0, 10.0], velocity_mps=[10.0, 0.0, 0.0])
    data["manned"][0]["modes"][0]["velocity_mps"] = [10.0, 0, 0]
    plan = plan_scenario(parse_scenario(data))
    assert plan.metrics["conflict_free"]
    assert plan.metrics["dense_check"]["min_zone_whitened_distance"] >= 1.0


def test_bad_settings_name_the_field():
    with pytest.raises(ScenarioError, match="planner: unknown key 'bogus'"):
        config_of(parse_scenario(_scenario(2, bogus=1)))
    with pytest.raises(ScenarioError, match="planner.iterations must be an integer, got 'many'"):
        config_of(parse_scenario(_scenario(2, iterations="many")))
