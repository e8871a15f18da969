"""Priority swarm planner: independent check passes, waypoints fly the path, seeded, no hidden failures."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from gcs_planner.core.config import parse
from gcs_planner.core.errors import UserError
from gcs_planner.core.geo import Origin
from gcs_planner.geometry.obstacles import HARD_PENALTY, Obstacles
from gcs_planner.model.scenario import Cylinder, Scenario, Vehicle
from gcs_planner.planning import load_scenario, plan_scenario, priority_swarm
from gcs_planner.planning.priority_swarm import Config, CostModel, Traffic, prepare, timed_samples
from gcs_planner.safety.separation import check_plan

MISSIONS = Path(__file__).resolve().parent.parent / "missions"
FAST = {"name": "priority_swarm", "waypoints": 3, "particles": 12, "iterations": 15, "rounds": 2}


@pytest.fixture(scope="module")
def small_plan():
    scenario = load_scenario(MISSIONS / "swarm_small.toml")
    return scenario, plan_scenario(scenario, seed=3)


def _polyline_distance(points: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Distance of each point to the polyline (what a waypoint-to-waypoint autopilot flies)."""
    a, b = poly[:-1], poly[1:]
    d = b - a
    dd = np.maximum(np.sum(d * d, axis=1), 1e-12)
    t = np.clip(np.einsum("pkj,kj->pk", points[:, None, :] - a, d) / dd, 0, 1)
    return np.linalg.norm(points[:, None, :] - (a + t[..., None] * d), axis=2).min(axis=1)


def test_small_scenario_plan_passes_independent_check(small_plan):
    scenario, plan = small_plan
    assert plan.planner == "priority_swarm"
    report = check_plan(plan, scenario, step_s=0.5, max_climb_rad=math.radians(20))
    assert report.ok, report.summary()
    assert plan.feasible and plan.metrics["feasible_count"] == len(scenario.vehicles)
    for vp, veh in zip(plan.vehicles, scenario.vehicles):
        assert np.allclose(vp.path[0], veh.start) and np.allclose(vp.path[-1], veh.goal)
        assert np.allclose(vp.waypoints[0], veh.start) and np.allclose(vp.waypoints[-1], veh.goal)
        assert np.all(np.diff(vp.path_times_s) > 0) and np.all(np.diff(vp.times_s) > 0)
        # the mission waypoints reproduce the smoothed path within the decimation tolerance
        assert _polyline_distance(vp.path, vp.waypoints).max() < 1.0 + 1e-6
        assert {"F1", "F2", "F3", "F4", "F5", "total", "length_m"} <= set(vp.cost)
        assert vp.cost["total"] < HARD_PENALTY


def test_same_seed_same_plan_other_seed_differs():
    scenario = load_scenario(MISSIONS / "swarm_small.toml")
    scenario.planner = dict(FAST)
    scenario.vehicles = scenario.vehicles[:3]
    a = plan_scenario(scenario, seed=11).to_dict()
    b = plan_scenario(scenario, seed=11).to_dict()
    c = plan_scenario(scenario, seed=12).to_dict()
    for d in (a, b, c):
        d["metrics"].pop("wall_time_s")
    assert a == b
    assert a["vehicles"] != c["vehicles"]


def _random_scenario(seed: int) -> Scenario:
    rng = np.random.default_rng(seed)
    cyl = []
    while len(cyl) < 5:
        x, y, r = rng.uniform(120, 380), rng.uniform(-20, 220), rng.uniform(10, 25)
        if all(math.hypot(x - c.x, y - c.y) > r + c.radius_m + 20 for c in cyl):
            cyl.append(Cylinder(x=x, y=y, radius_m=r, z_max_m=float(rng.choice([60.0, 300.0])), buffer_m=4.0))
    n = 4
    ys = rng.permutation(n) * 60.0
    vehicles = [
        Vehicle(
            id=f"r{k}",
            sysid=k + 1,
            type="multirotor",
            start=(0.0, 60.0 * k, float(rng.uniform(25, 50))),
            goal=(500.0, float(ys[k]), float(rng.uniform(25, 50))),
            speed_mps=float(rng.uniform(8, 14)),
            turn_radius_m=float(rng.uniform(10, 25)),
            min_alt_m=20.0,
            max_alt_m=100.0,
            separation_m=8.0,
            priority=float(rng.integers(1, 3)),
        )
        for k in range(n)
    ]
    bounds = {"x": (-80.0, 580.0), "y": (-80.0, 260.0)}
    return Scenario(f"random{seed}", Origin(47.0, 8.0, 400.0), dict(FAST), vehicles, cyl, bounds=bounds)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_random_scenarios_checker_agrees_with_feasible_flags(seed):
    scenario = _random_scenario(seed)
    plan = plan_scenario(scenario, seed=seed)
    report = check_plan(plan, scenario, step_s=0.5, max_climb_rad=math.radians(20))
    flagged = {vp.vehicle_id for vp in plan.vehicles if not vp.feasible}
    assert report.bad_vehicles() <= flagged  # never a silent violation
    for vp in plan.vehicles:
        if not vp.feasible:
            assert vp.notes, vp.vehicle_id
    assert len(flagged) <= 1  # these scenarios are easy: at most one failure is tolerated


