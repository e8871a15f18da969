"""Coalition HIL: awards flown on legs planned from live telemetry, uploaded over real UDP to flying mock
fixed wings; strike and assessment arrival time and angle against the award."""

import asyncio
import math
from pathlib import Path

import numpy as np

from gcs_planner.core import lockstep
from gcs_planner.core.geo import enu_to_geodetic
from gcs_planner.flight.coalition import (
    HilOptions,
    live_state,
    measure_task,
    plan_live_leg,
    run_coalition_hil,
)
from gcs_planner.planning import load_scenario
from gcs_planner.planning.coalition import load_world, paths
from gcs_planner.telemetry import read_flight
from sitl_mock.plan_fleet import MockVehiclesProcess

SCENARIO = Path(__file__).resolve().parents[1] / "missions" / "coalition_paper.toml"


def test_measure_task_interpolates_closest_approach_and_heading():
    t = np.arange(0.0, 20.0, 0.5)
    heading = np.radians(200.0)
    xy = np.column_stack([np.cos(heading), np.sin(heading)]) * (50.0 * (t - 10.3))[:, None]
    award = {"uav": "U1", "sysid": 1, "target": "T1", "task": "strike", "time_s": 10.0, "angle_deg": 20.0,
             "entry_xy": [0, 0]}  # fmt: skip
    row = measure_task(t, xy + [0.0, 3.0], award, (1.0, 10.0))
    assert abs(row.flown_s - 10.3) < 0.1 and abs(row.time_error_s - 0.3) < 0.1
    assert abs(row.angle_error_deg) < 1e-6 and row.passed
    late = measure_task(t + 1.5, xy, award, (1.0, 10.0))
    assert not late.passed and abs(late.time_error_s - 1.8) < 1e-6


def test_measure_task_checks_the_assessment_arc_start_and_radius():
    world = load_world(load_scenario(SCENARIO))
    target = next(tg for tg in world.targets if tg.id == "T1")
    radius, speed = world.params.assess_radius_m, 40.0
    t = np.arange(80.0, 130.0, 0.5)
    bearing = math.radians(90.0) + speed * (t - 100.0) / radius  # CCW, at bearing 90 deg at t = 100 s
    award = {"uav": "U2", "sysid": 2, "target": "T1", "task": "assess", "time_s": 100.0, "angle_deg": 90.0}
    for wobble_m, ok in ((5.0, True), (80.0, False)):
        r = radius + wobble_m * np.sin(t)
        xy = np.asarray(target.xy) + np.column_stack([np.cos(bearing), np.sin(bearing)]) * r[:, None]
        row = measure_task(t, xy, award, (1.0, 10.0), world)
        assert wobble_m - 1.0 <= row.arc_dev_m <= wobble_m + 1.0 and row.passed is ok, row
    assert abs(row.time_error_s) < 0.5  # the arc start is still found (a wide wobble shifts it a little)


def test_live_state_fits_the_turn_and_predicts_the_pose_ahead():
    world = load_world(load_scenario(SCENARIO))
    origin = load_scenario(SCENARIO).origin
    speed, radius = 40.0, 300.0
    t = np.arange(0.0, 3.0, 0.1)
    th = speed * t / radius  # CCW circle about (1000, 2000), heading = th + 90 deg
    x, y = 1000.0 + radius * np.cos(th), 2000.0 + radius * np.sin(th)
    lat, lon, _ = enu_to_geodetic(x, y, 0.0, origin)
    rows = list(zip(t, lat, lon, -speed * np.sin(th), speed * np.cos(th)))
    state = live_state(rows, origin, max_rate_rps=1.0)
    assert abs(state.rate_rps - speed / radius) < 1e-3 and abs(state.speed_mps - speed) < 0.05
    ahead = state.predict([t[-1] + 5.0])[0]
    th5 = speed * (t[-1] + 5.0) / radius
    assert np.hypot(ahead[0] - 1000.0 - radius * np.cos(th5), ahead[1] - 2000.0 - radius * np.sin(th5)) < 1.0
    # a leg from there reaches the award's stand-off entry pose at the awarded time and angle; from
    # too far away it is planned faster (up to the factor given) and still arrives on time
    award = {"uav": "U8", "target": "T1", "task": "strike", "t_s": 60.0, "time_s": 100.0, "angle_deg": 15.0}
    target = np.asarray(next(tg for tg in world.targets if tg.id == "T1").xy)
    entry = target + world.params.standoff_m * np.array(
        [math.cos(math.radians(15.0)), math.sin(math.radians(15.0))]
    )
    for q0, factor, fast in (
        ((target[0] - 1500.0, target[1], ahead[2]), 1.0, False),
        ((target[0] - 4300.0, target[1], math.pi), 1.2, True),
    ):
        leg = plan_live_leg(world, award, np.asarray(q0), 10.0, factor)
        assert abs(leg.t[0] - 10.0) < 1e-9 and abs(leg.t[-1] - 100.0) < 1e-6 and leg.info["clear"], leg.info
        assert (
            np.hypot(*(leg.xy[-1] - entry)) < 1.0 and abs(math.degrees(leg.heading[-1]) % 360 - 195.0) < 0.5
        )
        assert (leg.info["speed_mps"] > 50.0) is fast and np.allclose(leg.xy[0], q0[:2])


