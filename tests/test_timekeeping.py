import numpy as np
import pytest

from gcs_planner.flight.timekeeping import ScheduleKeeper
from gcs_planner.model.plan import VehiclePlan


def _route(speed=10.0):
    path = np.array([[0.0, 0.0, 20.0], [100.0, 0.0, 20.0], [100.0, 100.0, 20.0]])
    times = np.array([0.0, 10.0, 20.0]) * 10.0 / speed
    return VehiclePlan("uav1", 1, path, times, [speed] * 3, path, times)


def test_along_track_error_projects_onto_legs_and_signs_behind_positive():
    keeper = ScheduleKeeper()
    keeper.add(_route())
    assert keeper.along_track_error_m(1, 5.0, np.array([50.0, 3.0, 20.0])) == pytest.approx(0.0)
    assert keeper.along_track_error_m(1, 6.0, np.array([50.0, 0.0, 20.0])) == pytest.approx(10.0)
    # on the second leg, 30 m along it at t = 12 s (planned 20 m): 10 m ahead
    assert keeper.along_track_error_m(1, 12.0, np.array([100.0, 30.0, 20.0])) == pytest.approx(-10.0)


def test_speed_command_corrects_lag_within_limits_and_respects_deadband():
    keeper = ScheduleKeeper(horizon_s=2.0, min_factor=0.5, max_factor=1.3, deadband_mps=0.2)
    keeper.add(_route(speed=10.0))
    assert keeper.speed_command(1, 1.0, np.array([9.0, 0.0, 20.0])) == pytest.approx(10.5)
    assert keeper.speed_command(1, 1.05, np.array([9.5, 0.0, 20.0])) is None  # within the deadband
    assert keeper.speed_command(1, 5.0, np.array([20.0, 0.0, 20.0])) == pytest.approx(13.0)  # capped
    assert keeper.speed_command(1, 5.0, np.array([90.0, 0.0, 20.0])) == pytest.approx(5.0)  # floored


def test_progress_never_jumps_back_to_an_earlier_crossing():
    path = np.array(
        [[0.0, 0.0, 20.0], [100.0, 0.0, 20.0], [100.0, 50.0, 20.0], [50.0, 50.0, 20.0], [50.0, -50.0, 20.0]]
    )
    times = np.arange(5) * 10.0
    keeper = ScheduleKeeper()
    keeper.add(VehiclePlan("u", 1, path, times, [10.0] * 5, path, times))
    keeper.along_track_error_m(1, 30.0, np.array([50.0, 50.0, 20.0]))
    # (50, 0) lies on the first leg and on the last one; progress must stay on the last
    assert keeper.along_track_error_m(1, 35.0, np.array([50.0, 0.0, 20.0])) == pytest.approx(0.0)


def test_no_command_while_the_start_ramp_lasts():
    """A route started early by its ramp's loss is ahead of the plan on its ramp by design: the
    keeper leaves it alone until ``settle_s`` after the planned start, then corrects as usual."""
    keeper = ScheduleKeeper(horizon_s=2.0)
    keeper.add(_route(speed=10.0), settle_s=3.0)
    assert keeper.speed_command(1, -1.0, np.array([5.0, 0.0, 20.0])) is None  # 5 m ahead, before the start
    assert keeper.speed_command(1, 2.9, np.array([20.0, 0.0, 20.0])) is None  # 9 m behind, still on its ramp
    assert keeper.speed_command(1, 3.1, np.array([27.0, 0.0, 20.0])) == pytest.approx(12.0)  # 4 m behind


def test_an_error_is_removed_over_the_vehicles_response_where_that_is_longer():
    """A copter that takes 4 s to reach a new speed (ArduCopter's S-curve re-plan) is asked for half
    the correction a 2 s horizon gives, so that it is not asked again before it has answered."""
    keeper = ScheduleKeeper(horizon_s=2.0)
    keeper.add(_route(speed=10.0), response_s=4.0)
    assert keeper.speed_command(1, 1.0, np.array([6.0, 0.0, 20.0])) == pytest.approx(11.0)  # 4 m behind
    quick = ScheduleKeeper(horizon_s=2.0)
    quick.add(_route(speed=10.0), response_s=1.0)  # faster than the horizon: the horizon stands
    assert quick.speed_command(1, 1.0, np.array([6.0, 0.0, 20.0])) == pytest.approx(12.0)