def test_unavoidable_start_conflict_is_repaired_by_delayed_takeoff():
    # two UAVs start 3 m apart (separation 8 m) and fly away in different directions
    vehicles = [
        Vehicle(
            "a", 1, "multirotor", (0.0, 0.0, 40.0), (300.0, 100.0, 40.0), 10.0, 15.0, 20.0, 100.0, 8.0, 2.0
        ),
        Vehicle(
            "b", 2, "multirotor", (0.0, 3.0, 40.0), (300.0, -100.0, 40.0), 10.0, 15.0, 20.0, 100.0, 8.0, 1.0
        ),
    ]
    scenario = Scenario("pair", Origin(47.0, 8.0, 400.0), dict(FAST), vehicles)
    plan = plan_scenario(scenario, seed=1)
    report = check_plan(plan, scenario)
    assert report.ok, report.summary()
    assert plan.vehicle("b").takeoff_delay_s > 0 and plan.vehicle("a").takeoff_delay_s == 0
    assert plan.vehicle("b").path_times_s[0] == plan.vehicle("b").takeoff_delay_s
    assert any("delayed" in n for n in plan.vehicle("b").notes)


def test_cost_model_prices_obstacles_and_traffic():
    scenario = _random_scenario(4)
    scenario.cylinders = [Cylinder(x=250.0, y=0.0, radius_m=20.0, z_max_m=300.0, buffer_m=5.0)]
    scenario.vehicles = [
        dataclasses.replace(scenario.vehicles[0], start=(0.0, 0.0, 40.0), goal=(500.0, 0.0, 40.0))
    ]
    cfg = parse(Config, FAST, "planner")
    (prob,), obstacles, _, _ = prepare(scenario, cfg)
    straight = np.tile([0.0, 0.0, 40.0], 3) + np.repeat([125.0, 250.0, 375.0], 3) * np.tile([1, 0, 0], 3)
    detour = straight.copy()
    detour[[1, 4, 7]] = 80.0
    model = CostModel(prob, obstacles, Traffic(cfg.dt_s), cfg)
    through, around = model(np.vstack([straight, detour]))
    assert through > HARD_PENALTY > around
    # the same vehicle already flying the detour blocks the detour (separation on the timed grid)
    traffic = Traffic(cfg.dt_s)
    slices, pos = timed_samples(prob, detour, cfg)
    traffic.add(slices, pos, 8.0, prob.vehicle.speed_mps)
    assert CostModel(prob, obstacles, traffic, cfg)(detour[None, :])[0] > HARD_PENALTY


@pytest.mark.parametrize("landing_mps", [0.0, 1.0])
def test_a_landing_under_earlier_traffic_is_priced(landing_mps):
    """A UAV hovers 10 m below the goal of a later one: the path itself stays 10 m above it, but a
    landing at the goal descends through it (seen as a 4.9 m breach when swarm500 was flown: the
    landing column was in the traffic only, not in the cost of the vehicle that lands)."""
    scenario = _random_scenario(4)
    scenario.cylinders = []
    scenario.vehicles = [
        dataclasses.replace(
            scenario.vehicles[0], start=(0.0, 0.0, 40.0), goal=(300.0, 0.0, 40.0), landing_mps=landing_mps
        )
    ]
    cfg = parse(Config, FAST, "planner")
    (prob,), obstacles, _, _ = prepare(scenario, cfg)
    straight = np.tile([0.0, 0.0, 40.0], 3) + np.repeat([75.0, 150.0, 225.0], 3) * np.tile([1, 0, 0], 3)
    traffic = Traffic(cfg.dt_s)
    hover = np.arange(0, 400)  # 200 s at (300, 0, 30)
    traffic.add(hover, np.broadcast_to([300.0, 0.0, 30.0], (len(hover), 3)), 5.0, prob.vehicle.speed_mps)
    cost = CostModel(prob, obstacles, traffic, cfg)(straight[None, :])[0]
    assert (cost > HARD_PENALTY) == (landing_mps > 0)


