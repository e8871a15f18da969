"""The client's L1 predictor (gcs_planner.flight.l1_guidance) and the mock's own L1 law (sitl_mock.l1) are
two implementations of ArduPlane's AP_L1_Control::update_waypoint: on many random planes, legs and
winds they must demand the same turn, so a wrong model on either side fails here."""

from __future__ import annotations

import numpy as np
import pytest

from gcs_planner.flight.l1_guidance import l1_turn_rate
from sitl_mock.l1 import l1_lateral_accel

NE = np.array([1, 0])  # ENU (x east, y north) -> NE


def states(n: int, seed: int):
    rng = np.random.default_rng(seed)
    a = rng.uniform(-500, 500, (n, 3))
    b = a + rng.normal(0, 300, (n, 3)) * rng.choice([1.0, 1.0, 1.0, 1e-9], (n, 1))  # some legs of length ~0
    pos = rng.uniform(-800, 800, (n, 3))
    ground = rng.normal(0, 15, (n, 2)) + rng.choice([-1, 1], (n, 2)) * 12.0
    period = rng.uniform(8.0, 25.0, n)
    return pos, a, b, ground, period


@pytest.mark.parametrize("seed", range(5))
def test_the_client_and_the_mock_demand_the_same_turn(seed):
    pos, a, b, ground, period = states(20_000, seed)
    client = l1_turn_rate(pos, a, b, ground, period)  # rad/s, counter-clockwise
    lateral = l1_lateral_accel(pos[:, NE], a[:, NE], b[:, NE], ground[:, NE], period)  # m/s^2, + right
    mock = -lateral / np.maximum(np.hypot(ground[:, 0], ground[:, 1]), 0.1)
    np.testing.assert_allclose(client, mock, rtol=1e-9, atol=1e-9)
    assert np.ptp(mock) > 1.0  # the states cover turns both ways, not a trivial agreement


def test_the_cross_check_fails_when_one_side_is_wrong():
    pos, a, b, ground, period = states(2_000, 9)
    client = l1_turn_rate(pos, a, b, ground, period * 1.05)  # a 5 % period error on one side
    lateral = l1_lateral_accel(pos[:, NE], a[:, NE], b[:, NE], ground[:, NE], period)
    mock = -lateral / np.maximum(np.hypot(ground[:, 0], ground[:, 1]), 0.1)
    assert not np.allclose(client, mock, rtol=1e-9, atol=1e-9)