def test_upload_end_is_stamped_at_the_first_report_after_the_upload():
    """The run's clock only moves when a position report arrives. An upload that starts and ends
    between two reports gets the next report's time as its end, so start < end by construction
    (96d891a had loosened the HIL test's order to <= after an upload fell within one report)."""
    from gcs_planner.flight.coalition.run import next_report_after

    reads = iter([12.3, 12.3, 12.3, 12.3, 12.4, 12.5])
    calls = []

    def clock() -> float:
        calls.append(1)
        return next(reads)

    start = clock()
    assert asyncio.run(next_report_after(clock, clock())) == 12.4 > start
    assert len(calls) == 5  # polled until the clock moved, not a fixed wait
    frozen = asyncio.run(next_report_after(lambda: 7.0, 7.0, timeout_s=0.05))
    assert frozen == 7.0  # no report at all: gives up after the timeout


def test_a_mission_starts_at_the_first_waypoint_that_is_ahead_in_time_and_in_front_of_the_plane():
    """A mission uploaded late starts at a waypoint still ahead by its planned time; one the plane
    has just flown past (behind it and near) is skipped: ArduPlane started towards a waypoint
    behind it turns back for it (Plane::set_next_WP), and a mock SITL plane circled one. A plane
    far off the path still starts at the due one (the replayed simulation legs)."""
    from gcs_planner.core.geo import Origin
    from gcs_planner.flight.coalition.run import _first_ahead
    from gcs_planner.missions.items import plan_to_items
    from gcs_planner.model.plan import VehiclePlan

    xs = np.arange(6) * 100.0  # east at 20 m/s: a waypoint every 5 s
    wps = np.column_stack([xs, np.zeros(6), np.full(6, 100.0)])
    vp = VehiclePlan("U1", 1, wps, xs / 20.0, np.full(6, 20.0), wps, xs / 20.0, "fixed_wing",
                     turn_radius_m=100.0, final_action="loiter", acceptance_radius_m=15.0)  # fmt: skip
    items = plan_to_items(vp, Origin(31.5, 105.0, 500.0), "ardupilot")
    takeoff = next(it.seq for it in items if it.command == 22)  # stands for waypoint 0
    seq_of = [takeoff] + [it.seq for it in items if it.command == 16 and it.seq > takeoff]
    on_time = _first_ahead(items, vp, 6.0, 1.0)  # the waypoint at 200 m is due at 10 s
    ahead_of_schedule = _first_ahead(items, vp, 6.0, 1.0, (230.0, 0.0, 0.0))  # the plane is at 230 m
    far_off = _first_ahead(items, vp, 6.0, 1.0, (250.0, -400.0, 0.0))  # 400 m off the path: due one
    assert (on_time, ahead_of_schedule, far_off) == (seq_of[2], seq_of[3], seq_of[2])