def test_cylinder_terms_are_the_four_nearest_axes_of_a_brute_force_search():
    """F2 (a compiled walk of the axis grid) against every cylinder written out: per sample the
    four nearest axes within reach, in their altitude band, buffer depth times the sample's length
    and HARD + the depth inside the radius, summed per particle."""
    rng = np.random.default_rng(3)
    draw = rng.uniform([-60, -60, 3, 0, 0], [60, 60, 12, 8, 40], (60, 5))
    cyl = [
        Cylinder(x=x, y=y, radius_m=r, buffer_m=b, z_min_m=z0, z_max_m=z0 + 30.0)
        for x, y, r, b, z0 in draw.tolist()
    ]
    obstacles = Obstacles.from_scenario(cyl)
    cfg = parse(Config, FAST, "planner")
    probs, _, _, _ = prepare(_random_scenario(1), cfg)
    model = CostModel(probs[0], obstacles, Traffic(cfg.dt_s), cfg)
    mid = rng.uniform([-80, -80, 0], [80, 80, 70], (5, 200, 3))
    ds = rng.uniform(0.5, 6.0, (5, 200))
    soft, hard = np.zeros(5), np.zeros(5)
    priority_swarm._cylinder_sums(
        mid, ds, model._axes, model._cyl, cfg.obstacle_margin_m, model._reach, soft, hard
    )
    want_soft, want_hard = np.zeros(5), np.zeros(5)
    for p, k in np.ndindex(5, 200):
        x, y, z = mid[p, k]
        d = np.hypot(obstacles.cx - x, obstacles.cy - y)
        for j in [j for j in np.argsort(d, kind="stable")[:4] if d[j] < model._reach]:
            if obstacles.z_min_m[j] <= z <= obstacles.z_max_m[j]:
                r, buf = obstacles.radius_m[j] + cfg.obstacle_margin_m, obstacles.buffer_m[j]
                want_soft[p] += np.clip((r + buf - d[j]) / max(buf, 1e-9), 0.0, 1.0) * ds[p, k]
                want_hard[p] += (HARD_PENALTY + r - d[j]) if r > d[j] else 0.0
    assert (want_hard > HARD_PENALTY).all() and (want_soft > 0).all()
    np.testing.assert_allclose(soft, want_soft, rtol=1e-9)
    np.testing.assert_allclose(hard, want_hard, rtol=1e-9)


def test_bad_planner_parameters_are_named():
    with pytest.raises(UserError, match="unknown key 'particle'; did you mean 'particles'"):
        parse(Config, {"name": "priority_swarm", "particle": 3}, "planner")
    with pytest.raises(UserError, match=r"planner.dt_s must be a number <= 0.5, got 1.0"):
        parse(Config, {"name": "priority_swarm", "dt_s": 1.0}, "planner")
    with pytest.raises(UserError, match="planner.iterations must be an integer, got 2.5"):
        parse(Config, {"name": "priority_swarm", "iterations": 2.5}, "planner")


@pytest.mark.parametrize("method", ["pso", "de", "gwo"])
def test_baselines_use_the_same_budget_and_are_checked(method):
    from gcs_planner.planning.baselines import plan_baseline

    scenario = _random_scenario(5)
    scenario.vehicles = scenario.vehicles[:2]
    plan = plan_baseline(scenario, np.random.default_rng(0), method, evaluations_per_vehicle=120)
    assert plan.metrics["evaluations"] <= 120 * len(scenario.vehicles)
    assert plan.metrics["evaluations"] >= 100 * len(scenario.vehicles)
    report = check_plan(plan, scenario, step_s=0.5, max_climb_rad=math.radians(20))
    assert report.bad_vehicles() <= {vp.vehicle_id for vp in plan.vehicles if not vp.feasible}


def test_the_compare_task_gives_a_baseline_the_methods_counted_budget_on_the_same_seed():
    from gcs_planner.planning.baselines import compare_run, plan_baseline

    path = MISSIONS / "swarm_small.toml"
    params = {**FAST, "rounds": 1, "rrt_iterations": 60}
    runs = compare_run(path, {**params, "baselines": "de"}, 4)
    assert sorted(runs) == ["de", "priority_swarm"]
    method, de = runs["priority_swarm"], runs["de"]
    scenario = load_scenario(path)
    scenario.planner.update(params)
    assert method["cost_total"] == plan_scenario(scenario, seed=4).metrics["cost_total"]
    budget = method["evaluations"] // len(scenario.vehicles)
    direct = plan_baseline(scenario, np.random.default_rng(4), "de", budget).metrics
    assert de["cost_total"] == direct["cost_total"] and de["evaluations"] == direct["evaluations"]
    assert de["evaluations"] <= method["evaluations"] and de["method"] == "de"
    assert de["cpu_s"] > 0 and method["cpu_s"] > 0
    with pytest.raises(ValueError, match="'abc' is not one of pso, de, gwo"):
        compare_run(path, {**params, "baselines": "de,abc"}, 4)


