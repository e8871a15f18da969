"""Closest approach of two vehicles that may fly off their schedules: the timing-aware separation.

Vehicles fly their planned paths but not exactly on time: each is some seconds early or late
along its path (docs/timing-separation.md measures it on the mock). For two vehicles whose
schedule errors differ by at most ``T`` seconds, over a stretch where both move linearly, the
relative position is ``d0 + u s + w e`` with ``s`` in [0, 1] along the stretch (``u`` = the
relative displacement over it) and ``e`` in [-1, 1] (``w`` = one vehicle's displacement in ``T``
seconds): a parallelogram. Its distance from the origin is the closest the two can come under any
such timing error. Where they cross at an angle this is the planned miss distance less
``T x v_perp`` (v_perp = |v_a x v_b| / |v_a - v_b|, the speed they share across their relative
motion); side by side or head-on it is the planned miss distance; one behind the other it is
the gap less the ``v T`` the follower may close. ``T = 0`` is the plain closest approach.
"""

from __future__ import annotations

import numpy as np

__all__ = ["closest_under_timing", "closest_under_timing_t", "dot3"]


def dot3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Dot products of vectors stored component-first, (3, ...) -> (...), summed x + y + z in order
    (a reduction over a last axis of 3 is several times slower than three products)."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _norm(a: np.ndarray) -> np.ndarray:
    return np.sqrt(dot3(a, a))


def _segment(p: np.ndarray, q: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Distance from the origin to p + q s, s in [lo, hi]; vectors component-first (3, ...)."""
    qq = dot3(q, q)
    s = np.clip(-dot3(p, q) / np.where(qq > 0, qq, 1.0), lo, hi)
    return _norm(p + s * q)


def closest_under_timing(d0: np.ndarray, u: np.ndarray, w: np.ndarray) -> np.ndarray:
    """min |d0 + u s + w e| over s in [0, 1], e in [-1, 1]; vectors (..., 3) -> (...).

    The minimum of a convex function over the box is its stationary point where that lies inside,
    else on one of the four edges.
    """
    return closest_under_timing_t(np.moveaxis(d0, -1, 0), np.moveaxis(u, -1, 0), np.moveaxis(w, -1, 0))


def closest_under_timing_t(d0: np.ndarray, u: np.ndarray, w: np.ndarray) -> np.ndarray:
    """``closest_under_timing`` of vectors stored component-first, (3, ...) -> (...)."""
    edges = np.minimum(
        np.minimum(_segment(d0 - w, u, 0.0, 1.0), _segment(d0 + w, u, 0.0, 1.0)),
        np.minimum(_segment(d0, w, -1.0, 1.0), _segment(d0 + u, w, -1.0, 1.0)),
    )
    uu, ww, uw, du, dw = dot3(u, u), dot3(w, w), dot3(u, w), dot3(d0, u), dot3(d0, w)
    det = uu * ww - uw * uw
    ok = det > 1e-9 * np.maximum(uu * ww, 1e-300)  # u and w not parallel (nor zero)
    safe = np.where(ok, det, 1.0)
    s = (-du * ww + dw * uw) / safe
    e = (-dw * uu + du * uw) / safe
    inside = ok & (s >= 0.0) & (s <= 1.0) & (e >= -1.0) & (e <= 1.0)
    interior = _norm(d0 + s * u + e * w)
    return np.where(inside, np.minimum(interior, edges), edges)
