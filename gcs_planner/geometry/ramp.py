"""The time a multirotor loses to its speed ramps: the jerk-limited S-curve its autopilot flies from
the hover to cruise speed and back down (ArduCopter AC_WPNav WP_ACC / WP_JERK, PX4 MPC_ACC_HOR /
MPC_JERK_AUTO; a mock airframe's constant acceleration is the S-curve of infinite jerk).

The acceleration rises at the jerk to its peak (the limit, or less when the speed is reached
first), holds, and falls back to zero; that profile is symmetric, so the ramp to speed v over T
seconds covers v T / 2 and the vehicle ends it T / 2 behind one that moved at v from the start.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["ramp_loss_s", "stop_lag_s"]


def _peak_and_duration(speed_mps: float, accel_mps2: float, jerk_mps3: float) -> tuple[float, float]:
    peak = min(accel_mps2, math.sqrt(speed_mps * jerk_mps3))
    return peak, speed_mps / peak + peak / jerk_mps3


def ramp_loss_s(speed_mps: float, accel_mps2: float, jerk_mps3: float = math.inf) -> float:
    """How far behind a vehicle at constant ``speed_mps`` one that ramps from rest ends up [s]."""
    return _peak_and_duration(speed_mps, accel_mps2, jerk_mps3)[1] / 2.0


def stop_lag_s(
    to_go_m: np.ndarray, speed_mps: float, accel_mps2: float, jerk_mps3: float = math.inf
) -> np.ndarray:
    """How much later than at constant ``speed_mps`` a vehicle that brakes to a stop at the end of
    its route passes each point ``to_go_m`` [m] before that end [s]: 0 before its braking
    distance, ``ramp_loss_s`` at the end. Braking is the ramp from rest run backwards, so the time
    it takes over the last s metres is the ramp's time to cover s from rest."""
    peak, duration = _peak_and_duration(speed_mps, accel_mps2, jerk_mps3)
    t = np.linspace(0.0, duration, 2001)
    accel = (
        np.minimum(np.minimum(jerk_mps3 * t, peak), jerk_mps3 * (duration - t))
        if math.isfinite(jerk_mps3)
        else np.full_like(t, peak)
    )
    speed = np.concatenate([[0.0], np.cumsum((accel[1:] + accel[:-1]) / 2.0 * np.diff(t))])
    covered = np.concatenate([[0.0], np.cumsum((speed[1:] + speed[:-1]) / 2.0 * np.diff(t))])
    s = np.clip(np.asarray(to_go_m, dtype=float), 0.0, covered[-1])
    return (duration - covered[-1] / speed_mps) - (np.interp(s, covered, t) - s / speed_mps)