def test_ablation_switches_remove_the_rrt_start_and_the_priority_order():
    scenario = load_scenario(MISSIONS / "swarm_small.toml")
    scenario.planner = {**FAST, "rounds": 1, "rrt_iterations": 80}
    full = plan_scenario(scenario, seed=2)
    scenario.planner.update(rrt_start=False, priority_order=False)
    bare = plan_scenario(scenario, seed=2)
    ids = [v.id for v in scenario.vehicles]
    assert set(full.metrics["rrt_difficulty"].values()) != {1.0}
    assert set(bare.metrics["rrt_difficulty"].values()) == {1.0}  # no RRT* run
    assert bare.metrics["priority_order"] == ids  # scenario order
    assert full.metrics["priority_order"][:2] == ["uav1", "uav4"]  # priority 2 first


def test_a_landing_at_the_goal_is_traffic_for_the_planner_and_the_checker():
    """A plans to land at its goal at 1 m/s; B's straight line crosses that goal 1 s after A
    arrives, 1 m above A's descending column. The checker sees the conflict only with landing_mps;
    the planner, told the same, plans B clear of the column (500 mock vehicles flown: 65 of 67
    separation breaches were a vehicle passing another that was landing at its goal)."""
    common = dict(type="multirotor", speed_mps=10.0, turn_radius_m=20.0, min_alt_m=20.0, max_alt_m=60.0)
    a = Vehicle(id="a", sysid=1, start=(0.0, 0.0, 30.0), goal=(100.0, 0.0, 30.0), priority=2.0, **common)
    b = Vehicle(id="b", sysid=2, start=(100.0, -110.0, 30.0), goal=(100.0, 110.0, 30.0), **common)
    scenario = Scenario("landing", Origin(47.0, 8.0, 0.0), dict(FAST), [a, b])
    landed = [dataclasses.replace(v, landing_mps=1.0) for v in (a, b)]
    landing = dataclasses.replace(scenario, vehicles=landed)
    blind = plan_scenario(scenario, seed=2)
    assert check_plan(blind, scenario).ok  # gone on arrival: the straight lines never meet
    conflicts = check_plan(blind, landing).conflicts
    assert [(c[0], c[1]) for c in conflicts] == [("a", "b")], conflicts
    seen = plan_scenario(landing, seed=2)
    assert check_plan(seen, landing).ok, check_plan(seen, landing).summary()


def test_a_delayed_vehicle_that_waits_airborne_is_traffic_at_its_start_until_it_departs():
    cfg = parse(Config, FAST, "planner")
    common = dict(type="multirotor", speed_mps=10.0, turn_radius_m=20.0, min_alt_m=20.0, max_alt_m=60.0)
    v = Vehicle(id="a", sysid=1, start=(0.0, 0.0, 30.0), goal=(200.0, 0.0, 30.0), waits_airborne=True,
                **common)  # fmt: skip
    scenario = Scenario("wait", Origin(47.0, 8.0, 0.0), dict(FAST), [v])
    (prob,), *_ = prepare(scenario, cfg)
    x = np.linspace(prob.start, prob.goal, prob.n_wp + 2)[1:-1].ravel()
    prob.delay_s = 3.0
    slices, pos = timed_samples(prob, x, cfg)
    waiting = slices * cfg.dt_s < prob.delay_s
    assert list(slices[waiting]) == list(range(6)) and np.allclose(pos[waiting], v.start)
    grounded = dataclasses.replace(prob, vehicle=dataclasses.replace(v, waits_airborne=False))
    assert timed_samples(grounded, x, cfg)[0][0] * cfg.dt_s >= prob.delay_s - 1e-9  # the paper's model


def test_the_repair_re_plans_the_vehicle_passing_one_that_waits_at_its_start():
    """Delaying a vehicle that waits airborne at its start would keep it in the way: the repair
    re-plans the other one, whatever their priorities; after departure, priority decides."""
    from gcs_planner.planning.priority_swarm import _loser

    cfg = parse(Config, FAST, "planner")
    common = dict(type="multirotor", speed_mps=10.0, turn_radius_m=20.0, min_alt_m=20.0, max_alt_m=60.0)
    a = Vehicle(id="a", sysid=1, start=(0.0, 0.0, 30.0), goal=(200.0, 0.0, 30.0), waits_airborne=True,
                **common)  # fmt: skip
    b = Vehicle(id="b", sysid=2, start=(-25.0, 0.0, 30.0), goal=(200.0, 20.0, 30.0), **common)
    problems, *_ = prepare(Scenario("w", Origin(47.0, 8.0, 0.0), dict(FAST), [a, b]), cfg)
    problems[0].delay_s = 5.0
    rank = {0: 1, 1: 0}  # b plans first: a is the lower priority
    assert _loser(problems, 0, 1, 2.0, rank) == 1  # b passes a while a waits
    assert _loser(problems, 0, 1, 7.0, rank) == 0  # both flying: the lower priority
