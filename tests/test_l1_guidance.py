"""The L1 flight predictor against the mock's L1 plane, and waypoints shaped with it."""

import itertools
import math
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from gcs_planner.flight.coalition.live_legs import timed_leg
from gcs_planner.flight.l1_guidance import (
    ARDUPLANE_SITL,
    G_MPS2,
    SHAPE_AFTER_S,
    L1Response,
    TurnGain,
    predict_flight,
    shape_for_l1,
    shape_waypoints,
)
from gcs_planner.model.plan import VehiclePlan
from sitl_mock.flight import AIRFRAMES, Arrival, Guidance, Kinematics
from sitl_mock.l1 import L1Plane

DT = 0.05
SPEED = 20.0
BANK = math.radians(45.0)
R = 100.0


def _goal_leg(run_in_m: float):
    """A plane flying east at the origin turns left through 180 deg at R and flies run_in_m west
    into the goal pose (heading west), then 40 m on: (dense path, waypoints as a mission places
    them: every 30 deg of turn, every 10 m on the last 30 m before the goal and 20 m after it)."""
    th = np.linspace(0.0, math.pi, 181)
    arc = np.column_stack([R * np.sin(th), R - R * np.cos(th)])
    line = np.column_stack([np.arange(-1.0, -run_in_m - 41.0, -1.0), np.full(int(run_in_m) + 40, 2 * R)])
    path = np.vstack([arc, line])
    s = np.r_[0.0, np.cumsum(np.hypot(*np.diff(path, axis=0).T))]
    s_goal = math.pi * R + run_in_m
    near_goal = s_goal + np.array([-30.0, -20.0, -10.0, 0.0, 10.0, 20.0, 40.0])
    at = np.r_[np.arange(1, 6) * math.pi * R / 6, near_goal]
    wps = np.column_stack([np.interp(at, s, path[:, 0]), np.interp(at, s, path[:, 1])])
    return path, wps, np.array([-run_in_m, 2 * R])


def _mock_flight(waypoints: np.ndarray, response: L1Response, each_step=lambda kin: None) -> np.ndarray:
    """The mock's L1 plane (sitl_mock.flight.Kinematics) flying the waypoints from the origin,
    heading east, each accepted within 15 m or once passed: its positions every DT."""
    plane = L1Plane(response.period_s, response.turn_gain, response.roll_tau_s)  # the mock's own law
    kin = Kinematics([replace(AIRFRAMES["fixed_wing"], l1=plane, max_bank_rad=BANK)], np.zeros((1, 3)))
    kin.pos[0], kin.psi[0], kin.speed_cmd[0] = [0.0, 0.0, 50.0], 0.0, SPEED
    track = [kin.pos[0, :2].copy()]
    for wp in waypoints:
        kin.command(0, Guidance.PASS, np.array([*wp, 50.0]), Arrival.RADIUS_2D, accept_radius_m=15.0)
        while not kin.arrived()[0]:
            kin.step(DT)
            each_step(kin)
            track.append(kin.pos[0, :2].copy())
    return np.array(track)


def _at_goal(track: np.ndarray, goal: np.ndarray, heading_rad: float = math.pi) -> tuple[float, float]:
    """Miss distance [m] and heading error [deg] (against heading_rad, default west) where the
    track passes the goal."""
    k = int(np.argmin(np.hypot(*(track - goal).T)))
    step = track[k + 1] - track[k - 1]
    error = math.remainder(math.atan2(step[1], step[0]) - heading_rad, 2 * math.pi)
    return float(np.hypot(*(track[k] - goal))), abs(math.degrees(error))


