"""The speed-ramp model behind the route lead and the final stop: checked against a vehicle
braked step by step at the jerk and acceleration limits, and against constant deceleration's
closed form."""

import math

import numpy as np
import pytest

from gcs_planner.geometry.ramp import ramp_loss_s, stop_lag_s


def _braked(speed: float, accel: float, jerk: float, dt: float = 1e-4) -> tuple[np.ndarray, np.ndarray]:
    """(time, distance to go) of a vehicle braking from ``speed`` to rest, stepped at ``dt``: the
    deceleration grows at ``jerk`` to ``accel`` and shrinks again as late as still stops it at 0."""
    v, a, t, x = speed, 0.0, 0.0, 0.0
    times, xs = [0.0], [0.0]
    while v > 1e-9:
        # start easing off once the speed left equals what easing off from ``a`` sheds (a^2 / 2j)
        a = max(a - jerk * dt, 0.0) if v <= a * a / (2.0 * jerk) else min(a + jerk * dt, accel)
        a = max(a, 1e-6)
        v_new = max(v - a * dt, 0.0)
        x += (v + v_new) / 2.0 * dt
        v, t = v_new, t + dt
        times.append(t)
        xs.append(x)
    xs = np.array(xs)
    return np.array(times), xs[-1] - xs


@pytest.mark.parametrize(("speed", "accel", "jerk"), [(10.0, 3.0, 4.0), (10.0, 2.5, 1.0), (4.0, 5.0, 2.0)])
def test_the_stop_lag_matches_a_vehicle_braked_step_by_step(speed, accel, jerk):
    times, to_go = _braked(speed, accel, jerk)
    # the constant-speed vehicle passes a point to_go before the end at (T_end - to_go / speed); it
    # reached the braking start (to_go[0]) when the braking one did
    on_time = to_go[0] / speed - to_go / speed
    lag = times - on_time
    model = stop_lag_s(to_go, speed, accel, jerk)
    assert np.max(np.abs(model - lag)) < 0.02
    assert model[-1] == pytest.approx(ramp_loss_s(speed, accel, jerk), abs=1e-6)
    assert lag[-1] == pytest.approx(ramp_loss_s(speed, accel, jerk), abs=0.02)


def test_constant_deceleration_has_its_closed_form_and_no_lag_before_braking():
    v, a = 10.0, 3.0
    s = np.array([0.0, 1.0, 5.0, 12.0, v * v / (2 * a), 40.0])
    closed = np.where(s < v * v / (2 * a), v / (2 * a) - (np.sqrt(2 * s / a) - s / v), 0.0)
    np.testing.assert_allclose(stop_lag_s(s, v, a), closed, atol=2e-3)
    assert ramp_loss_s(v, a, math.inf) == pytest.approx(v / (2 * a))
