"""Sampled-track helpers shared by the leg planning, the missions and the report.

A track is times t (K,) [s] and ENU positions xy (K, 2) [m], oldest first, as the coalition
simulation records them and as the flown telemetry is recorded.
"""

from __future__ import annotations

import math

import numpy as np

from gcs_planner.core.geo import wrap_pi

__all__ = ["continue_turn", "drop_spikes", "pose_at", "slice_track"]


def slice_track(t: np.ndarray, xy: np.ndarray, t0: float, t1: float) -> tuple[np.ndarray, np.ndarray]:
    """Track samples in [t0, t1], with the ends interpolated exactly."""
    inner = (t > t0 + 1e-6) & (t < t1 - 1e-6)
    ts = np.r_[t0, t[inner], t1]
    return ts, np.column_stack([np.interp(ts, t, xy[:, 0]), np.interp(ts, t, xy[:, 1])])


def pose_at(t: np.ndarray, xy: np.ndarray, t_s: float) -> np.ndarray:
    """x, y, heading [rad] of a sampled track at t_s (heading of the segment there)."""
    k = int(np.clip(np.searchsorted(t, t_s) - 1, 0, len(t) - 2))
    u = (t_s - t[k]) / max(t[k + 1] - t[k], 1e-9)
    d = xy[k + 1] - xy[k]
    return np.r_[xy[k] + u * d, math.atan2(d[1], d[0])]


def continue_turn(
    t: np.ndarray, xy: np.ndarray, t_end: float, speed_mps: float, max_rate: float, extend_s: float,
    dt_s: float = 0.5,
) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """extend_s of flight after t_end at the track's turn rate there (the pre-award loiter goes on,
    as the bids predicted): times (K,) and positions (K, 2), t_end excluded."""
    tau = t_end + np.array([-2.0, -1.0, 0.0])
    p = np.column_stack([np.interp(tau, t, xy[:, 0]), np.interp(tau, t, xy[:, 1])])
    h = np.arctan2(*np.diff(p, axis=0).T[::-1])
    rate = float(np.clip(wrap_pi(h[1] - h[0]), -max_rate, max_rate))
    steps = np.arange(1, int(extend_s / dt_s) + 1)
    heading = h[1] + rate * (0.5 + (steps - 0.5) * dt_s)
    xy_ext = p[-1] + np.cumsum(speed_mps * dt_s * np.column_stack([np.cos(heading), np.sin(heading)]), axis=0)
    return t_end + steps * dt_s, xy_ext


def drop_spikes(t: np.ndarray, xy: np.ndarray, speed_mps: float) -> tuple[np.ndarray, np.ndarray]:
    """The simulated track without its isolated far samples: a sample reached and left at more than
    twice the cruise speed. Track.start_leg, cutting a leg short, fills the gap up to the new leg
    with the loiter planned after the cut leg, which starts elsewhere (one sample, up to 1.6 km
    away, on the station changes at t = 140 s of the paper scenario); as a waypoint it would send the
    vehicle there."""
    v = np.hypot(*np.diff(xy, axis=0).T) / np.maximum(np.diff(t), 1e-9)
    spike = np.r_[False, (v[:-1] > 2.0 * speed_mps) & (v[1:] > 2.0 * speed_mps), False]
    return t[~spike], xy[~spike]
