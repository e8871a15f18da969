"""4-D trajectories: timed waypoints (x, y, z, t) per UAV and the dynamics model that flies them.

Representation. A UAV's 4-D trajectory is a *timed polyline*: points (W, 3) [m] with
non-decreasing times (W,) [s]. Batches carry leading axes: (B, U, W, 3) for B candidate
solutions of U UAVs. Vertical-take-off vehicles get a climb leg from the ground under the first
waypoint and a descent leg to the ground under the last one, so the whole time in the air is
checked for conflicts. Polylines of different lengths are padded at the end by repeating the
last point and time (zero-duration legs, zero velocity), which changes nothing below.

Dynamics model (the paper leaves it open; one model, parameters per vehicle type):
constant-velocity legs joined at every point by a constant-acceleration *blend* centred on the
point's time (linear segments with parabolic blends). The blend at point k changes the velocity
from v_{k-1} to v_k (rest before the first and after the last point) with
``tau_k = max_xi |dv_xi| / a_max`` (per-axis limits, the paper's ``|a_xi| < a_max``) or
``|dv| / a_max`` (``limit="norm"``), so the acceleration limit holds by construction and the
model is valid when consecutive blends fit in the leg between them:
``tau_k / 2 + tau_{k+1} / 2 <= dt_k`` (penalised as the acceleration constraint ``f_a``).
During a blend the vehicle cuts the corner; it is never farther than
``|dv_k| tau_k / 8`` from the polyline at the same time (the deviation at the blend centre),
which is the margin the conflict checks add (see conflicts.py). Speed limits apply per axis
(paper) or to the norm, per leg. The turn radius ``|v|^3 / |v x a|`` is evaluated at the start,
middle and end of each in-flight blend (climb/descent ends excluded). The waypoint time error is
the arrival time at the last waypoint minus the planned arrival time.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "DYNAMICS",
    "Dynamics",
    "blend_times",
    "corner_deviation",
    "leg_velocities",
    "limit_violations",
    "position_at",
    "sample_path",
]

LIMIT_MODES = ("axis", "norm")


@dataclass(frozen=True)
class Dynamics:
    """Kinematic limits and model parameters of one vehicle.

    v_max_mps: speed limit, per axis or norm (``limit``) [m/s]; a_max_mps2 likewise [m/s^2].
    climb_mps / descent_mps: vertical speed of the take-off climb / landing descent legs [m/s].
    min_turn_radius_m: smallest allowed radius of curvature in a blend (0 = none) [m].
    max_time_error_s: allowed |arrival - planned arrival| at the last waypoint [s].
    takeoff_settle_s: extra time the take-off takes before the vehicle leaves the first waypoint
    (an autopilot finishes its take-off only when settled at altitude) [s]; modelled as a slower
    climb in the same vertical column, so the column stays occupied that long.
    vertical_takeoff: climb from / descend to the ground under the first / last waypoint.
    """

    v_max_mps: float = 5.0
    a_max_mps2: float = 2.0
    climb_mps: float = 2.5
    descent_mps: float = 1.5
    min_turn_radius_m: float = 0.0
    max_time_error_s: float = 30.0
    takeoff_settle_s: float = 0.0
    limit: str = "axis"
    vertical_takeoff: bool = True

    def __post_init__(self) -> None:
        for name in ("v_max_mps", "a_max_mps2", "climb_mps", "descent_mps"):
            if not getattr(self, name) > 0:
                raise ValueError(f"dynamics {name} must be > 0, got {getattr(self, name)!r}")
        if self.limit not in LIMIT_MODES:
            raise ValueError(f"dynamics limit must be one of {LIMIT_MODES}, got {self.limit!r}")


# Defaults per vehicle type (overridable per scenario): a multirotor hovers, turns on the spot and
# takes off vertically; a fixed wing starts its 4-D trajectory airborne and needs a turn radius.
DYNAMICS: dict[str, Dynamics] = {
    "multirotor": Dynamics(),
    "fixed_wing": Dynamics(
        v_max_mps=25.0, a_max_mps2=3.0, min_turn_radius_m=40.0, vertical_takeoff=False, limit="norm"
    ),
}


def leg_velocities(points: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Velocity of each leg (..., W-1, 3) [m/s]; zero on zero-duration (padding) legs."""
    dt = np.diff(times, axis=-1)
    dp = np.diff(points, axis=-2)
    safe = np.where(dt > 0, dt, 1.0)
    return np.where((dt > 0)[..., None], dp / safe[..., None], 0.0)


