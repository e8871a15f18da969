"""ArduCopter's waypoint legs as it flies them: the S-curve of each leg and the hand-over at corners.

ArduCopter (AC_WPNav, AP_Math/SCurve.cpp) plans every straight leg on its own, from rest at its
start to rest at its end: the speed rises on a jerk-limited ramp (raised-cosine jerk edges,
``WaypointNav.jerk_edge_s``), holds, and falls back on the mirror ramp (``SCurve::add_segments``:
``calculate_path`` over half the leg), so a leg too short to reach its speed within its first
half peaks lower. A climbing or descending leg takes the speed and acceleration whose horizontal
and vertical parts keep WP_SPD, WP_SPD_UP / _DN, WP_ACC and WP_ACC_Z (``kinematic_limit``). The
next leg starts once this one is braking and has no longer to run than the next one's ramp, and
only when the turn's midpoint lies within WP_RADIUS_M of the waypoint, below both legs' speeds and
within the corner (WP_ACC_CNR, 2 WP_ACC by default) and vertical accelerations
(``advance_target_along_track``); the two legs' motions then add up.

This is the autopilot's target, checked leg by leg against SITL (tests/test_scurve.py); the
vehicle's lag behind it and a top speed under WP_SPD are not modelled.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["DT_S", "WaypointNav", "fly_legs"]

DT_S = 0.01  # time step of the flown profile [s]


@dataclass(frozen=True)
class WaypointNav:
    """ArduCopter's waypoint-navigation parameters (AC_WPNav; defaults: ArduCopter 4.7+'s)."""

    accel_mps2: float = 2.5  # WP_ACC
    jerk_mps3: float = 1.0  # WP_JERK
    climb_mps: float = 2.5  # WP_SPD_UP
    descent_mps: float = 1.5  # WP_SPD_DN
    accel_z_mps2: float = 1.0  # WP_ACC_Z
    radius_m: float = 2.0  # WP_RADIUS_M
    corner_accel_mps2: float = 0.0  # WP_ACC_CNR (0: twice WP_ACC)
    input_tc_s: float = 0.15  # ATC_INPUT_TC

    @property
    def jerk_edge_s(self) -> float:
        """``tj``: how long the jerk takes to rise. AC_WPNav::calc_scurve_jerk_and_snap sets the snap
        to WP_JERK pi / (2 max(ATC_INPUT_TC, 0.1)) / 2 and tj = WP_JERK pi / (2 snap): twice the
        time constant, whatever the jerk (the snap's cap by ATC_ACCEL_R_MAX is far above it)."""
        return 2.0 * max(self.input_tc_s, 0.1)


@dataclass
class _Leg:
    unit: np.ndarray  # direction (3,)
    length_m: float
    speed_max_mps: float  # along the leg
    speed: np.ndarray  # speed samples DT_S apart, from rest to rest
    ramp_n: int  # samples of the ramp up (and down)


def _ramp_jerk(accel: float, jerk: float, tj: float) -> float:
    """The jerk the ramp rises at: WP_JERK, or less where even ``tj`` of it would overshoot the
    acceleration (SCurve::calculate_path then shortens the rise; a mock's unlimited jerk)."""
    return min(jerk, accel / tj)


def _ramp_reach(speed: float, accel: float, jerk: float, tj: float) -> tuple[float, float]:
    """(peak acceleration, duration) of the ramp from rest to ``speed``: the acceleration rises to
    its peak over a/J + tj, holds, and falls back, so the ramp covers speed x duration / 2."""
    jerk = _ramp_jerk(accel, jerk, tj)
    peak = accel
    if peak * (peak / jerk + tj) > speed:  # the speed comes before the acceleration limit
        peak = jerk * (-tj + math.sqrt(tj * tj + 4.0 * speed / jerk)) / 2.0
    return peak, 2.0 * (peak / jerk + tj) + max(0.0, speed / peak - (peak / jerk + tj))


def _peak_speed(length_m: float, speed: float, accel: float, jerk: float, tj: float) -> float:
    """The highest speed up to ``speed`` whose ramp fits in half the leg (bisection: the ramp's
    distance grows with its speed)."""
    if speed * _ramp_reach(speed, accel, jerk, tj)[1] <= length_m:
        return speed
    lo, hi = 0.0, speed
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        fits = mid * _ramp_reach(mid, accel, jerk, tj)[1] <= length_m
        lo, hi = (mid, hi) if fits else (lo, mid)
    return lo


def _ramp_speeds(speed: float, accel: float, jerk: float, tj: float) -> np.ndarray:
    """Speed samples of the ramp from rest to ``speed`` (raised-cosine jerk edges)."""
    peak, _ = _ramp_reach(speed, accel, jerk, tj)
    jerk = _ramp_jerk(accel, jerk, tj)
    jerk_used = jerk if peak >= jerk * tj else peak / tj
    rise, hold = max(1, round(tj / DT_S)), round(max(0.0, peak / jerk_used - tj) / DT_S)
    edge = jerk_used * (1.0 - np.cos(np.pi * (np.arange(rise) + 0.5) / rise)) / 2.0
    block = np.concatenate([edge, np.full(hold, jerk_used), edge[::-1]])
    cruise = round(max(0.0, speed / peak - (peak / jerk_used + tj)) / DT_S)
    speeds = np.cumsum(np.cumsum(np.concatenate([block, np.zeros(cruise), -block])) * DT_S) * DT_S
    return speeds * (speed / speeds[-1])


def _leg(step: np.ndarray, speed_xy: float, nav: WaypointNav) -> _Leg:
    """One leg's speed profile with its speed and acceleration limits along it (kinematic_limit)."""
    length = float(np.linalg.norm(step))
    unit = step / length
    horizontal, vertical = float(np.hypot(unit[0], unit[1])), abs(float(unit[2]))
    climb = nav.climb_mps if unit[2] > 0 else nav.descent_mps
    speed = min(_along(speed_xy, horizontal), _along(climb, vertical))
    accel = min(_along(nav.accel_mps2, horizontal), _along(nav.accel_z_mps2, vertical))
    tj = nav.jerk_edge_s
    ramp = _ramp_speeds(_peak_speed(length, speed, accel, nav.jerk_mps3, tj), accel, nav.jerk_mps3, tj)
    cruise = round(max(0.0, length - 2.0 * ramp.sum() * DT_S) / ramp[-1] / DT_S)
    profile = np.concatenate([ramp, np.full(cruise, ramp[-1]), ramp[::-1]])
    return _Leg(unit, length, speed, profile * (length / (profile.sum() * DT_S)), len(ramp))


def _along(limit: float, part: float) -> float:
    """The largest value along a leg whose component ``part`` (of a unit vector) keeps ``limit``."""
    return limit / part if part > 0 else math.inf


def _hand_over(a: _Leg, b: _Leg, nav: WaypointNav) -> int:
    """The sample of leg ``a`` at which leg ``b`` starts (SCurve::advance_target_along_track)."""
    first = max(a.speed.size - a.ramp_n, a.speed.size - b.ramp_n)
    k = np.arange(first, a.speed.size)
    half = (a.speed.size - k) // 2
    s_a = np.concatenate([[0.0], np.cumsum(a.speed)[:-1]]) * DT_S
    s_b = np.concatenate([[0.0], np.cumsum(b.speed)[:-1]]) * DT_S
    acc_a, acc_b = np.gradient(a.speed, DT_S), np.gradient(b.speed, DT_S)
    at_a, at_b = np.minimum(k + half, a.speed.size - 1), np.minimum(half, b.speed.size - 1)
    turn_pos = np.outer(s_a[at_a] - a.length_m, a.unit) + np.outer(s_b[at_b], b.unit)
    turn_vel = np.outer(a.speed[at_a], a.unit) + np.outer(b.speed[at_b], b.unit)
    turn_acc = np.outer(acc_a[at_a], a.unit) + np.outer(acc_b[at_b], b.unit)
    corner = nav.corner_accel_mps2 if nav.corner_accel_mps2 > 0 else 2.0 * nav.accel_mps2
    ok = (
        (np.linalg.norm(turn_pos, axis=1) < nav.radius_m)
        & (np.linalg.norm(turn_vel, axis=1) < min(a.speed_max_mps, b.speed_max_mps))
        & (np.hypot(turn_acc[:, 0], turn_acc[:, 1]) < corner)
        & (np.abs(turn_acc[:, 2]) < nav.accel_z_mps2)
    )
    return int(k[np.argmax(ok)]) if ok.any() else a.speed.size


def fly_legs(
    waypoints: np.ndarray, speeds_mps: np.ndarray, nav: WaypointNav
) -> tuple[np.ndarray, np.ndarray]:
    """Times [s] and positions (N, 3) [m] of the position target ArduCopter flies from the hover at
    ``waypoints[0]`` through the others to rest at the last; ``speeds_mps[k]``: the horizontal speed
    of the leg into waypoint k."""
    legs = [
        _leg(waypoints[k + 1] - waypoints[k], float(speeds_mps[k + 1]), nav)
        for k in range(len(waypoints) - 1)
        if np.linalg.norm(waypoints[k + 1] - waypoints[k]) > 1e-3
    ]
    if not legs:
        return np.zeros(1), np.asarray(waypoints[:1], dtype=float)
    starts = [0]
    for a, b in zip(legs, legs[1:], strict=False):
        starts.append(starts[-1] + _hand_over(a, b, nav))
    velocity = np.zeros((starts[-1] + legs[-1].speed.size, 3))
    for start, leg in zip(starts, legs, strict=True):
        velocity[start : start + leg.speed.size] += np.outer(leg.speed, leg.unit)
    positions = waypoints[0] + np.concatenate([np.zeros((1, 3)), np.cumsum(velocity, axis=0)[:-1] * DT_S])
    return np.arange(len(velocity)) * DT_S, positions