@pytest.mark.parametrize("response", [L1Response(15.0), ARDUPLANE_SITL], ids=["l1", "sitl-plane"])
def test_the_predicted_flight_is_the_mock_l1_planes_flight(response):
    """Two integrations of ArduPlane's waypoint following (Plane::verify_nav_wp's acceptance
    radius and finish line, the previous waypoint as the line's start): the predictor's and the
    mock fleet's kinematics agree to within a metre over a turn onto a line."""
    path, wps, _ = _goal_leg(60.0)
    mock = _mock_flight(wps, response)
    predicted, reached = predict_flight((0.0, 0.0, 0.0), SPEED, wps, response, 15.0, BANK, dt_s=DT)
    assert (reached >= 0).all() and np.all(np.diff(reached) > 0)
    n = min(len(mock), len(predicted))
    assert np.hypot(*(mock[:n] - predicted[:n, :2]).T).max() < 1.0
    assert abs(len(mock) - len(predicted)) <= 2


@pytest.mark.parametrize("run_in_m", [0.0, 60.0])
def test_shaped_waypoints_bring_an_l1_plane_onto_its_goal_pose_after_a_turn(run_in_m):
    """ArduPlane SITL's plane flies a turn wide and is still converging on the line at a goal
    shortly after it; the waypoints moved by shape_waypoints bring the mock's plane with its
    response (flown apart from the predictor) through the goal on its heading."""
    path, wps, goal = _goal_leg(run_in_m)
    miss, dh = _at_goal(_mock_flight(wps, ARDUPLANE_SITL), goal)
    assert dh > 5.0 or miss > 8.0, (miss, dh)  # the plain waypoints: off the goal pose
    shaped = shape_waypoints((0.0, 0.0, 0.0), SPEED, wps, path, ARDUPLANE_SITL, 15.0, BANK)
    miss_s, dh_s = _at_goal(_mock_flight(shaped, ARDUPLANE_SITL), goal)
    assert miss_s < 3.0 and dh_s < 2.0 and dh_s < dh / 3, (miss_s, dh_s, miss, dh)
    assert np.hypot(*(shaped - wps).T).max() < 60.0  # moved across the path, not elsewhere


def test_a_shaped_mission_keeps_its_items_times_and_first_waypoints():
    """Shaping moves waypoints across the path, nothing else, and none that the plane flies to
    before or just after it starts the mission (its line then starts at the last mission's
    waypoint, which the prediction does not know)."""
    path, wps, _ = _goal_leg(60.0)
    wps = np.vstack([[0.0, 0.0], wps])
    path_t = np.r_[0.0, np.cumsum(np.hypot(*np.diff(path, axis=0).T))] / SPEED
    times = path_t[np.argmin(np.hypot(*(wps[:, None, :] - path[None, :, :]).transpose(2, 0, 1)), axis=1)]
    up = np.full((len(wps), 1), 50.0)
    vp = VehiclePlan("U1", 1, np.hstack([wps, up]), times, np.full(len(wps), SPEED),
                     np.column_stack([path, np.full(len(path), 50.0)]), path_t, "fixed_wing", turn_radius_m=R,
                     acceptance_radius_m=15.0)  # fmt: skip
    from_s = 2.0
    shaped = shape_for_l1(vp, ARDUPLANE_SITL, BANK, from_s)
    assert shaped.waypoints.shape == vp.waypoints.shape
    kept = vp.times_s <= from_s + SHAPE_AFTER_S
    assert 1 < kept.sum() < len(kept)
    np.testing.assert_array_equal(shaped.waypoints[kept], vp.waypoints[kept])
    np.testing.assert_array_equal(shaped.waypoints[:, 2], vp.waypoints[:, 2])
    np.testing.assert_array_equal(shaped.times_s, vp.times_s)
    np.testing.assert_array_equal(shaped.path, vp.path)
    assert np.hypot(*(shaped.waypoints - vp.waypoints)[:, :2].T).max() > 1.0