def _corner_dv(points: np.ndarray, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Velocity before / after every point (rest outside the polyline), each (..., W, 3)."""
    v = leg_velocities(points, times)
    zero = np.zeros_like(v[..., :1, :])
    return np.concatenate([zero, v], axis=-2), np.concatenate([v, zero], axis=-2)


def _magnitude(vec: np.ndarray, norm) -> np.ndarray:
    """|vec| as limited: largest axis (norm False) or Euclidean norm (norm True), (...,)."""
    return np.where(norm, np.linalg.norm(vec, axis=-1), np.abs(vec).max(axis=-1))


def blend_times(points: np.ndarray, times: np.ndarray, a_max_mps2, norm=False) -> np.ndarray:
    """Blend duration tau at every point (..., W) [s] for the acceleration limit.

    ``a_max_mps2`` and ``norm`` (True: norm limit, False: per axis) broadcast against the
    leading axes, e.g. (U, 1) per UAV.
    """
    v_in, v_out = _corner_dv(points, times)
    return _magnitude(v_out - v_in, norm) / a_max_mps2


def corner_deviation(points: np.ndarray, times: np.ndarray, tau: np.ndarray) -> np.ndarray:
    """Largest distance between the blended path and the polyline, per trajectory (...,) [m]."""
    v_in, v_out = _corner_dv(points, times)
    return (np.linalg.norm(v_out - v_in, axis=-1) * tau / 8.0).max(axis=-1)


def limit_violations(
    points: np.ndarray,
    times: np.ndarray,
    tau: np.ndarray,
    v_max_mps,
    min_turn_radius_m,
    norm=False,
    inflight: np.ndarray | None = None,
) -> dict[str, np.ndarray]:
    """Constraint excesses per trajectory (...,), all >= 0 and 0 when the limit holds.

    speed: sum over legs of the speed excess [m/s]; blend_overlap: sum over legs of
    ``tau_k/2 + tau_{k+1}/2 - dt_k`` when positive [s] (the acceleration constraint of the model;
    zero-duration padding legs excluded);
    turn: sum over blends of ``R_min - R`` when positive [m]. ``inflight`` (..., W) bool marks the
    points whose blends count for the turn radius (default: all). Limits broadcast like
    :func:`blend_times`.
    """
    v = leg_velocities(points, times)
    v_max = np.asarray(v_max_mps, dtype=float)[..., None]
    per_axis = np.maximum(np.abs(v) - v_max[..., None], 0.0).sum(axis=-1)
    total = np.maximum(np.linalg.norm(v, axis=-1) - v_max, 0.0)
    speed = np.where(norm, total, per_axis).sum(axis=-1)
    dt = np.diff(times, axis=-1)
    overlap = np.where(dt > 0, np.maximum(0.5 * (tau[..., :-1] + tau[..., 1:]) - dt, 0.0), 0.0).sum(axis=-1)
    r_min = np.asarray(min_turn_radius_m, dtype=float)
    if np.any(r_min > 0):
        v_in, v_out = _corner_dv(points, times)
        dv = v_out - v_in
        acc = dv / np.where(tau > 0, tau, 1.0)[..., None]
        radius = np.full(tau.shape, np.inf)
        for s in (0.0, 0.5, 1.0):
            vel = v_in + s * dv
            cross = np.linalg.norm(np.cross(vel, acc), axis=-1)
            r = np.where(
                cross > 1e-12, np.linalg.norm(vel, axis=-1) ** 3 / np.where(cross > 0, cross, 1), np.inf
            )
            radius = np.minimum(radius, r)
        if inflight is not None:
            radius = np.where(inflight, radius, np.inf)
        turn = np.maximum(r_min[..., None] - radius, 0.0).sum(axis=-1)
    else:
        turn = np.zeros(tau.shape[:-1])
    return {"speed": speed, "blend_overlap": overlap, "turn": turn}


def position_at(points: np.ndarray, times: np.ndarray, tau: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Blended-path position at query times ``t`` (Q,) for ONE trajectory (W, 3) -> (Q, 3) [m].

    Outside the blends the vehicle is on the polyline; inside blend k (``|t - t_k| < tau_k/2``)
    it follows ``p_k + v_in (t - t_k) + a/2 (t - t_k + tau_k/2)^2``, a = dv / tau_k.
    Before the first / after the last time it rests at the first / last point.
    """
    t = np.asarray(t, dtype=float)
    v_in, v_out = _corner_dv(points, times)
    legs = leg_velocities(points, times)
    k = np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(times) - 2)
    base = points[k] + legs[k] * np.clip(t - times[k], 0.0, None)[:, None]
    base = np.where((t <= times[0])[:, None], points[0], base)
    base = np.where((t >= times[-1])[:, None], points[-1], base)
    # the nearest point in time owns the blend that may contain t
    j = np.clip(np.searchsorted(times, t), 0, len(times) - 1)
    prev = np.clip(j - 1, 0, len(times) - 1)
    j = np.where(np.abs(times[prev] - t) < np.abs(times[j] - t), prev, j)
    half = tau[j] / 2.0
    inside = np.abs(t - times[j]) < half
    s = t - times[j] + half
    acc = (v_out[j] - v_in[j]) / np.where(tau[j] > 0, tau[j], 1.0)[:, None]
    blended = points[j] + v_in[j] * (t - times[j])[:, None] + 0.5 * acc * (s**2)[:, None]
    return np.where(inside[:, None], blended, base)


def sample_path(
    points: np.ndarray, times: np.ndarray, tau: np.ndarray, per_blend: int = 8
) -> tuple[np.ndarray, np.ndarray]:
    """Dense samples (M, 3), (M,) of the blended path of ONE trajectory.

    The path runs from ``t_0 - tau_0/2`` (the vehicle leaves the first point: its blend from rest
    is centred on t_0) to ``t_last + tau_last/2``. Samples at every blend's ends and ``per_blend``
    steps inside it, so linear interpolation between samples is within
    ``a tau^2 / (8 per_blend^2)`` of the path.
    """
    keep = np.concatenate([[True], np.diff(times) > 0])  # drop padding repeats
    pts, tms, ta = points[keep], times[keep], tau[keep]
    grid = [tms]
    for tk, hk in zip(tms, ta / 2.0, strict=True):
        if hk > 0:
            grid.append(np.linspace(tk - hk, tk + hk, per_blend + 1))
    t = np.unique(np.concatenate(grid))
    return position_at(pts, tms, ta, t), t
