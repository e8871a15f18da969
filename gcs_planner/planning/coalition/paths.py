"""Coalition paths (section 4.2): entry poses, timed Dubins arrivals, recon / assessment arcs, threat avoidance.

Built on gcs_planner.geometry.dubins (``word_lengths``, ``DubinsPath``). Two thin, batched additions
live here because the coalition planner calls them for every bidder and member inside the
0.05 s compute budget (the library's scalar versions take ~0.1 s per call):
- ``free_heading_lengths``: shortest length to a point with free terminal heading (bid ETA,
  eq. 23), batched: the analytic CS tangent length for both turn directions; a goal inside a
  turning circle falls back to a 72-heading sweep of all six words.
- ``stretch_batch``: paths of exact given lengths for many members at once (simultaneous /
  staggered arrival, ref [28]): both radii scale by one factor k >= 1 (scan of k, then batched
  bisection); when no k <= k_max reaches the length, whole loiter loops are added on the start
  circle (loiter fallback), as in the library's ``stretch_to_length``.

Geometry conventions (model.py): a strike entry pose is the stand-off point L^s from the target at
the attack bearing, heading to the target; recon and assessment arcs start on their circle
(C^r, C^e) at the start bearing, heading tangent counter-clockwise.

Threat avoidance (eq. 17): threats are circles known at planning time. When the shortest path
enters one, the safe circle D (r_D = kappa r_T) gives two safe points, P1/P2 = centre +- r_D n,
n normal to the start-goal chord; the one nearer the original path is used, heading along the
chord (tangent to D there), and the path becomes start -> safe pose -> goal (two Dubins
segments, recursively for further threats, depth <= 3; the other safe point and larger kappa are
tried when the first choice still intersects). Stretching for timing is applied to the last
segment, else the first; every returned leg is re-checked against the threats and the check's
result is reported.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gcs_planner.geometry.dubins import WORDS, DubinsPath, word_lengths
from gcs_planner.planning.coalition.model import Threat
from gcs_planner.planning.coalition.track import Leg

__all__ = [
    "arc_leg",
    "arc_start_pose",
    "clearance_m",
    "entry_poses",
    "free_heading_lengths",
    "min_route",
    "shortest_lengths",
    "stretch_batch",
    "timed_route",
]

TWO_PI = 2.0 * math.pi
K_MAX = 4.0  # largest radius stretch factor before loiter loops are added


def entry_poses(target_xy, angles_rad, standoff_m: float) -> np.ndarray:
    """(K, 3) stand-off poses at attack bearings angles_rad, heading towards the target."""
    a = np.asarray(angles_rad, dtype=float)
    return np.column_stack(
        [target_xy[0] + standoff_m * np.cos(a), target_xy[1] + standoff_m * np.sin(a), a + math.pi]
    )


def arc_start_pose(centre_xy, angle_rad, radius_m: float) -> np.ndarray:
    """(K, 3) poses on a circle about centre at bearings angle_rad, heading tangent CCW."""
    a = np.atleast_1d(np.asarray(angle_rad, dtype=float))
    return np.column_stack(
        [centre_xy[0] + radius_m * np.cos(a), centre_xy[1] + radius_m * np.sin(a), a + math.pi / 2]
    )


def shortest_lengths(q0: np.ndarray, q1: np.ndarray, r_m) -> np.ndarray:
    """Shortest Dubins length [m] for N pose pairs, equal radius r_m (scalar or (N,))."""
    return word_lengths(q0, q1, r_m, r_m).sum(axis=2).min(axis=1)


def free_heading_lengths(q0: np.ndarray, goal_xy: np.ndarray, r_m) -> np.ndarray:
    """Shortest length [m] from poses q0 (N, 3) to points goal_xy (N, 2) or (2,), any end heading."""
    q0 = np.atleast_2d(np.asarray(q0, dtype=float))
    n = len(q0)
    g = np.broadcast_to(np.asarray(goal_xy, dtype=float), (n, 2))
    r = np.broadcast_to(np.asarray(r_m, dtype=float), (n,))
    best = np.full(n, np.inf)
    for s in (1.0, -1.0):
        c = np.column_stack([q0[:, 0] - s * r * np.sin(q0[:, 2]), q0[:, 1] + s * r * np.cos(q0[:, 2])])
        d = g - c
        dist = np.hypot(d[:, 0], d[:, 1])
        ok = dist >= r
        tangent = np.sqrt(np.maximum(dist**2 - r**2, 0.0))
        h_leave = np.arctan2(d[:, 1], d[:, 0]) + s * np.arcsin(np.clip(r / np.maximum(dist, 1e-9), -1, 1))
        arc = np.mod(s * (h_leave - q0[:, 2]), TWO_PI) * r
        best = np.where(ok, np.minimum(best, arc + tangent), best)
    inside = ~np.isfinite(best)
    if inside.any():
        h = np.linspace(-math.pi, math.pi, 72, endpoint=False)
        qi, gi, ri = q0[inside], g[inside], r[inside]
        m = len(qi)
        q1 = np.column_stack([np.repeat(gi, len(h), 0), np.tile(h, m)])
        lens = shortest_lengths(np.repeat(qi, len(h), 0), q1, np.repeat(ri, len(h)))
        best[inside] = lens.reshape(m, len(h)).min(1)
    return best


def _path(q0, word_i: int, seg: np.ndarray, r0: float, r1: float) -> DubinsPath:
    word = WORDS[word_i]
    return DubinsPath(
        start=tuple(float(v) for v in q0),
        word=word,
        lengths=tuple(float(v) for v in seg),
        radii=(float(r0), math.inf if word[1] == "S" else float(min(r0, r1)), float(r1)),
    )


def stretch_batch(
    q0: np.ndarray, q1: np.ndarray, length_m: np.ndarray, r_m: np.ndarray
) -> list[DubinsPath | None]:
    """Dubins paths q0[i] -> q1[i] of exactly length_m[i] with radius k r_m[i] (k >= 1) plus loops.

    None where length_m[i] is shorter than the shortest path (more than 1 mm).
    """
    q0, q1 = np.atleast_2d(q0).astype(float), np.atleast_2d(q1).astype(float)
    length_m, r_m = np.atleast_1d(length_m).astype(float), np.broadcast_to(np.asarray(r_m, float), len(q0))
    n = len(q0)
    ks = np.geomspace(1.0, K_MAX, 120)
    nk = len(ks)
    table = (
        word_lengths(np.repeat(q0, nk, 0), np.repeat(q1, nk, 0), np.tile(ks, n) * np.repeat(r_m, nk))
        .sum(2)
        .reshape(n, nk, 6)
    )  # (n, k, word)
    out: list[DubinsPath | None] = [None] * n
    lo_k, hi_k, word, loops = np.ones(n), np.ones(n), np.zeros(n, int), np.zeros(n)
    solved = np.zeros(n, bool)
    for i in range(n):
        shortest = table[i, 0].min()
        if length_m[i] < shortest - 1e-3:
            continue
        if length_m[i] <= shortest + 1e-6:
            w = int(table[i, 0].argmin())
            out[i] = _path(q0[i], w, word_lengths(q0[i], q1[i], r_m[i])[0, w], r_m[i], r_m[i])
            continue
        loop_len = TWO_PI * r_m[i] * ks
        n_loops = 0
        while True:
            f = table[i] + n_loops * loop_len[:, None] - length_m[i]  # (k, word)
            cross = np.isfinite(f[:-1]) & np.isfinite(f[1:]) & (f[:-1] < 0) & (f[1:] >= 0)
            # reject jumps: an arc wrapping 0 <-> 2 pi changes the length by about 2 pi r
            with np.errstate(invalid="ignore"):
                jump = np.abs(f[1:] - f[:-1]) > math.pi * r_m[i] * ks[1:, None]
            cross &= ~jump
            if cross.any():
                ki, w = np.argwhere(cross)[np.argmin(np.argwhere(cross)[:, 0])]
                lo_k[i], hi_k[i], word[i], loops[i] = ks[ki], ks[ki + 1], w, n_loops
                solved[i] = True
                break
            n_loops += 1
            if n_loops > 200:
                break
    idx = np.flatnonzero(solved)
    if len(idx):
        lo, hi = lo_k[idx], hi_k[idx]
        for _ in range(50):  # batched bisection on k for all members at once
            mid = 0.5 * (lo + hi)
            seg = word_lengths(q0[idx], q1[idx], mid * r_m[idx])[np.arange(len(idx)), word[idx]]
            f = seg.sum(1) + loops[idx] * TWO_PI * r_m[idx] * mid - length_m[idx]
            below = f < 0
            lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
        k = hi
        seg = word_lengths(q0[idx], q1[idx], k * r_m[idx])[np.arange(len(idx)), word[idx]].copy()
        seg[:, 0] += loops[idx] * TWO_PI * r_m[idx] * k
        for j, i in enumerate(idx):
            out[i] = _path(q0[i], word[i], seg[j], k[j] * r_m[i], k[j] * r_m[i])
    return out


def clearance_m(xy: np.ndarray, threats: list[Threat]) -> float:
    """Smallest distance from the points to any threat boundary [m] (negative = inside; inf if none)."""
    if not threats:
        return math.inf
    c = np.array([[t.x, t.y] for t in threats])
    r = np.array([t.radius_m for t in threats])
    d = np.hypot(xy[:, None, 0] - c[None, :, 0], xy[:, None, 1] - c[None, :, 1]) - r
    return float(d.min())


def _samples(path: DubinsPath, ds_m: float) -> np.ndarray:
    return path.sample_step(ds_m)[1]


def _first_violated(xy: np.ndarray, threats: list[Threat]) -> Threat | None:
    for i in range(len(xy)):
        for t in threats:
            if math.hypot(xy[i, 0] - t.x, xy[i, 1] - t.y) < t.radius_m:
                return t
    return None


def _shortest(q0, q1, r: float) -> DubinsPath:
    lens = word_lengths(q0, q1, r)[0]
    w = int(lens.sum(1).argmin())
    return _path(q0, w, lens[w], r, r)


@dataclass
class Route:
    """A chain of poses (start, safe poses..., goal) whose shortest Dubins links clear the threats."""

    poses: list[np.ndarray]
    r_m: float
    length_m: float
    clear: bool
    centres: list[np.ndarray | None] | None = None  # threat centre of each pose (None: start/goal)

    def pushed(self, sigma: float) -> list[np.ndarray]:
        """Poses with every safe point moved radially away from its threat by factor sigma."""
        out = []
        for q, c in zip(self.poses, self.centres or [None] * len(self.poses)):
            if c is None:
                out.append(q)
            else:
                out.append(np.array([*(c + sigma * (q[:2] - c)), q[2]]))
        return out


def _route_length(poses, r) -> float:
    return float(sum(_shortest(a, b, r).length for a, b in zip(poses[:-1], poses[1:])))


def min_route(
    q0, q1, r_m: float, threats: list[Threat], kappa: float, ds_m: float = 10.0, depth: int = 3
) -> Route:
    """Shortest route start -> goal around the threats by safe-point two-segment Dubins paths."""
    q0, q1 = np.asarray(q0, float), np.asarray(q1, float)
    xy = _samples(_shortest(q0, q1, r_m), ds_m)[:, :2]
    hit = _first_violated(xy, threats)
    if hit is None:
        return Route([q0, q1], r_m, _route_length([q0, q1], r_m), True, [None, None])
    if depth == 0:
        return Route([q0, q1], r_m, _route_length([q0, q1], r_m), False)
    chord = q1[:2] - q0[:2]
    d = chord / max(np.hypot(*chord), 1e-9)
    n = np.array([-d[1], d[0]])
    centre = np.array([hit.x, hit.y])
    best: Route | None = None
    for k in (kappa, kappa * 1.3, kappa * 1.7):
        rd = k * hit.radius_m
        cands = [centre + rd * n, centre - rd * n]
        cands.sort(key=lambda p: float(np.min(np.hypot(*(xy - p).T))))  # nearer the original path first
        for p in cands:
            safe = np.array([p[0], p[1], math.atan2(d[1], d[0])])
            a = min_route(q0, safe, r_m, threats, kappa, ds_m, depth - 1)
            b = min_route(safe, q1, r_m, threats, kappa, ds_m, depth - 1)
            centres = [*a.centres[:-1], centre, *b.centres[1:]]
            route = Route(a.poses + b.poses[1:], r_m, a.length_m + b.length_m, a.clear and b.clear, centres)
            if route.clear and (best is None or route.length_m < best.length_m):
                best = route
        if best is not None:
            return best
    return Route([q0, q1], r_m, _route_length([q0, q1], r_m), False, [None, None])


def timed_route(
    route: Route, length_m: float, threats: list[Threat], ds_m: float = 10.0
) -> tuple[list[DubinsPath], bool]:
    """Dubins segments along `route` of total length_m (stretching one link); and whether they clear."""
    links = [_shortest(a, b, route.r_m) for a, b in zip(route.poses[:-1], route.poses[1:])]
    extra = length_m - sum(p.length for p in links)
    if extra <= 1e-6:
        return links, route.clear
    fallback = None
    for j in [len(links) - 1, *range(len(links) - 1)]:
        a, b = route.poses[j], route.poses[j + 1]
        p = stretch_batch(a[None], b[None], np.array([links[j].length + extra]), np.array([route.r_m]))[0]
        if p is None:
            continue
        trial = links[:j] + [p] + links[j + 1 :]
        ok = clearance_m(_samples(p, ds_m)[:, :2], threats) >= 0.0
        if ok:
            return trial, route.clear
        fallback = fallback or trial
    if len(route.poses) > 2:  # lengthen by pushing the safe points outwards (larger kappa), bisected
        lo, hi = 1.0, 1.0
        while hi < 8.0 and _route_length(route.pushed(hi), route.r_m) < length_m:
            hi *= 1.5
        if _route_length(route.pushed(hi), route.r_m) >= length_m:
            for _ in range(40):
                mid = 0.5 * (lo + hi)
                lo, hi = (mid, hi) if _route_length(route.pushed(mid), route.r_m) < length_m else (lo, mid)
            poses = route.pushed(lo)
            links = [_shortest(a, b, route.r_m) for a, b in zip(poses[:-1], poses[1:])]
            rest = length_m - sum(p.length for p in links)
            p = stretch_batch(
                poses[-2][None], poses[-1][None], np.array([links[-1].length + rest]), np.array([route.r_m])
            )[0]
            if p is not None:
                trial = [*links[:-1], p]
                xy = np.concatenate([_samples(q, ds_m)[:, :2] for q in trial])
                if clearance_m(xy, threats) >= 0.0:
                    return trial, True
    return (fallback or links), False


def sample_segments(
    paths: list[DubinsPath], t0_s: float, speed_mps: float, ds_m: float, kind: str, info=None
) -> Leg:
    """Sample a chain of Dubins paths at <= ds_m into a timed Leg starting at t0_s."""
    pts, s_off = [], 0.0
    ss = []
    for i, p in enumerate(paths):
        s, q = p.sample_step(ds_m)
        if i:
            s, q = s[1:], q[1:]
        pts.append(q)
        ss.append(s + s_off)
        s_off += p.length
    q = np.concatenate(pts)
    s = np.concatenate(ss)
    return Leg(t0_s + s / speed_mps, q[:, :2], q[:, 2], kind, dict(info or {}))


def arc_leg(
    centre_xy,
    radius_m: float,
    start_rad: float,
    t0_s: float,
    duration_s: float,
    speed_mps: float,
    ds_m: float,
    kind: str,
    info=None,
) -> Leg:
    """CCW arc of radius_m about centre from bearing start_rad, flown for duration_s (eq. 16 arcs)."""
    length = speed_mps * duration_s
    n = max(2, int(math.ceil(length / ds_m)) + 1)
    s = np.linspace(0.0, length, n)
    th = start_rad + s / radius_m
    xy = np.column_stack([centre_xy[0] + radius_m * np.cos(th), centre_xy[1] + radius_m * np.sin(th)])
    return Leg(t0_s + s / speed_mps, xy, th + math.pi / 2, kind, dict(info or {}))
