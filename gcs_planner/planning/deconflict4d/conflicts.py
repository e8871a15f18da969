"""Conflict detection between timed polylines by analytic closest approach (CPA).

Two UAVs conflict when their distance drops below the separation at any common instant. Both
trajectories are piecewise linear in time, so over every pair of legs whose time windows
overlap the relative position is linear, ``d(s) = d0 + dv s`` for ``s in [0, T]``, and the
closest approach is exact: ``s* = clip(-d0.dv / |dv|^2, 0, T)``. No time step is needed, so
1 m separation at 10 m/s closing speed (which a 0.05 s sampling step would barely catch) is
handled exactly. Compiled (numba) loops over candidate solutions, pairs and leg pairs.

A UAV-manned conflict is the same computation in the frame of the manned aircraft's
uncertainty ellipsoid: rotating by the ellipsoid's axes and dividing by its (inflated)
semi-axes maps the ellipsoid to the unit sphere and keeps motion linear, so "enters the region"
is "whitened closest approach < 1" (see manned.py for how the regions are built).

Counting (the paper sorts UAVs by their number of conflicts): a UAV's count is the number of
*other aircraft* (UAVs and manned) it conflicts with at least once, not the number of leg pairs.
Pairs are pre-filtered by space-time bounding boxes so large fleets stay cheap.
"""

from __future__ import annotations

import numpy as np

from gcs_planner.core.compiled import compiled
from gcs_planner.geometry.timing import closest_under_timing_one
from gcs_planner.geometry.vec3 import along, dot_xzy, row, scale, sub, times_each

__all__ = [
    "candidate_pairs",
    "closest_approach",
    "conflict_counts",
    "pair_closest_approach",
    "zone_closest_approach",
]


def closest_approach(
    pa: np.ndarray, ta: np.ndarray, pb: np.ndarray, tb: np.ndarray, scale_b: np.ndarray | None = None
) -> tuple[float, float]:
    """Minimum distance between two timed polylines over their common time, and when.

    pa (Wa, 3), ta (Wa,); pb (Wb, 3), tb (Wb,). Optional ``scale_b`` (Wb-1, 3): per leg of b,
    divide the relative position by it axis by axis (ellipsoid semi-axes in a frame where the
    ellipsoid is axis-aligned; 1 = on its surface). The distance is +inf when the time spans
    never overlap. The same kernels as the fleet checks, for one pair.
    """
    if scale_b is not None:
        no_margin = np.zeros((1, 1))
        d, t = zone_closest_approach(
            pa[None, None], ta[None, None], pb[None], tb[None], np.eye(3)[None], scale_b[None], no_margin
        )
        return float(d[0, 0, 0]), float(t[0, 0, 0])
    n_w = max(len(ta), len(tb))
    points = np.stack([_padded(pa, n_w), _padded(pb, n_w)])[None]
    times = np.stack([_padded(ta, n_w), _padded(tb, n_w)])[None]
    d, t = pair_closest_approach(points, times, np.array([[0, 1]]))
    return float(d[0, 0]), float(t[0, 0])


def _padded(a: np.ndarray, n: int) -> np.ndarray:
    """a repeated at its last row to n rows: a vehicle that stays (zero-duration legs)."""
    return np.concatenate([a, np.repeat(a[-1:], n - len(a), axis=0)])


def candidate_pairs(points: np.ndarray, times: np.ndarray, reach_m: np.ndarray) -> np.ndarray:
    """UAV pairs (P, 2), i < j, whose space-time boxes come within reach in ANY candidate.

    points (B, U, W, 3), times (B, U, W); reach_m (B, U) is how far each UAV's own influence
    extends (half the separation plus its corner deviation margin).
    """
    return _near_pairs(points, times, reach_m)


