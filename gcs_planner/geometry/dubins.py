"""Dubins paths in the plane: six words, unequal start/end radii, free end heading, stretching, 3-D lift.

A pose is ``(x_m, y_m, heading_rad)`` with heading CCW from east (ENU). A Dubins path is three
segments (arc, straight or arc, arc); ``L`` turns left (CCW, signed curvature +1/r), ``R`` right.

Method (why it is general rather than the textbook normalised formulas):
- Every word is built from circle geometry, so the start circle (radius ``r0``) and the end
  circle (radius ``r1``) may differ (needed by the coalition planner, seed 003 eq. 18).
- CSC words (LSL, RSR, LSR, RSL): the generalised common-tangent construction. With turn signs
  s0, s1 (+1 for L, -1 for R) and centres c0, c1, a tangent of direction u leaves circle 0 at
  ``c0 - s0 r0 left(u)`` and meets circle 1 at ``c1 - s1 r1 left(u)``; hence
  ``D . left(u) = s1 r1 - s0 r0`` and the straight length is ``D . u`` with D = c1 - c0. This has
  exactly one solution when ``|s1 r1 - s0 r0| <= |D|`` (outer tangents for equal turn signs,
  inner tangents otherwise), so unequal radii are exact for CSC words.
- CCC words (LRL, RLR): the middle circle (radius ``r_mid``, default ``min(r0, r1)``) touches
  both end circles externally: ``|cm - c0| = r0 + r_mid``, ``|cm - c1| = r1 + r_mid``. Both
  intersection points (either side of c0 -> c1) are tried and the shorter kept, so unequal radii
  are exact for CCC words too.
- Arc angles are taken modulo 2 pi; an angle within ``_ANGLE_EPS`` of 2 pi is treated as 0 (a
  pose already on the tangent must not produce a spurious full circle).
- ``word_lengths`` takes a batch of N problems and is compiled (numba), one problem at a time:
  the planners make many calls on small batches (the coalition planner hundreds per formation, the
  priority swarm one per cost evaluation), where numpy passes were mostly call overhead; invalid
  words get length inf. Its arithmetic is the earlier vectorised code's, term for term.

Free terminal heading (shortest path to a point): the optimum is a CS path (or a CC path when the
point is inside a turning circle). We evaluate the analytic CS tangent headings for both turn
directions plus a sweep of ``n_headings`` end headings over all six words, then refine the best
few headings with a bounded scalar search; the result is never longer than any swept heading. For
a point inside a turning circle the optimum often sits where an arc of a CCC word vanishes (a CC
path, a jump in the swept length), so the analytic CC headings (third arc zero, or first arc zero
so the middle circle starts at q0) are candidates too.

Stretching (simultaneous arrival, seed 003): ``stretch_to_length`` scales both radii by one factor
``k >= 1`` (so ``r0 : r1`` is kept) and solves ``L_word(k) + n 2 pi k r0 = target`` by a scan over
k and Brent's method per word, adding ``n`` full loiter loops on the first circle only when no
radius alone reaches the target. The returned path's length matches the target to ``tol_m``.

3-D lift: altitude is linear in horizontal arc length from z0 to z1, so the climb angle is constant
``atan(|z1 - z0| / L)``; ``lift`` reports by how much it exceeds the limit (the caller decides to
stretch, e.g. with ``min_length_for_climb`` and ``stretch_to_length``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq, minimize_scalar

from gcs_planner.core.compiled import compiled
from gcs_planner.core.geo import wrap_pi

__all__ = [
    "WORDS",
    "DubinsPath",
    "advance",
    "segment_starts",
    "LiftedPath",
    "lift",
    "min_length_for_climb",
    "sample_batch",
    "shortest_batch",
    "shortest_path",
    "shortest_path_free_heading",
    "stretch_to_length",
    "word_lengths",
]

WORDS = ("LSL", "RSR", "LSR", "RSL", "RLR", "LRL")
_SIGN = {"L": 1.0, "R": -1.0, "S": 0.0}
_WORD_SIGNS = np.array([[_SIGN[c] for c in w] for w in WORDS])
_TWO_PI = 2.0 * math.pi
_ANGLE_EPS = 1e-9


@dataclass(frozen=True)
class DubinsPath:
    """A planar Dubins path: start pose, word, segment lengths [m] and segment radii [m] (inf for S).

    ``lengths`` may exceed one full circle on an arc (loiter loops added by stretching).
    """

    start: tuple[float, float, float]
    word: str
    lengths: tuple[float, float, float]
    radii: tuple[float, float, float]

    @property
    def length(self) -> float:
        """Total horizontal length [m] (sum of the three segment lengths)."""
        return float(sum(self.lengths))

    @property
    def end(self) -> tuple[float, float, float]:
        """End pose reached by integrating the segments (x, y, heading wrapped to (-pi, pi])."""
        x, y, h = self.sample(np.array([self.length]))[0]
        return float(x), float(y), float(h)

    def curvatures(self) -> np.ndarray:
        """Signed curvature per segment [1/m] (+ left, - right, 0 straight)."""
        return np.array([_SIGN[c] / r if c != "S" else 0.0 for c, r in zip(self.word, self.radii)])

    def segment_starts(self) -> np.ndarray:
        """(4, 3) poses at the start of each segment and at the end (heading unwrapped)."""
        poses = np.empty((4, 3))
        poses[0] = self.start
        for i, (kappa, ds) in enumerate(zip(self.curvatures(), self.lengths)):
            poses[i + 1] = _advance(poses[i], kappa, ds)
        return poses

    def sample(self, s_m: np.ndarray) -> np.ndarray:
        """Poses (n, 3) at arc lengths ``s_m`` [m] (clipped to [0, length]); vectorised over s."""
        s = np.clip(np.asarray(s_m, dtype=float).reshape(-1), 0.0, self.length)
        poses = self.segment_starts()
        bounds = np.cumsum(self.lengths)
        seg = np.minimum(np.searchsorted(bounds, s, side="left"), 2)
        seg_start_s = np.concatenate([[0.0], bounds[:2]])[seg]
        out = advance(poses[seg], self.curvatures()[seg], s - seg_start_s)
        out[:, 2] = wrap_pi(out[:, 2])
        return out

    def sample_step(self, step_m: float) -> tuple[np.ndarray, np.ndarray]:
        """Arc lengths (n,) every <= step_m, always including both ends, and the poses (n, 3) there."""
        n = max(1, math.ceil(self.length / step_m))
        s = np.linspace(0.0, self.length, n + 1)
        return s, self.sample(s)


@dataclass(frozen=True)
class LiftedPath:
    """A Dubins path with altitude linear in horizontal arc length from z0_m to z1_m."""

    path: DubinsPath
    z0_m: float
    z1_m: float
    climb_rad: float
    climb_violation_rad: float

    @property
    def length_3d(self) -> float:
        """Flown 3-D length [m]: horizontal length / cos(climb)."""
        return math.hypot(self.path.length, self.z1_m - self.z0_m)

    def sample(self, s_m: np.ndarray) -> np.ndarray:
        """Points (n, 4) = x, y, z, heading at horizontal arc lengths s_m [m]."""
        s = np.clip(np.asarray(s_m, dtype=float).reshape(-1), 0.0, self.path.length)
        xyh = self.path.sample(s)
        frac = s / self.path.length if self.path.length > 0 else np.ones_like(s)
        z = self.z0_m + (self.z1_m - self.z0_m) * frac
        return np.column_stack([xyh[:, :2], z, xyh[:, 2]])


def lift(path: DubinsPath, z0_m: float, z1_m: float, max_climb_rad: float) -> LiftedPath:
    """Lift a planar path to 3-D and report the climb-angle violation [rad] (0 if within limit)."""
    dz = abs(z1_m - z0_m)
    climb = math.atan2(dz, path.length) if dz > 0 else 0.0
    return LiftedPath(path, float(z0_m), float(z1_m), climb, max(0.0, climb - max_climb_rad))


def min_length_for_climb(dz_m: float, max_climb_rad: float) -> float:
    """Shortest horizontal length [m] that climbs |dz_m| within the climb-angle limit."""
    return abs(dz_m) / math.tan(max_climb_rad)


def word_lengths(
    q0: np.ndarray,
    q1: np.ndarray,
    r0: np.ndarray | float,
    r1: np.ndarray | float | None = None,
    r_mid: np.ndarray | float | None = None,
) -> np.ndarray:
    """Segment lengths (N, 6, 3) [m] of every word in WORDS for N problems (inf where a word is invalid).

    q0, q1: (N, 3) or (3,) start and end poses; r0, r1: start/end circle radii [m] (r1 defaults
    to r0); r_mid: radius of the middle circle of CCC words (default min(r0, r1)).
    """
    q0 = np.atleast_2d(np.asarray(q0, dtype=float))
    q1 = np.atleast_2d(np.asarray(q1, dtype=float))
    n = max(len(q0), len(q1), *(np.size(r) for r in (r0, r1, r_mid) if r is not None))
    q0, q1 = _rows(q0, (n, 3)), _rows(q1, (n, 3))
    r0 = _rows(np.asarray(r0, dtype=float), (n,))
    r1 = r0 if r1 is None else _rows(np.asarray(r1, dtype=float), (n,))
    rm = np.minimum(r0, r1) if r_mid is None else _rows(np.asarray(r_mid, dtype=float), (n,))
    if ((rm if r_mid is None else np.minimum(np.minimum(r0, r1), rm)) <= 0).any():
        raise ValueError(f"Dubins radii must be > 0, got r0={r0.min()}, r1={r1.min()}, r_mid={rm.min()}")
    out = np.empty((n, 6, 3))
    _word_lengths(q0, q1, r0, r1, rm, out)
    return out


def shortest_batch(
    q0: np.ndarray, q1: np.ndarray, r0: np.ndarray | float, r1: np.ndarray | float | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Shortest word of N problems at once: word index into WORDS (N,), lengths (N, 3), radii (N, 3).

    Rows with no valid word (cannot happen for CSC words with equal radii) get lengths inf.
    """
    seg = word_lengths(q0, q1, r0, r1)
    n = len(seg)
    r0 = np.broadcast_to(np.asarray(r0, dtype=float), (n,))
    r1 = r0 if r1 is None else np.broadcast_to(np.asarray(r1, dtype=float), (n,))
    best, lengths, radii = np.empty(n, dtype=np.intp), np.empty((n, 3)), np.empty((n, 3))
    _pick_shortest(seg, r0, r1, best, lengths, radii)
    return best, lengths, radii


