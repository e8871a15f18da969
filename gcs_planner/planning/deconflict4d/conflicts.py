"""Conflict detection between timed polylines by analytic closest approach (CPA).

Two UAVs conflict when their distance drops below the separation at any common instant. Both
trajectories are piecewise linear in time, so over every pair of legs whose time windows
overlap the relative position is linear, ``d(s) = d0 + dv s`` for ``s in [0, T]``, and the
closest approach is exact: ``s* = clip(-d0.dv / |dv|^2, 0, T)``. No time step is needed, so
1 m separation at 10 m/s closing speed (which a 0.05 s sampling step would barely catch) is
handled exactly. Everything is vectorised over candidate solutions, pairs and leg pairs.

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

from gcs_planner.geometry.timing import closest_under_timing

__all__ = [
    "candidate_pairs",
    "closest_approach",
    "conflict_counts",
    "pair_closest_approach",
    "segment_closest_approach",
    "zone_closest_approach",
]

# elements of one (pairs x legs x legs) block before the work is split into chunks
_CHUNK_ELEMENTS = 2_000_000


def _cpa(d0: np.ndarray, dv: np.ndarray, span: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Min of |d0 + dv s| over s in [0, span] and its argmin s; arrays (..., 3), (...)."""
    vv = np.einsum("...i,...i->...", dv, dv)
    s = -np.einsum("...i,...i->...", d0, dv) / np.where(vv > 0, vv, 1.0)
    s = np.clip(np.where(vv > 0, s, 0.0), 0.0, span)
    d = d0 + dv * s[..., None]
    return np.sqrt(np.einsum("...i,...i->...", d, d)), s


def _velocity(p0: np.ndarray, p1: np.ndarray, t0: np.ndarray, t1: np.ndarray) -> np.ndarray:
    """Constant velocity of each leg (..., 3); 0 on a leg of zero duration."""
    dt = t1 - t0
    return np.where((dt > 0)[..., None], (p1 - p0) / np.where(dt > 0, dt, 1.0)[..., None], 0.0)