@compiled
def _near_pairs(points, times, reach_m) -> np.ndarray:
    """``candidate_pairs``: each UAV's box per candidate, then every pair i < j in order."""
    n_b, n_u, n_w, _ = points.shape
    lo = np.empty((n_u, 3))
    hi = np.empty((n_u, 3))
    t_lo = np.empty(n_u)
    t_hi = np.empty(n_u)
    near = np.zeros((n_u, n_u), dtype=np.bool_)
    for c in range(n_b):
        for u in range(n_u):
            t_lo[u], t_hi[u] = times[c, u].min(), times[c, u].max()
            for ax in range(3):
                lo[u, ax] = points[c, u, :, ax].min() - reach_m[c, u]
                hi[u, ax] = points[c, u, :, ax].max() + reach_m[c, u]
        for i in range(n_u):
            for j in range(i + 1, n_u):
                if not near[i, j] and t_lo[i] < t_hi[j] and t_lo[j] < t_hi[i]:
                    near[i, j] = (
                        lo[i, 0] <= hi[j, 0]
                        and lo[j, 0] <= hi[i, 0]
                        and lo[i, 1] <= hi[j, 1]
                        and lo[j, 1] <= hi[i, 1]
                        and lo[i, 2] <= hi[j, 2]
                        and lo[j, 2] <= hi[i, 2]
                    )
    return np.argwhere(near)