def sample_batch(
    q0: np.ndarray, word: np.ndarray, lengths: np.ndarray, radii: np.ndarray, s_m: np.ndarray
) -> np.ndarray:
    """Poses (N, K, 3) of N paths at arc lengths s_m (N, K) [m], clipped to each path; vectorised.

    q0 (N, 3) start poses, word (N,) indices into WORDS, lengths (N, 3), radii (N, 3) as returned by
    shortest_batch. Headings are not wrapped.
    """
    starts, kappa = segment_starts(q0, word, lengths, radii)
    bounds = np.cumsum(lengths, axis=1)
    s = np.clip(np.asarray(s_m, dtype=float), 0.0, bounds[:, 2:3])
    seg = (s > bounds[:, 0:1]).astype(int) + (s > bounds[:, 1:2])
    seg_start = np.concatenate([np.zeros((len(starts), 1)), bounds[:, :2]], axis=1)
    rows = np.broadcast_to(np.arange(len(starts))[:, None], s.shape)
    ds = s - seg_start[rows, seg]
    out = advance(starts[rows, seg].reshape(-1, 3), kappa[rows, seg].ravel(), ds.ravel())
    return out.reshape(*s.shape, 3)


def segment_starts(
    q0: np.ndarray, word: np.ndarray, lengths: np.ndarray, radii: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Start pose of each segment (N, 3, 3) and signed curvature per segment (N, 3) [1/m]."""
    q0 = np.asarray(q0, dtype=float)
    starts, kappa = np.empty((len(q0), 3, 3)), np.empty((len(q0), 3))
    _segment_starts(q0, np.asarray(word), np.asarray(lengths, dtype=float), radii, starts, kappa)
    return starts, kappa


def shortest_path(
    q0: tuple[float, float, float],
    q1: tuple[float, float, float],
    r0_m: float,
    r1_m: float | None = None,
    r_mid_m: float | None = None,
    words: tuple[str, ...] = WORDS,
) -> DubinsPath:
    """Shortest Dubins path among ``words`` from pose q0 to pose q1 with start/end radii r0_m, r1_m."""
    r1_m = r0_m if r1_m is None else r1_m
    r_mid_m = min(r0_m, r1_m) if r_mid_m is None else r_mid_m
    lengths = word_lengths(np.asarray(q0), np.asarray(q1), r0_m, r1_m, r_mid_m)[0]
    allowed = np.array([w in words for w in WORDS])
    totals = np.where(allowed, lengths.sum(axis=1), np.inf)
    best = int(np.argmin(totals))
    if not np.isfinite(totals[best]):
        raise ValueError(f"no Dubins path among {words} from {q0} to {q1} (r0={r0_m}, r1={r1_m})")
    return _make(q0, WORDS[best], lengths[best], r0_m, r1_m, r_mid_m)


def shortest_path_free_heading(
    q0: tuple[float, float, float],
    goal_xy: tuple[float, float],
    r0_m: float,
    r1_m: float | None = None,
    n_headings: int = 360,
    refine: int = 2,
) -> DubinsPath:
    """Shortest Dubins path from pose q0 to the point goal_xy with any terminal heading.

    Sweeps n_headings end headings (plus the analytic CS tangents) and refines the ``refine`` best.
    """
    r1_m = r0_m if r1_m is None else r1_m
    x0, y0, h0 = (float(v) for v in q0)
    gx, gy = float(goal_xy[0]), float(goal_xy[1])
    headings = list(np.linspace(-math.pi, math.pi, n_headings, endpoint=False))
    for s in (1.0, -1.0):  # analytic CS tangent heading from each start circle to the point
        c = np.array([x0 - s * r0_m * math.sin(h0), y0 + s * r0_m * math.cos(h0)])
        d = np.array([gx, gy]) - c
        dist = float(np.hypot(*d))
        if dist > r0_m:
            headings.append(math.atan2(d[1], d[0]) - math.asin(-s * r0_m / dist))
        # CC paths ending on the point (vanishing third arc, or vanishing first arc of a CCC word)
        r_mid = min(r0_m, r1_m)
        goal = np.array([gx, gy])
        for cm in _circle_intersections(c, r0_m + r_mid, goal, r_mid):
            g = goal - cm
            headings.append(math.atan2(g[1], g[0]) - s * math.pi / 2)
        cm = np.array([x0 + s * r_mid * math.sin(h0), y0 - s * r_mid * math.cos(h0)])  # turns -s
        for c1 in _circle_intersections(cm, r_mid + r1_m, goal, r1_m):
            g = goal - c1
            headings.append(math.atan2(g[1], g[0]) + s * math.pi / 2)
    headings = np.asarray(headings)

    def lengths_for(h: np.ndarray) -> np.ndarray:
        q1 = np.column_stack([np.full(len(h), gx), np.full(len(h), gy), h])
        return word_lengths(np.asarray(q0, dtype=float), q1, r0_m, r1_m).sum(axis=2).min(axis=1)

    totals = lengths_for(headings)
    h_best, l_best = float(headings[np.argmin(totals)]), float(totals.min())
    half = math.pi / n_headings
    for i in np.argsort(totals)[:refine]:  # the length is only piecewise smooth in the heading
        res = minimize_scalar(
            lambda h: float(lengths_for(np.array([h]))[0]),
            bounds=(headings[i] - half, headings[i] + half),
            method="bounded",
            options={"xatol": 1e-9},
        )
        if res.fun < l_best:
            h_best, l_best = float(res.x), float(res.fun)
    return shortest_path(q0, (gx, gy, h_best), r0_m, r1_m)


def stretch_to_length(
    q0: tuple[float, float, float],
    q1: tuple[float, float, float],
    length_m: float,
    r0_min_m: float,
    r1_min_m: float | None = None,
    k_max: float = 20.0,
    max_loops: int = 50,
    tol_m: float = 1e-6,
) -> DubinsPath | None:
    """A Dubins path q0 -> q1 of horizontal length ``length_m`` with radii k*(r0_min, r1_min), k >= 1.

    Prefers the smallest k (tightest turns still allowed); adds full loiter loops on the start
    circle when no k <= k_max reaches the length. Returns None when length_m is shorter than the
    shortest path or no solution exists within k_max and max_loops.
    """
    r1_min_m = r0_min_m if r1_min_m is None else r1_min_m
    ks = np.geomspace(1.0, k_max, 400)

    def word_len(k: np.ndarray) -> np.ndarray:  # (len(k), 6)
        k = np.atleast_1d(k)
        return word_lengths(np.asarray(q0), np.asarray(q1), r0_min_m * k, r1_min_m * k).sum(axis=2)

    base = word_len(ks)
    if length_m < base[0].min() - tol_m:
        return None
    for loops in range(max_loops + 1):
        table = base + loops * _TWO_PI * r0_min_m * ks[:, None]
        best: tuple[float, int] | None = None
        for w in range(6):

            def residual(kk: float, w: int = w, loops: int = loops) -> float:
                return float(word_len(np.array([kk]))[0, w]) + loops * _TWO_PI * r0_min_m * kk - length_m

            k = _first_root(ks, table[:, w] - length_m, residual, tol_m)
            if k is not None and (best is None or k < best[0]):
                best = (k, w)
        if best is not None:
            k, w = best
            r0, r1 = r0_min_m * k, r1_min_m * k
            seg = word_lengths(np.asarray(q0), np.asarray(q1), r0, r1)[0, w].copy()
            seg[0] += loops * _TWO_PI * r0
            return _make(q0, WORDS[w], seg, r0, r1, min(r0, r1))
    return None


def _circle_intersections(c0: np.ndarray, ra: float, c1: np.ndarray, rb: float) -> list[np.ndarray]:
    """Intersection points of circle (c0, ra) and circle (c1, rb); empty when they do not meet."""
    d = c1 - c0
    dist = float(np.hypot(*d))
    if dist < 1e-12 or dist > ra + rb or dist < abs(ra - rb):
        return []
    x = (ra**2 - rb**2 + dist**2) / (2 * dist)
    h = math.sqrt(max(ra**2 - x**2, 0.0))
    e = d / dist
    n = np.array([-e[1], e[0]])
    return [c0 + x * e + h * n, c0 + x * e - h * n]


def _first_root(ks: np.ndarray, f: np.ndarray, fn, tol_m: float) -> float | None:
    """Smallest k where the scanned f changes sign between finite neighbours, refined by Brent."""
    if np.isfinite(f[0]) and abs(f[0]) <= tol_m:
        return float(ks[0])
    ok = np.isfinite(f[:-1]) & np.isfinite(f[1:]) & (np.sign(f[:-1]) != np.sign(f[1:]))
    for i in np.flatnonzero(ok):
        k = brentq(fn, ks[i], ks[i + 1], xtol=1e-12)
        if abs(fn(k)) <= tol_m:  # reject jumps (an arc angle wrapping 0 <-> 2 pi)
            return float(k)
    return None


def _make(q0, word: str, lengths: np.ndarray, r0: float, r1: float, rm: float) -> DubinsPath:
    radii = (float(r0), math.inf if word[1] == "S" else float(rm), float(r1))
    return DubinsPath(
        start=tuple(float(v) for v in q0),
        word=word,
        lengths=tuple(float(v) for v in lengths),
        radii=radii,
    )


def _rows(a: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    return a if a.shape == shape else np.broadcast_to(a, shape)


@compiled
def _word_lengths(q0, q1, r0, r1, rm, out) -> None:
    """``word_lengths`` into ``out`` (N, 6, 3), one problem at a time (compiled: numpy's passes over
    small batches were mostly call overhead)."""
    for i in range(len(out)):
        h0, h1 = q0[i, 2], q1[i, 2]
        # turning-circle centres, L (left of the heading) then R
        rs0, rc0 = r0[i] * np.sin(h0), r0[i] * np.cos(h0)
        rs1, rc1 = r1[i] * np.sin(h1), r1[i] * np.cos(h1)
        c0 = ((q0[i, 0] - rs0, q0[i, 1] + rc0), (q0[i, 0] + rs0, q0[i, 1] - rc0))
        c1 = ((q1[i, 0] - rs1, q1[i, 1] + rc1), (q1[i, 0] + rs1, q1[i, 1] - rc1))
        for w in range(6):
            s0, s1 = _WORD_SIGNS[w, 0], _WORD_SIGNS[w, 2]
            a, b = c0[0 if s0 > 0 else 1], c1[0 if s1 > 0 else 1]
            if w < 4:
                out[i, w] = _csc(h0, h1, b[0] - a[0], b[1] - a[1], r0[i], r1[i], s0, s1)
            else:
                left = _ccc(h0, h1, a, b, r0[i], r1[i], rm[i], s0, 1.0)
                right = _ccc(h0, h1, a, b, r0[i], r1[i], rm[i], s0, -1.0)
                better = (right[0] + right[1]) + right[2] < (left[0] + left[1]) + left[2]
                out[i, w] = right if better else left


@compiled
def _ccw(a: float) -> float:
    """Angle mod 2 pi in [0, 2 pi), with near-2 pi values snapped to 0."""
    a = np.fmod(a, _TWO_PI)  # fmod and a sign fix: np.mod's value
    if a < 0.0:
        a += _TWO_PI
    return 0.0 if a > _TWO_PI - _ANGLE_EPS else a


@compiled
def _csc(h0, h1, dx, dy, r0, r1, s0, s1) -> tuple[float, float, float]:
    """Segment lengths of a CSC word with turn signs s0, s1 and centre offset (dx, dy)."""
    dist = np.hypot(dx, dy)
    dr = s1 * r1 - s0 * r0
    if not abs(dr) <= dist + 1e-12:
        return np.inf, np.inf, np.inf
    alpha = h0  # concentric equal circles: no straight part
    if dist > 1e-12:
        alpha = np.arctan2(dy, dx) - np.arcsin(min(max(dr / dist, -1.0), 1.0))
    straight = np.sqrt(max(dist**2 - dr**2, 0.0))
    return _ccw(s0 * (alpha - h0)) * r0, straight, _ccw(s1 * (h1 - alpha)) * r1


@compiled
def _ccc(h0, h1, c0, c1, r0, r1, rm, s, side) -> tuple[float, float, float]:
    """Segment lengths of a CCC word (first turn sign s), middle circle on the ``side`` (+1 left,
    -1 right) of c0 -> c1."""
    dx, dy = c1[0] - c0[0], c1[1] - c0[1]
    dist = np.hypot(dx, dy)
    a, b = r0 + rm, r1 + rm
    if not (dist > 1e-12 and dist <= a + b and dist >= abs(a - b)):
        return np.inf, np.inf, np.inf
    x = (a**2 - b**2 + dist**2) / (2.0 * dist)
    h = side * np.sqrt(max(a**2 - x**2, 0.0))
    ex, ey = dx / dist, dy / dist
    cmx = c0[0] + x * ex + h * -ey
    cmy = c0[1] + x * ey + h * ex
    hq0 = np.arctan2(cmy - c0[1], cmx - c0[0]) + s * (math.pi / 2)  # tangency with circle 0 is along c0 -> cm
    hq1 = np.arctan2(c1[1] - cmy, c1[0] - cmx) - s * (math.pi / 2)  # middle circle turns the other way
    return _ccw(s * (hq0 - h0)) * r0, _ccw(-s * (hq1 - hq0)) * rm, _ccw(s * (h1 - hq1)) * r1


def _advance(pose: np.ndarray, kappa: float, ds: float) -> np.ndarray:
    return advance(pose[None, :], np.array([kappa]), np.array([ds]))[0]


def advance(poses: np.ndarray, kappa: np.ndarray, ds: np.ndarray) -> np.ndarray:
    """Integrate constant-curvature motion exactly: poses (n, 3), signed curvature (n,), distance (n,)."""
    poses = np.asarray(poses, dtype=float)
    out = np.empty((len(poses), 3))
    _advance_rows(poses, np.asarray(kappa, dtype=float), np.asarray(ds, dtype=float), out)
    return out


@compiled
def _advance_rows(poses, kappa, ds, out) -> None:
    for i in range(len(poses)):
        out[i] = _advance_one(poses[i, 0], poses[i, 1], poses[i, 2], kappa[i], ds[i])


@compiled
def _advance_one(x: float, y: float, h: float, kappa: float, ds: float) -> tuple[float, float, float]:
    """Pose after ``ds`` [m] at signed curvature ``kappa`` from (x, y, h)."""
    if kappa == 0.0:
        return x + ds * np.cos(h), y + ds * np.sin(h), h + 0.0
    h_new = h + kappa * ds
    return x + (np.sin(h_new) - np.sin(h)) / kappa, y - (np.cos(h_new) - np.cos(h)) / kappa, h_new


@compiled
def _pick_shortest(seg, r0, r1, best, lengths, radii) -> None:
    """``shortest_batch`` from the word lengths: the first shortest word of each row, its lengths and
    radii (the middle one inf for CSC words)."""
    for i in range(len(seg)):
        b, low = 0, seg[i, 0, 0] + seg[i, 0, 1] + seg[i, 0, 2]
        for w in range(1, 6):
            total = seg[i, w, 0] + seg[i, w, 1] + seg[i, w, 2]
            if total < low:
                b, low = w, total
        best[i] = b
        lengths[i] = seg[i, b]
        radii[i, 0], radii[i, 1], radii[i, 2] = r0[i], np.inf if b < 4 else min(r0[i], r1[i]), r1[i]


@compiled
def _segment_starts(q0, word, lengths, radii, starts, kappa) -> None:
    for i in range(len(q0)):
        for k in range(3):
            sign = _WORD_SIGNS[word[i], k]
            kappa[i, k] = 0.0 if sign == 0 else sign / (radii[i, k] if np.isfinite(radii[i, k]) else 1.0)
        starts[i, 0] = q0[i]
        for k in range(2):
            starts[i, k + 1] = _advance_one(
                starts[i, k, 0], starts[i, k, 1], starts[i, k, 2], kappa[i, k], lengths[i, k]
            )
