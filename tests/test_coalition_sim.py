"""The seed-003 experiment (missions/coalition_paper.toml) through the event simulation and plan()."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import msgspec
import numpy as np
import pytest

from gcs_planner.model.plan import Plan
from gcs_planner.planning import load_scenario, plan_scenario
from gcs_planner.planning.coalition import leg_vehicle_plan, load_world, paths, simulate
from gcs_planner.planning.coalition.sim import CoalitionSim

MISSION = Path(__file__).resolve().parents[1] / "missions" / "coalition_paper.toml"


@pytest.fixture(scope="module")
def world():
    return load_world(load_scenario(MISSION))


@pytest.fixture(scope="module")
def result(world):
    return simulate(world, np.random.default_rng(3))


def _events(result, kind):
    return [e for e in result.events if e["event"] == kind]


def test_paper_model_is_loaded(world):
    assert len(world.uavs) == 32 and [t.id for t in world.targets] == ["T1", "T3", "T2"]
    assert world.params.delta_max_s == pytest.approx(1.4)
    assert sum(u.munitions for u in world.uavs) == 6 * 2 + 5 * 1 + 11 * 4


def test_all_targets_served_and_T2_first_tender_fails(result):
    assert all(o.t_done_s is not None for o in result.outcomes.values())
    t2 = [
        e for e in result.events if e.get("target") == "T2" and e["event"] in ("formation_failed", "formed")
    ]
    assert t2[0]["event"] == "formation_failed" and t2[-1]["event"] == "formed"


def test_strict_resources(world, result):
    for u, st in zip(world.uavs, result.states):
        assert st.munitions >= 0 and st.strikes <= u.munitions and st.munitions == u.munitions - st.strikes
    by_id = {u.id: u for u in world.uavs}
    for e in _events(result, "award"):
        assert by_id[e["uav"]].strike if e["task"] == "strike" else by_id[e["uav"]].assess
    assert len(_events(result, "strike")) == sum(len(t.strike_angles_rad) for t in world.targets)


def test_synchronised_arrival_error_below_half_a_second(world, result):
    by_id = {u.id: u for u in world.uavs}
    awards = {(e["target"], e["uav"]): e for e in _events(result, "award")}
    strikes = _events(result, "strike")
    assert strikes
    for s in strikes:
        award = awards[(s["target"], s["uav"])]
        leg = result.award_legs[(s["target"], s["uav"])]
        # arrival from the sampled geometry: flown polyline length at the UAV's speed
        flown_s = np.hypot(*np.diff(leg.xy, axis=0).T).sum() / by_id[s["uav"]].speed_mps
        assert abs(leg.t[0] + flown_s - award["time_s"]) < 0.5
        assert np.hypot(*(leg.xy[-1] - award["entry_xy"])) < 1.0
        heading_err = (math.radians(s["heading_deg"] - award["angle_deg"] - 180.0) + math.pi) % (2 * math.pi)
        assert abs(heading_err - math.pi) < math.radians(1.0)
    t1 = {s["t_s"] for s in strikes if s["target"] == "T1"}
    assert max(t1) - min(t1) < 0.5  # simultaneous
    t3 = sorted(s["t_s"] for s in strikes if s["target"] == "T3")
    assert np.allclose(np.diff(t3), 5.0, atol=0.5)  # staggered by the 5 s interval


def test_threat_clearance_on_all_paths(world, result):
    for track in result.tracks:
        _, _, legs = track.history(result.t_end_s)
        for leg in legs:
            for th in world.threats:
                known = leg.t >= th.appear_s
                d = np.hypot(leg.xy[known, 0] - th.x, leg.xy[known, 1] - th.y)
                assert d.size == 0 or d.min() >= th.radius_m, (leg.kind, th)


def test_award_leg_becomes_an_uploadable_vehicle_plan(world, result):
    (tid, uid), leg = next(iter(result.award_legs.items()))
    uav = next(u for u in world.uavs if u.id == uid)
    vp = leg_vehicle_plan(leg, uav, waypoint_dt_s=2.0, t_offset_s=float(leg.t[0]))
    assert vp.sysid == uav.sysid and vp.times_s[0] == pytest.approx(0.0)
    assert np.allclose(vp.waypoints[-1, :2], leg.xy[-1]) and np.all(vp.waypoints[:, 2] == uav.altitude_m)
    assert np.all(np.diff(vp.times_s) <= 2.0 + 1e-6)


def test_plan_round_trip(tmp_path):
    scenario = load_scenario(MISSION)
    scenario.planner["t_end_s"] = 90.0  # T1 and T3 phases only
    plan = plan_scenario(scenario)
    assert plan.planner == "coalition" and len(plan.vehicles) == 32  # feasible: tests/test_safety_checker.py
    assert {"tender", "bid", "award", "strike"} <= {e["event"] for e in plan.events}
    plan.save(tmp_path / "plan.json")
    again = Plan.load(tmp_path / "plan.json")
    assert again.events == plan.events and len(again.vehicles) == 32
    assert [(v.feasible, v.notes) for v in again.vehicles] == [(v.feasible, v.notes) for v in plan.vehicles]


def test_lookalikes_are_the_candidates_starting_near_the_excluded_pose():
    """Within the turn radius and 30 deg of the excluded member's pose: near and same heading yes;
    near but turned, or same heading but far, no; the member itself is never listed."""
    from gcs_planner.planning.coalition.sim import lookalikes

    poses = np.array(
        [
            [1000.0, 1000.0, 0.1],  # the excluded member
            [1100.0, 1050.0, 0.3],  # 112 m, 11 deg: alike
            [1000.0, 1000.0, 0.1 + math.radians(60.0)],  # same place, turned 60 deg
            [1250.0, 1000.0, 0.1],  # 250 m away
            [900.0, 950.0, 0.1 - 2.0 * math.pi + 0.2],  # 112 m, 11 deg across the wrap
        ]
    )
    assert lookalikes(poses, 0, 200.0) == [1, 4]
    assert lookalikes(poses, 0, 300.0) == [1, 3, 4]
    assert lookalikes(poses, 2, 200.0) == []


def test_an_excluded_member_takes_its_lookalikes_off_the_task(world):
    """The paper world with the earlier 10 x 15 colony (seed 3): at T2 the member chosen for the
    60 deg strike cannot clear the threat at (1900, 950) and is excluded with its look-alikes;
    none of them gets that strike, and the formation still covers every task with clear legs."""
    old = replace(world, params=msgspec.structs.replace(world.params, ants=10, iterations=15))
    result = simulate(old, np.random.default_rng(3))
    excluded = [e for e in _events(result, "member_excluded") if e["target"] == "T2"]
    assert excluded and excluded[0]["alike"]
    off = {excluded[0]["uav"], *excluded[0]["alike"]}
    awards = [e for e in _events(result, "award") if e["target"] == "T2"]
    sixty = next(e for e in awards if e["angle_deg"] == 60.0)
    assert sixty["task"] == "strike" and sixty["uav"] not in off
    assert len(awards) == 12 and all(result.award_legs[("T2", e["uav"])].info["clear"] for e in awards)


def test_no_uav_loiters_tighter_than_its_turn_radius():
    """coalition_sitl's loiter radius (120 m) is below U13 / U16's r_min (133 m): they loiter at r_min."""
    world = load_world(load_scenario(MISSION.with_name("coalition_sitl.toml")))
    assert any(u.r_min_m > world.params.loiter_radius_m for u in world.uavs)
    result = simulate(world, np.random.default_rng(3))
    for u, track in zip(world.uavs, result.tracks, strict=True):
        _, _, legs = track.history(result.t_end_s)
        for leg in (leg for leg in legs if leg.kind == "loiter" and leg.t.size > 2):
            turn_rate = np.abs(np.diff(np.unwrap(leg.heading)) / np.diff(leg.t))
            radius = u.speed_mps / np.maximum(turn_rate, 1e-9)
            assert radius.min() >= u.r_min_m * 0.99, (u.id, radius.min(), u.r_min_m)


def test_an_approach_allowance_leaves_each_strike_leg_that_much_longer_than_its_shortest_route(world):
    """approach_s (connected planes: their run-in) is flown on top of each member's shortest route,
    so the strike waits for it; with none, the latest member of a coalition has no slack."""
    spare = {}
    for approach_s in (0.0, 6.0):
        sim = CoalitionSim(world, np.random.default_rng(3))
        sim.approach_s = approach_s
        result = sim.run()
        spare[approach_s] = []
        for (_, uid), leg in result.award_legs.items():
            if leg.kind != "strike":
                continue
            u = next(u for u in world.uavs if u.id == uid)
            known = [th for th in world.threats if th.appear_s <= leg.t[0]]
            q0 = np.array([*leg.xy[0], leg.heading[0]])
            q1 = np.array([*leg.xy[-1], leg.heading[-1]])
            shortest = paths.min_route(q0, q1, u.r_min_m, known, world.params.kappa).length_m
            spare[approach_s].append((leg.t[-1] - leg.t[0]) - shortest / u.speed_mps)
    assert min(spare[0.0]) < 1.0  # some member flies its shortest route
    assert min(spare[6.0]) > 6.0 - 0.5, sorted(spare[6.0])[:3]