def test_t1_awards_are_flown_from_live_state_and_arrive_on_time_and_angle(tmp_path):
    """In lockstep (gcs_planner.core.lockstep): the same flight however busy the machine."""
    scenario = load_scenario(SCENARIO)
    options = HilOptions(out_dir=tmp_path, targets=("T1",))
    result = lockstep.run(run_coalition_hil(scenario, options, MockVehiclesProcess), True)
    assert not result.failures, result.failures
    # the 8 strikes of T1's simultaneous attack, each within 1 s and 10 deg of its award
    assert len(result.strikes) == 8 and len({r.awarded_s for r in result.strikes}) == 1
    for r in result.strikes:
        assert abs(r.time_error_s) <= 1.0 and abs(r.angle_error_deg) <= 10.0, r
        assert r.miss_m < 15.0, r
    # the 2 assessors reach their arc start on time, tangent, and fly the arc
    assess = [r for r in result.rows if r.task == "assess"]
    assert len(assess) == 2 and all(r.passed and r.arc_dev_m < 50.0 for r in assess), assess
    assert result.passed
    # every award became a mission planned from telemetry and uploaded while flying, after its award
    # time, landing before its leg starts (or at most 1 s after: the estimate is a measured average)
    awards = [u for u in result.uploads if u["kind"] == "award"]
    assert len(awards) == 10 and all(u["ok"] for u in result.uploads)
    strike_s = result.strikes[0].awarded_s
    for u in awards:
        # scenario time advances with position reports (~0.1 s apart); an upload's end is the first
        # report after it, so the order is strict even for an upload that fits between two reports
        assert u["award_t_s"] <= u["upload_start_s"] < u["upload_end_s"] < u["t0_s"] + 1.0, u
        assert u["t0_s"] < strike_s - 10.0, u
        assert u["prediction_error_m"] < 60.0, u  # predicted vs flown pose at the leg start
        t, p = result.tracks[u["sysid"]]
        k = np.searchsorted(t, u["upload_end_s"])
        assert p[k, 2] > 250.0  # airborne at the upload (cruise altitudes 300-500 m)
    flight = read_flight(result.mcap_path)
    kinds = [e.get("event") for _, e in flight.events]
    assert {"tender", "bid", "award", "upload", "route_start"} <= set(kinds)
    in_flight = [e for _, e in flight.events if e.get("event") == "upload" and e["kind"] != "first"]
    first = [e for _, e in flight.events if e.get("event") == "upload" and e["kind"] == "first"]
    assert kinds.count("award") == 10 and len(in_flight) == len(result.uploads)
    assert len(first) == len(result.tracks) and all(e["ok"] for e in first)  # one first mission each


def test_a_vehicle_away_from_its_simulated_state_still_strikes_because_its_leg_is_planned_live(tmp_path):
    """U13 flies its pre-award loiter 424 m from the simulated one: the simulation's own leg (replay)
    misses by far, the leg planned from its telemetry hits on time and angle."""
    scenario = load_scenario(SCENARIO)
    runs = {}
    for replay in (False, True):
        options = HilOptions(out_dir=tmp_path / str(replay), targets=("T1",), uavs=("U13",),
                             offset_m={"U13": (300.0, -300.0)}, replay_legs=replay)  # fmt: skip
        runs[replay] = lockstep.run(run_coalition_hil(scenario, options, MockVehiclesProcess), True)
    live, replayed = runs[False], runs[True]
    assert not live.failures and not replayed.failures, (live.failures, replayed.failures)
    (row,) = live.strikes
    assert row.start_diff_m > 350.0, row  # the live start pose is far from the simulated one
    assert row.passed and row.miss_m < 15.0, row
    (bad,) = replayed.strikes
    assert not bad.passed, bad


def test_fly_coalition_command_refuses_a_scenario_without_the_coalition_planner(capsys):
    from gcs_planner.cli import main

    assert main(["fly-coalition", str(SCENARIO.parent / "straight_4uav.toml")]) == 2
    assert "[planner] name must be 'coalition'" in capsys.readouterr().err


