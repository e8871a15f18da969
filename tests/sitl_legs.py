"""ArduCopter SITL's leg times (4.8.0-dev 64a9c787, 2026-12-06; docs/real-autopilots.md): one copter
at 10 m/s from the hover through LEGS_M, headings alternating by the turn. Both S-curve models are
checked against them: the client's (tests/test_scurve.py) and the mock's (tests/test_sitl_scurve.py)."""

from __future__ import annotations

import math

import numpy as np

LEGS_M = (150, 20, 30, 45, 60, 70, 90, 120, 160, 150)
# (WP_ACC, WP_JERK, turn [deg]) -> the time [s] between passing one inner waypoint and the next
SITL_LEG_S = {
    (2.5, 1.0, 20.0): (4.67, 5.49, 6.23, 6.81, 7.14, 9.00, 11.99, 16.00),
    (5.0, 5.0, 20.0): (2.77, 3.52, 4.56, 5.99, 6.99, 9.00, 12.00, 16.00),
    (2.5, 1.0, 60.0): (4.64, 5.61, 6.84, 8.15, 9.03, 11.09, 14.07, 18.09),
}


def zigzag(turn_deg: float) -> np.ndarray:
    """The waypoints [m ENU] of the SITL runs: LEGS_M, turning by ``turn_deg`` left and right."""
    points = [np.zeros(3)]
    for k, length in enumerate(LEGS_M):
        heading = math.radians(45.0 + (turn_deg / 2.0) * (1 if k % 2 == 0 else -1))
        points.append(points[-1] + length * np.array([math.sin(heading), math.cos(heading), 0.0]))
    return np.array(points)


def inner_leg_times_s(times_s: np.ndarray, positions: np.ndarray, waypoints: np.ndarray) -> np.ndarray:
    """The time between passing (nearest to) one waypoint and the next, for the inner legs (those
    the SITL times are of: between the run-in's end and the run-out's start)."""
    passed = [times_s[int(np.linalg.norm(positions - w, axis=1).argmin())] for w in waypoints[1:]]
    return np.diff(passed)[:-1]


# the same SITL, five copters on swarm_small with WP_ACC 3.5 / WP_JERK 2 (2026-12-06 22:44 UTC): how
# far behind [s] the copter's own S-curve timeline it flew, seconds after its route's start (the
# median of the four whose first leg starts level or climbs gently; docs/real-autopilots.md)
SITL_START_LAG_S = {4.0: 0.50, 6.0: 0.69, 8.0: 0.82}
