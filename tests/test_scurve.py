"""ArduCopter's S-curve legs (geometry.scurve) against ArduCopter SITL 4.8.0-dev, and the pre-flight
check built on them (flight.limits.check_waypoint_timing)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from sitl_legs import SITL_LEG_S, inner_leg_times_s, zigzag

from gcs_planner.core.errors import UserError
from gcs_planner.flight.limits import check_waypoint_timing, predicted_errors_s
from gcs_planner.geometry.scurve import WaypointNav, fly_legs
from gcs_planner.model.plan import VehiclePlan


@pytest.mark.parametrize(("accel", "jerk", "turn"), list(SITL_LEG_S))
def test_leg_times_match_arducopter_sitl(accel, jerk, turn):
    """The inner legs (20-160 m) take what SITL's took, to 0.2 s: short legs peak low on their own
    ramps (20 m: +2.7 s over L / 10 at stock WP_ACC / WP_JERK), sharp corners wait for the turn."""
    waypoints = zigzag(turn)
    times, positions = fly_legs(waypoints, np.full(len(waypoints), 10.0), WaypointNav(accel, jerk, 4.0, 4.0))
    legs_s = inner_leg_times_s(times, positions, waypoints)
    assert legs_s == pytest.approx(SITL_LEG_S[(accel, jerk, turn)], abs=0.2)
    assert np.linalg.norm(positions[-1] - waypoints[-1]) < 0.05  # it ends at rest on the last one


def test_a_climbing_leg_keeps_the_climb_speed_and_vertical_acceleration():
    """WP_SPD_UP 2.5 over a 30-degree climb: 5 m/s along the leg, 4.3 m/s over ground."""
    waypoints = np.array([[0.0, 0.0, 0.0], [200.0 * math.cos(math.pi / 6), 0.0, 100.0]])
    times, positions = fly_legs(waypoints, np.array([10.0, 10.0]), WaypointNav(2.5, 1.0, 2.5, 1.5))
    vertical = np.gradient(positions[:, 2], times)
    assert vertical.max() == pytest.approx(2.5, abs=0.01)
    assert np.abs(np.gradient(vertical, times)).max() <= 1.0 + 0.05  # WP_ACC_Z


def plan_with_short_legs() -> VehiclePlan:
    """Level at 10 m/s: 160 m, two legs of ~45 m turning 10 degrees, then 250 m (swarm_small's uav4)."""
    waypoints = np.array([[0.0, 0.0, 30.0], [160.0, 0.0, 30.0], [205.0, 7.9, 30.0], [250.0, 15.8, 30.0],
                          [500.0, 15.8, 30.0]])  # fmt: skip
    times = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(waypoints, axis=0), axis=1)) / 10.0])
    return VehiclePlan("uav4", 4, waypoints, times, np.full(5, 10.0), waypoints, times)


def test_a_plan_of_short_legs_is_refused_with_the_ramp_that_would_fly_it():
    vp = plan_with_short_legs()
    stock = WaypointNav(2.5, 1.0, 4.0, 4.0)
    errors = predicted_errors_s(vp, stock)
    late_s = errors.max()
    assert 2.0 < late_s < 4.0 and errors[:15].max() < 0.5  # lost on the ~45 m legs, peaking at ~7.8 m/s
    with pytest.raises(UserError) as refused:
        check_waypoint_timing([vp], {4: stock}, bound_s=late_s - 0.5)
    words = str(refused.value)
    assert "vehicle uav4 (sysid 4): with WP_ACC 2.5 and WP_JERK 1 its short legs never reach" in words
    assert f"over the {late_s - 0.5:g} s bound 2" in words  # 2x s into its route: after the short legs
    assert "WP_ACC 3.5 and WP_JERK 2 predict" in words or "WP_ACC 5 and WP_JERK 3 predict" in words, words
    check_waypoint_timing([vp], {4: stock}, bound_s=late_s + 0.1)  # within the bound: flown
    check_waypoint_timing([vp], {4: WaypointNav(5.0, 5.0, 4.0, 4.0)}, bound_s=late_s - 0.5)
    check_waypoint_timing([vp], {}, bound_s=0.0)  # a vehicle that does not fly S-curve legs
