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

Computed one pair at a time and compiled (numba): the priority swarm's traffic walk and the 4-D
planner's pair check call it from their own compiled loops.
"""

from __future__ import annotations

import numpy as np

from gcs_planner.core.compiled import compiled
from gcs_planner.geometry.vec3 import add, along, dot, sub

__all__ = ["closest_on_segment", "closest_under_timing_one"]


@compiled
def closest_under_timing_one(d0: tuple, u: tuple, w: tuple) -> float:
    """min |d0 + u s + w e| over s in [0, 1], e in [-1, 1]. The minimum of a convex function over
    the box is its stationary point where that lies inside, else on one of the four edges."""
    edges = min(
        min(closest_on_segment(sub(d0, w), u, 0.0, 1.0), closest_on_segment(add(d0, w), u, 0.0, 1.0)),
        min(closest_on_segment(d0, w, -1.0, 1.0), closest_on_segment(add(d0, u), w, -1.0, 1.0)),
    )
    uu, ww, uw, du, dw = dot(u, u), dot(w, w), dot(u, w), dot(d0, u), dot(d0, w)
    det = uu * ww - uw * uw
    if not det > 1e-9 * max(uu * ww, 1e-300):  # u and w parallel (or zero)
        return edges
    s = (-du * ww + dw * uw) / det
    e = (-dw * uu + du * uw) / det
    if not (0.0 <= s <= 1.0 and -1.0 <= e <= 1.0):
        return edges
    c = along(along(d0, s, u), e, w)
    return min(np.sqrt(dot(c, c)), edges)


@compiled
def closest_on_segment(p: tuple, q: tuple, lo: float, hi: float) -> float:
    """Distance from the origin to p + q s, s in [lo, hi]."""
    qq = dot(q, q)
    s = min(max(-dot(p, q) / (qq if qq > 0 else 1.0), lo), hi)
    c = along(p, s, q)
    return np.sqrt(dot(c, c))