def _legs_cpa(
    pa0, ta0, ta1, va, pb0, tb0, tb1, vb, scale_b=None, timing_s: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """Closest approach of legs given by start point, time span and velocity; +inf without overlap.
    With ``timing_s`` the distance is the closest under any relative schedule error up to that
    (gcs_planner.geometry.timing: leg b moved along its velocity by up to ``vb timing_s``)."""
    lo = np.maximum(ta0, tb0)
    hi = np.minimum(ta1, tb1)
    valid = hi > lo
    d0 = (pa0 + va * (lo - ta0)[..., None]) - (pb0 + vb * (lo - tb0)[..., None])
    dv = va - vb
    if scale_b is not None:
        inv = 1.0 / scale_b
        d0, dv = d0 * inv, dv * inv
    span = np.where(valid, hi - lo, 0.0)
    dist, s = _cpa(d0, dv, span)
    if timing_s > 0:
        dist = closest_under_timing(d0, dv * span[..., None], vb * timing_s)
    return np.where(valid, dist, np.inf), lo + s


def segment_closest_approach(
    pa0: np.ndarray,
    pa1: np.ndarray,
    ta0: np.ndarray,
    ta1: np.ndarray,
    pb0: np.ndarray,
    pb1: np.ndarray,
    tb0: np.ndarray,
    tb1: np.ndarray,
    scale_b: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Closest approach of leg a (pa0 at ta0 -> pa1 at ta1) and leg b over their common time.

    Points (..., 3), times (...), all broadcast; ``scale_b`` (..., 3) divides the relative
    position axis by axis (ellipsoid semi-axes). Returns (distance, time); +inf without overlap.
    """
    va, vb = _velocity(pa0, pa1, ta0, ta1), _velocity(pb0, pb1, tb0, tb1)
    return _legs_cpa(pa0, ta0, ta1, va, pb0, tb0, tb1, vb, scale_b)


def closest_approach(
    pa: np.ndarray, ta: np.ndarray, pb: np.ndarray, tb: np.ndarray, scale_b: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Minimum distance between two timed polylines over their common time, and when.

    pa (..., Wa, 3), ta (..., Wa); pb (..., Wb, 3), tb (..., Wb); leading axes broadcast.
    Optional ``scale_b`` (..., Wb-1, 3): per leg of b, divide the relative position by it axis by
    axis (ellipsoid semi-axes in a frame where the ellipsoid is axis-aligned; 1 = on its surface).
    Returns (d_min (...), t_min (...)); d_min is +inf when the time spans never overlap.
    """
    dist, t = segment_closest_approach(
        pa[..., :-1, None, :],
        pa[..., 1:, None, :],
        ta[..., :-1, None],
        ta[..., 1:, None],
        pb[..., None, :-1, :],
        pb[..., None, 1:, :],
        tb[..., None, :-1],
        tb[..., None, 1:],
        None if scale_b is None else scale_b[..., None, :, :],
    )
    flat = dist.reshape(*dist.shape[:-2], -1)
    k = np.argmin(flat, axis=-1)[..., None]
    t_flat = t.reshape(flat.shape)
    return np.take_along_axis(flat, k, axis=-1)[..., 0], np.take_along_axis(t_flat, k, axis=-1)[..., 0]


def candidate_pairs(points: np.ndarray, times: np.ndarray, reach_m: np.ndarray) -> np.ndarray:
    """UAV pairs (P, 2), i < j, whose space-time boxes come within reach in ANY candidate.

    points (B, U, W, 3), times (B, U, W); reach_m (B, U) is how far each UAV's own influence
    extends (half the separation plus its corner deviation margin).
    """
    lo = points.min(axis=2) - reach_m[..., None]
    hi = points.max(axis=2) + reach_m[..., None]
    t_lo, t_hi = times.min(axis=2), times.max(axis=2)
    overlap = (t_lo[:, :, None] < t_hi[:, None, :]) & (t_lo[:, None, :] < t_hi[:, :, None])
    for ax in range(3):  # axis by axis: a reduction over a last axis of 3 is slow
        a_lo, a_hi = lo[..., ax], hi[..., ax]
        overlap &= (a_lo[:, :, None] <= a_hi[:, None, :]) & (a_lo[:, None, :] <= a_hi[:, :, None])
    i, j = np.nonzero(np.triu(overlap.any(axis=0), k=1))
    return np.stack([i, j], axis=1)


def pair_closest_approach(
    points: np.ndarray,
    times: np.ndarray,
    pairs: np.ndarray,
    reach_m: np.ndarray | None = None,
    timing_s: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Closest approach (B, P) distance [m] and time [s] for the given UAV pairs (P, 2); with
    ``timing_s`` the distance under any relative schedule error up to that (``_legs_cpa``).

    With ``reach_m`` (U,) only leg pairs whose space-time boxes (over all B candidates) come
    within ``reach_i + reach_j`` are computed; the others report +inf, which is exact for every
    question "closer than reach_i + reach_j?". Without it every leg pair is computed.
    """
    n_b, _, n_w, _ = points.shape
    n_p = len(pairs)
    d_min = np.full((n_b, n_p), np.inf)
    t_min = np.zeros((n_b, n_p))
    if not n_p:
        return d_min, t_min
    p0, p1 = points[:, :, :-1], points[:, :, 1:]
    t0, t1 = times[:, :, :-1], times[:, :, 1:]
    vel = _velocity(p0, p1, t0, t1)  # once per leg, not per leg pair
    if reach_m is None:
        keep = np.ones((n_p, n_w - 1, n_w - 1), dtype=bool)
    else:
        lo = np.minimum(p0, p1).min(axis=0)  # (U, S, 3) leg boxes over all candidates
        hi = np.maximum(p0, p1).max(axis=0)
        tlo, thi = t0.min(axis=0), t1.max(axis=0)
        keep = np.zeros((n_p, n_w - 1, n_w - 1), dtype=bool)
        step = max(1, _CHUNK_ELEMENTS // (3 * (n_w - 1) ** 2))
        for start in range(0, n_p, step):
            i, j = pairs[start : start + step, 0], pairs[start : start + step, 1]
            r = (reach_m[i] + reach_m[j])[:, None, None]
            near = (tlo[i][:, :, None] < thi[j][:, None, :]) & (tlo[j][:, None, :] < thi[i][:, :, None])
            for ax in range(3):
                lo_i, lo_j, hi_i, hi_j = lo[i, :, ax], lo[j, :, ax], hi[i, :, ax], hi[j, :, ax]
                near &= (lo_i[:, :, None] - r <= hi_j[:, None, :]) & (
                    lo_j[:, None, :] - r <= hi_i[:, :, None]
                )
            keep[start : start + step] = near
    k_p, k_a, k_b = np.nonzero(keep)  # sorted by pair
    if not len(k_p):
        return d_min, t_min
    step = max(1, _CHUNK_ELEMENTS // max(1, n_b))
    dist = np.empty((n_b, len(k_p)))
    when = np.empty((n_b, len(k_p)))
    for start in range(0, len(k_p), step):
        sl = slice(start, start + step)
        i, j, a, b = pairs[k_p[sl], 0], pairs[k_p[sl], 1], k_a[sl], k_b[sl]
        dist[:, sl], when[:, sl] = _legs_cpa(
            p0[:, i, a],
            t0[:, i, a],
            t1[:, i, a],
            vel[:, i, a],
            p0[:, j, b],
            t0[:, j, b],
            t1[:, j, b],
            vel[:, j, b],
            timing_s=timing_s,
        )
    starts = np.flatnonzero(np.r_[True, k_p[1:] != k_p[:-1]])
    group = k_p[starts]
    best = np.minimum.reduceat(dist, starts, axis=1)
    counts = np.diff(np.r_[starts, len(k_p)])
    at_best = dist == np.repeat(best, counts, axis=1)
    d_min[:, group] = best
    t_min[:, group] = np.maximum.reduceat(np.where(at_best, when, -np.inf), starts, axis=1)
    return d_min, t_min


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
    for z in range(n_z):  # few zones (manned aircraft x motion modes); vectorised inside
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
        width = max(int((last - first).max()) + 1, 1)
        k = first[..., None] + np.arange(width)
        overlap = k <= last[..., None]
        k = np.minimum(k, len(legs) - 1)
        pts = (points @ rot.T)[..., None, :]
        dist, t = segment_closest_approach(
            pts[..., :-1, :, :],
            pts[..., 1:, :, :],
            ta0[..., None],
            ta1[..., None],
            zp[k],
            zp[k + 1],
            zt[k],
            zt[k + 1],
            axes[k] + margin_m[..., None, None, None],
        )
        flat = np.where(overlap, dist, np.inf).reshape(n_b, n_u, -1)
        best = np.argmin(flat, axis=-1)[..., None]
        d_out[..., z] = np.take_along_axis(flat, best, axis=-1)[..., 0]
        t_out[..., z] = np.take_along_axis(t.reshape(flat.shape), best, axis=-1)[..., 0]
    return d_out, t_out


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