@pytest.mark.parametrize("gain", [0.75, 1.0])
@pytest.mark.parametrize("side", [1.0, -1.0], ids=["right", "left"])
def test_the_turn_gain_is_learnt_from_bank_and_course_reports(gain, side):
    """A plane banked 30 deg at 20 m/s turning at gain x the coordinated rate (clockwise for a
    right bank): the estimate is that gain once 3 s of the turn were seen; straight flight tells
    nothing."""
    estimate = TurnGain()
    roll = side * math.radians(30.0)
    rate = -side * gain * G_MPS2 * math.tan(abs(roll)) / SPEED
    for k in range(100):  # straight: no bank, no gain
        estimate.velocity(0.1 * k, SPEED, 0.0)
    assert estimate.value is None
    estimate.attitude(roll)
    for k in range(100, 160):
        course = rate * 0.1 * (k - 100)
        estimate.velocity(0.1 * k, SPEED * math.cos(course), SPEED * math.sin(course))
    assert estimate.value == pytest.approx(gain, rel=0.02)


def test_the_mock_sitl_plane_reports_the_bank_that_turns_it_at_its_gain():
    """The mock's stand-in for ArduPlane SITL's plane banks more than a coordinated turn needs
    (SITL: 33.3 deg for 12.9 deg/s at 21.4 m/s): the gain learnt from its reports is its own."""
    estimate, steps = TurnGain(), itertools.count(1)

    def report(kin: Kinematics) -> None:
        estimate.attitude(float(kin.roll[0]))
        estimate.velocity(DT * next(steps), *kin.vel[0, :2])

    _mock_flight(_goal_leg(60.0)[1][:5], ARDUPLANE_SITL, report)  # the arc
    assert estimate.value == pytest.approx(ARDUPLANE_SITL.turn_gain, abs=0.02)


def test_shaping_random_legs_never_loops_and_never_makes_the_goal_worse():
    """Shaped or not, a leg's predicted flight must not loop (a shaping iterate once circled a
    waypoint); shaping keeps the goal pose at least as well as the plain waypoints: 12 seeded
    legs from a loiter-like start to a goal 400-1200 m away, turns at R, a 60 m run-in."""
    rng = np.random.default_rng(7)
    world = SimpleNamespace(params=SimpleNamespace(kappa=1.3, sample_ds_m=4.0))
    uav = SimpleNamespace(r_min_m=R, speed_mps=SPEED)
    for _ in range(12):
        q0 = np.array([0.0, 0.0, rng.uniform(-math.pi, math.pi)])
        bearing, dist = rng.uniform(0, 2 * math.pi), rng.uniform(400.0, 1200.0)
        goal = np.array([dist * math.cos(bearing), dist * math.sin(bearing), rng.uniform(-math.pi, math.pi)])
        leg = timed_leg(world, uav, q0, 0.0, goal, 0.0, [], "strike", 1.0, 60.0)
        on = goal[:2] + np.outer([10.0, 20.0, 30.0, 40.0], [math.cos(goal[2]), math.sin(goal[2])])
        path = np.vstack([leg.xy, on])
        s = np.r_[0.0, np.cumsum(np.hypot(*np.diff(path, axis=0).T))]
        at = np.r_[np.arange(45.0, s[-5] - 30.0, 45.0), s[-5] + np.arange(-30.0, 41.0, 10.0)]
        wps = np.column_stack([np.interp(at, s, path[:, 0]), np.interp(at, s, path[:, 1])])
        shaped = shape_waypoints(q0, SPEED, wps, path, ARDUPLANE_SITL, 15.0, BANK)
        errors = []
        for w in (wps, shaped):
            flown, reached = predict_flight(q0, SPEED, w, ARDUPLANE_SITL, 15.0, BANK)
            assert (reached >= 0).all()
            assert np.hypot(*np.diff(flown[:, :2], axis=0).T).sum() < 1.3 * s[-1] + 30.0  # no loop
            errors.append(_at_goal(flown[:, :2], goal[:2], goal[2]))
        (miss, dh), (miss_s, dh_s) = errors
        assert miss_s <= max(miss, 3.0) and dh_s <= max(dh, 3.0), (miss, dh, miss_s, dh_s)