def test_a_connected_vehicles_leg_ends_with_a_straight_run_in_when_it_can_still_arrive_on_time():
    """ArduPlane's L1 controller lags a turn that ends at the goal pose (a SITL strike came in 23.5
    deg off after an S-bend in its last 6 s): a connected vehicle's leg ends with RUN_IN_S straight
    into the goal pose; a leg the run-in would make late goes without it."""
    from gcs_planner.flight.coalition.live_legs import RUN_IN_S

    world = load_world(load_scenario(SCENARIO))
    award = {"uav": "U8", "target": "T1", "task": "strike", "t_s": 60.0, "time_s": 100.0, "angle_deg": 15.0}
    uav = next(u for u in world.uavs if u.id == "U8")
    target = np.asarray(next(tg for tg in world.targets if tg.id == "T1").xy)
    goal_heading = math.radians(195.0)
    q0 = np.array([target[0] + 900.0, target[1] - 900.0, math.radians(90.0)])  # off to the side

    def final_turn_deg(leg) -> float:
        to_end = np.r_[np.cumsum(np.hypot(*np.diff(leg.xy[::-1], axis=0).T))[::-1], 0.0]  # along the leg
        near = to_end <= RUN_IN_S * uav.speed_mps - 1.0
        return float(np.degrees(np.ptp(np.unwrap(leg.heading[near]))))

    plain = plan_live_leg(world, award, q0, 10.0, 1.2)
    assert final_turn_deg(plain) > 5.0  # without a run-in the leg turns into the goal pose
    leg = plan_live_leg(world, award, q0, 10.0, 1.2, run_in_s=RUN_IN_S)
    assert leg.info["run_in_s"] == RUN_IN_S and leg.info["clear"] and abs(leg.info["late_s"]) < 0.05
    assert final_turn_deg(leg) < 0.1
    assert abs(math.remainder(leg.heading[-1] - goal_heading, 2 * math.pi)) < 1e-6
    assert np.hypot(*(leg.xy[-1] - plain.xy[-1])) < 1e-6 and abs(leg.t[-1] - plain.t[-1]) < 1e-6
    goal = np.r_[plain.xy[-1], goal_heading]
    shortest = paths.min_route(q0, goal, uav.r_min_m, [], world.params.kappa, world.params.sample_ds_m)
    tight = {**award, "time_s": 10.0 + shortest.length_m / (1.2 * uav.speed_mps) + 0.01}  # just on time
    late_with = plan_live_leg(world, tight, q0, 10.0, 1.2, run_in_s=RUN_IN_S)
    late_without = plan_live_leg(world, tight, q0, 10.0, 1.2)
    assert late_without.info["late_s"] < 0.05 and late_with.info["run_in_s"] == 0.0
    assert np.array_equal(late_with.xy, late_without.xy)


def test_a_connected_planes_leg_turns_wider_when_it_still_arrives_on_time():
    """ArduPlane SITL overshot its turn onto the run-in line by 25-37 m on r_min arcs: a connected
    plane's leg turns at TURN_FACTOR x r_min while that still arrives on time, else at r_min."""
    from gcs_planner.flight.coalition.live_legs import RUN_IN_S, TURN_FACTOR

    world = load_world(load_scenario(SCENARIO))
    award = {"uav": "U8", "target": "T1", "task": "strike", "t_s": 60.0, "time_s": 100.0, "angle_deg": 15.0}
    uav = next(u for u in world.uavs if u.id == "U8")
    target = np.asarray(next(tg for tg in world.targets if tg.id == "T1").xy)
    q0 = np.array([target[0] + 900.0, target[1] - 900.0, math.radians(90.0)])

    def tightest_radius(leg) -> float:
        ds = np.hypot(*np.diff(leg.xy, axis=0).T)
        rate = np.abs(np.diff(np.unwrap(leg.heading))) / np.maximum(ds, 1e-9)
        return float(1.0 / rate[ds > 1e-6].max())

    wide = plan_live_leg(world, award, q0, 10.0, 1.2, run_in_s=RUN_IN_S, turn_factor=TURN_FACTOR)
    assert wide.info["turn_factor"] == TURN_FACTOR and abs(wide.info["late_s"]) < 0.05, wide.info
    assert tightest_radius(wide) >= 0.99 * TURN_FACTOR * uav.r_min_m
    goal = np.r_[wide.xy[-1], wide.heading[-1]]
    shortest = paths.min_route(q0, goal, uav.r_min_m, [], world.params.kappa, world.params.sample_ds_m)
    tight = {**award, "time_s": 10.0 + shortest.length_m / (1.2 * uav.speed_mps) + 0.01}
    late = plan_live_leg(world, tight, q0, 10.0, 1.2, run_in_s=RUN_IN_S, turn_factor=TURN_FACTOR)
    assert late.info["turn_factor"] == 1.0 and late.info["late_s"] < 0.05
    assert tightest_radius(late) < TURN_FACTOR * uav.r_min_m  # no time to turn wider
