"""The mock plane's own ArduPlane L1 waypoint guidance, written from ArduPilot's
``AP_L1_Control::update_waypoint`` (libraries/AP_L1_Control/AP_L1_Control.cpp) and not shared
with the client's predictor (gcs_planner.flight.l1_guidance), so that a wrong model on either side fails
the cross-check test instead of agreeing with itself.

Like the source it works in the NE frame (x north, y east) with the controller's 2-D cross
product ``a % b = a.x b.y - a.y b.x``: a positive lateral acceleration turns the plane right
(clockwise seen from above). Left out, as in a plane that has just started a leg: the cross-track
integrator (NAVL1_XTRACK_I = 0 by default) and the indecision guard for a target behind.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["L1Plane", "SITL_PLANE", "l1_lateral_accel"]

NAVL1_DAMPING = 0.75  # AP_L1_Control var_info default
ONE_OVER_PI = 0.3183099


@dataclass(frozen=True)
class L1Plane:
    """How a mock plane flies L1 guidance: NAVL1_PERIOD [s], the share of the turn rate the bank
    the guidance demands gives it, and the time constant [s] of its bank (RLL2SRV_TCONST)."""

    period_s: float
    turn_gain: float = 1.0
    roll_tau_s: float = 0.0


# ArduPlane SITL's stock plane: NAVL1_PERIOD 15 and RLL2SRV_TCONST 0.25 (Tools/autotest/models/
# plane.parm); it turns at 0.7 of its bank's coordinated rate (measured, docs/coalition.md)
SITL_PLANE = L1Plane(15.0, 0.7, 0.25)


def l1_lateral_accel(
    north_east: np.ndarray, prev_wp: np.ndarray, next_wp: np.ndarray, ground_ne: np.ndarray, period_s
) -> np.ndarray:
    """``_latAccDem`` [m/s^2, + = right turn] for rows of planes: position, the leg's start and end
    and the ground velocity as (N, 2) arrays in metres north / east."""
    speed = np.maximum(np.linalg.norm(ground_ne, axis=1), 0.1)
    l1_dist = np.maximum(ONE_OVER_PI * NAVL1_DAMPING * period_s * speed, 0.1)
    a_air = north_east - prev_wp
    ab = next_wp - prev_wp
    ab_length = np.linalg.norm(ab, axis=1)
    degenerate = ab_length < 1.0e-6  # WP A on WP B: fly the way it goes
    ab = np.where(degenerate[:, None], ground_ne, ab) / np.where(degenerate, speed, ab_length)[:, None]
    wp_a_dist = np.linalg.norm(a_air, axis=1)
    crosstrack = _cross(a_air, ab)
    along = np.einsum("ij,ij->i", a_air, ab)

    nu2 = np.arctan2(_cross(ground_ne, ab), np.einsum("ij,ij->i", ground_ne, ab))
    nu1 = np.arcsin(np.clip(crosstrack / l1_dist, -0.7071, 0.7071))
    nu = nu1 + nu2
    behind_a = (wp_a_dist > l1_dist) & (along / np.maximum(wp_a_dist, 1.0) < -0.7071)
    nu = np.where(behind_a, _heading_error(ground_ne, prev_wp - north_east), nu)
    past_b = along > ab_length + speed * 3.0
    nu = np.where(past_b, _heading_error(ground_ne, next_wp - north_east), nu)
    nu = np.clip(nu, -1.5708, 1.5708)
    k_l1 = 4.0 * NAVL1_DAMPING * NAVL1_DAMPING
    return k_l1 * speed * speed / l1_dist * np.sin(nu)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]


def _heading_error(ground_ne: np.ndarray, to_point: np.ndarray) -> np.ndarray:
    """Nu of flying straight at a point: atan2(v % u, v . u) with u the unit vector to it."""
    unit = to_point / np.maximum(np.linalg.norm(to_point, axis=1), 1.0e-6)[:, None]
    return np.arctan2(_cross(ground_ne, unit), np.einsum("ij,ij->i", ground_ne, unit))