def pair_closest_approach(
    points: np.ndarray,
    times: np.ndarray,
    pairs: np.ndarray,
    reach_m: np.ndarray | None = None,
    timing_s: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Closest approach (B, P) distance [m] and time [s] for the given UAV pairs (P, 2); with
    ``timing_s`` the distance under any relative schedule error up to that (``_cpa_one``).

    With ``reach_m`` (U,) only leg pairs whose space-time boxes (over all B candidates) come
    within ``reach_i + reach_j`` are computed; the others report +inf, which is exact for every
    question "closer than reach_i + reach_j?". Without it every leg pair is computed. Of equally
    close leg pairs the latest time is reported.
    """
    n_b, n_p = points.shape[0], len(pairs)
    d_min = np.full((n_b, n_p), np.inf)
    t_min = np.zeros((n_b, n_p))
    if n_p:
        prune = reach_m is not None
        reach = np.asarray(reach_m if prune else np.zeros(points.shape[1]), dtype=float)
        _pair_kernel(points, times, np.asarray(pairs, dtype=np.int64), reach, prune, timing_s, d_min, t_min)
    return d_min, t_min


@compiled
def _pair_kernel(points, times, pairs, reach, prune, timing_s, d_min, t_min) -> None:
    """Each pair's legs whose boxes come within reach (all legs unless ``prune``), every
    candidate's closest approach over them (``_leg_pair``), the minimum and its latest time.
    Times are non-decreasing along each polyline, so the legs of UAV j that overlap leg a of UAV i
    in time are a run that only moves forward with a."""
    n_b = points.shape[0]
    lo, hi, tlo, thi = _leg_boxes(points, times)
    n_s = tlo.shape[1]
    for k in range(len(pairs)):
        i, j = pairs[k, 0], pairs[k, 1]
        r = reach[i] + reach[j]
        best = np.full(n_b, np.inf)
        when = np.full(n_b, -np.inf)
        seen = False
        first = 0
        for a in range(n_s):
            for b in range(first if prune else 0, n_s):
                if prune:
                    if thi[j, b] <= tlo[i, a]:  # b ends before a starts, and before every later a
                        first = b + 1
                        continue
                    if tlo[j, b] >= thi[i, a]:  # b and every later b start after a ends
                        break
                    if not _boxes_near(lo, hi, i, a, j, b, r):
                        continue
                seen = True
                for c in range(n_b):
                    dist, t = _leg_pair(points[c], times[c], i, a, j, b, timing_s)
                    if dist < best[c]:
                        best[c], when[c] = dist, t
                    elif dist == best[c]:
                        when[c] = max(when[c], t)
        if seen:
            d_min[:, k] = best
            t_min[:, k] = when


@compiled
def _leg_boxes(points, times) -> tuple:
    """Each leg's box (U, S, 3) and time span (U, S) over all candidates."""
    n_b, n_u, n_w, _ = points.shape
    lo = np.full((n_u, n_w - 1, 3), np.inf)
    hi = np.full((n_u, n_w - 1, 3), -np.inf)
    tlo = np.full((n_u, n_w - 1), np.inf)
    thi = np.full((n_u, n_w - 1), -np.inf)
    for c in range(n_b):
        for u in range(n_u):
            for s in range(n_w - 1):
                tlo[u, s] = min(tlo[u, s], times[c, u, s])
                thi[u, s] = max(thi[u, s], times[c, u, s + 1])
                for ax in range(3):
                    lo[u, s, ax] = min(lo[u, s, ax], points[c, u, s, ax], points[c, u, s + 1, ax])
                    hi[u, s, ax] = max(hi[u, s, ax], points[c, u, s, ax], points[c, u, s + 1, ax])
    return lo, hi, tlo, thi


@compiled
def _boxes_near(lo, hi, i, a, j, b, r) -> bool:
    """Do the boxes of leg a of UAV i and leg b of UAV j come within r in x, y and z?"""
    return (
        lo[i, a, 0] - r <= hi[j, b, 0]
        and lo[j, b, 0] - r <= hi[i, a, 0]
        and lo[i, a, 1] - r <= hi[j, b, 1]
        and lo[j, b, 1] - r <= hi[i, a, 1]
        and lo[i, a, 2] - r <= hi[j, b, 2]
        and lo[j, b, 2] - r <= hi[i, a, 2]
    )


@compiled
def _leg_pair(points, times, i, a, j, b, timing_s) -> tuple:
    """Closest approach of leg a of UAV i and leg b of UAV j in one candidate: (distance, time)."""
    pa, va = _leg(points[i], times[i], a)
    pb, vb = _leg(points[j], times[j], b)
    lo = max(times[i, a], times[j, b])
    hi = min(times[i, a + 1], times[j, b + 1])
    d0 = sub(along(pa, lo - times[i, a], va), along(pb, lo - times[j, b], vb))
    return _cpa_one(d0, sub(va, vb), lo, hi, timing_s, vb)


@compiled
def _cpa_one(d0, dv, lo, hi, timing_s, vb) -> tuple:
    """min |d0 + dv s| over the legs' common time [lo, hi] (+inf when empty) and when, s in
    [0, hi - lo]; with ``timing_s`` > 0 the distance under any schedule error up to that
    (leg b, velocity vb, moved along itself: gcs_planner.geometry.timing)."""
    valid = hi > lo
    span = hi - lo if valid else 0.0
    vv = dot_xzy(dv, dv)
    s = -dot_xzy(d0, dv) / vv if vv > 0 else 0.0
    s = min(max(s, 0.0), span)
    if not valid:
        return np.inf, lo + s
    if timing_s > 0:
        return closest_under_timing_one(d0, scale(dv, span), scale(vb, timing_s)), lo + s
    d = along(d0, s, dv)
    return np.sqrt(dot_xzy(d, d)), lo + s


@compiled
def _leg(p, t, s) -> tuple:
    """Start point and velocity of leg s of the polyline p (W, 3) timed t (W,); a leg of no
    duration does not move."""
    p0 = row(p, s)
    dt = t[s + 1] - t[s]
    if not dt > 0:
        return p0, (0.0, 0.0, 0.0)
    d = sub(row(p, s + 1), p0)
    return p0, (d[0] / dt, d[1] / dt, d[2] / dt)


def zone_closest_approach(
    points: np.ndarray,
    times: np.ndarray,
    zone_points: np.ndarray,
    zone_times: np.ndarray,
    zone_rot: np.ndarray,
    zone_axes: np.ndarray,
    margin_m: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Whitened closest approach of every UAV to every moving ellipsoid zone.

    points (B, U, W, 3), times (B, U, W); zones Z with centre polylines zone_points (Z, H, 3),
    zone_times (Z, H), ellipsoid axes as rows of zone_rot (Z, 3, 3) and per leg semi-axes
    zone_axes (Z, H-1, 3) [m]; margin_m (B, U) is added to every semi-axis of the zone when
    checking that UAV. Returns (d (B, U, Z) with < 1 meaning inside, t (B, U, Z)).
    """
    n_b, n_u = points.shape[:2]
    n_z = len(zone_points)
    d_out = np.full((n_b, n_u, n_z), np.inf)
    t_out = np.zeros((n_b, n_u, n_z))
    t_lo, t_hi = times.min(), times.max()
    ta0, ta1 = times[..., :-1], times[..., 1:]
    for z in range(n_z):  # few zones (manned aircraft x motion modes)
        # only the zone legs that overlap the UAVs' time span matter
        legs = np.nonzero((zone_times[z, 1:] > t_lo) & (zone_times[z, :-1] < t_hi))[0]
        if not len(legs):
            continue
        sl = slice(legs[0], legs[-1] + 2)
        rot = zone_rot[z]
        zt = zone_times[z, sl]
        zp = zone_points[z, sl] @ rot.T
        axes = zone_axes[z, legs[0] : legs[-1] + 1]
        # per UAV leg only the zone legs that overlap it in time (zt[k] < ta1 and zt[k + 1] > ta0)
        first = np.clip(np.searchsorted(zt, ta0, side="right") - 1, 0, len(legs) - 1)
        last = np.clip(np.searchsorted(zt, ta1, side="left") - 1, 0, len(legs) - 1)
        _zone_kernel(points @ rot.T, times, zp, zt, axes, margin_m, first, last, d_out[..., z], t_out[..., z])
    return d_out, t_out


@compiled
def _zone_kernel(points, times, zp, zt, axes, margin_m, first, last, d_out, t_out) -> None:
    """Each UAV's whitened closest approach to one zone, in the zone's axis frame, over the zone
    legs ``first..last`` of each of its legs (the semi-axes grown by the UAV's margin): the first
    minimum and its time (with no approach at all, the first leg pair's)."""
    n_b, n_u, n_w, _ = points.shape
    for c in range(n_b):
        for u in range(n_u):
            p, t = points[c, u], times[c, u]
            _, when = _zone_leg_pair(p, t, 0, zp, zt, first[c, u, 0], axes, margin_m[c, u])
            best = np.inf
            for a in range(n_w - 1):
                for k in range(first[c, u, a], last[c, u, a] + 1):
                    dist, at = _zone_leg_pair(p, t, a, zp, zt, k, axes, margin_m[c, u])
                    if dist < best:
                        best, when = dist, at
            d_out[c, u], t_out[c, u] = best, when


@compiled
def _zone_leg_pair(p, t, a, zp, zt, k, axes, margin) -> tuple:
    """Closest approach of leg a of a UAV polyline (p, t) and leg k of a zone's centre, the
    relative motion divided by the zone's semi-axes plus margin: (distance, time)."""
    pa, va = _leg(p, t, a)
    pb, vb = _leg(zp, zt, k)
    lo, hi = max(t[a], zt[k]), min(t[a + 1], zt[k + 1])
    inv = (1.0 / (axes[k, 0] + margin), 1.0 / (axes[k, 1] + margin), 1.0 / (axes[k, 2] + margin))
    d0 = sub(along(pa, lo - t[a], va), along(pb, lo - zt[k], vb))
    dv = sub(va, vb)
    return _cpa_one(times_each(d0, inv), times_each(dv, inv), lo, hi, 0.0, vb)


def conflict_counts(
    n_uav: int,
    pairs: np.ndarray,
    pair_conflict: np.ndarray,
    zone_conflict: np.ndarray,
    zone_owner: np.ndarray,
) -> np.ndarray:
    """Conflicting-aircraft count per UAV (B, U) from pair flags (B, P) and zone flags (B, U, Z).

    A manned aircraft counts once however many of its motion-mode zones a UAV enters;
    ``zone_owner`` (Z,) gives the manned aircraft index of each zone.
    """
    n_b = pair_conflict.shape[0]
    counts = np.zeros((n_b, n_uav), dtype=int)
    if len(pairs):
        flags = pair_conflict.astype(int)
        np.add.at(counts, (slice(None), pairs[:, 0]), flags)
        np.add.at(counts, (slice(None), pairs[:, 1]), flags)
    if zone_conflict.shape[-1]:
        n_m = int(zone_owner.max()) + 1
        per_manned = np.zeros((n_b, n_uav, n_m), dtype=bool)
        for z, owner in enumerate(zone_owner):
            per_manned[..., owner] |= zone_conflict[..., z]
        counts += per_manned.sum(axis=-1)
    return counts
