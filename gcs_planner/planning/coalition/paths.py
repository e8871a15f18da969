"""Coalition paths (section 4.2): entry poses, timed Dubins arrivals, recon/assessment arcs, threat avoidance.

Built on gcs_planner.geometry.dubins (``word_lengths``, ``DubinsPath``). Two thin, batched additions
live here because the coalition planner calls them for every bidder and member inside the
0.05 s compute budget (the library's scalar versions take ~0.1 s per call):
- ``free_heading_lengths``: shortest length to a point with free terminal heading (bid ETA,
  eq. 23), batched: the analytic CS tangent length for both turn directions; a goal inside a
  turning circle falls back to a 72-heading sweep of all six words.
- ``stretch_batch``: paths of exact given lengths for many members at once (simultaneous /
  staggered arrival, ref [28]): both radii scale by one factor k >= 1 (scan of k, then batched
  bisection); when no k <= k_max reaches the length, whole loiter loops are added on the start
  circle (loiter fallback). The result is the readable reference's, geometry/dubins.py
  ``stretch_to_length`` with k_max = ``K_MAX`` (tests/test_coalition_paths_aco.py holds them equal),
  which is not called here because it costs ~0.5 s per hard case.

Geometry conventions (model.py): a strike entry pose is the stand-off point L^s from the target at
the attack bearing, heading to the target; recon and assessment arcs start on their circle
(C^r, C^e) at the start bearing, heading tangent counter-clockwise.

Threat avoidance (eq. 17): threats are circles known at planning time. When the shortest path
enters one, the safe circle D (r_D = kappa r_T) gives two safe points, P1/P2 = centre +- r_D n,
n normal to the start-goal chord; the one nearer the original path is used, heading along the
chord (tangent to D there), and the path becomes start -> safe pose -> goal (two Dubins
segments, recursively for further threats, depth <= 2; the other safe point and 1.5 kappa are
tried when the first choice still intersects). Timing (a required length) is met by, in order:
radius stretching of the last link, else of another; pushing the safe points outwards; a detour
through a via pose (distance to the goal solved per bearing); loiter on a turning
circle (after 0-3/4 of the first link). Every returned leg is re-checked against the threats and
the result is reported.

Choices in the fallbacks (compute; not in the paper):
- The detour scans via poses on 24 bearings x 30 distances. The roots are refined by Illinois to
  1e-2 m either way, so the grid only has to bracket them.
- The loiter fallback runs only for a route whose detour found no exact path at all, not for one
  whose exact detours all cross a threat (``_DetourPlan.blocked``); a route it would clear has
  its member excluded instead (the leader re-covers the task).
(Measurements behind both: docs/coalition.md, Decisions.)

Compute (target 0.05 s per formation; numpy call overhead, not arithmetic, dominates): paths are
sampled for clearance checks and legs in one ``sample_batch`` call (``chains_clear``,
``sample_legs``), with exactly ``DubinsPath.sample_step``'s samples. The detour and loiter
fallbacks evaluate their whole scan in one Dubins call. Their scans skip points where a lower
bound of the Dubins length proves the residual positive (``_scan``): the Euclidean distance, and
where that is not enough the larger of the free-heading reach lengths (turn + tangent, Dubins
1957) forwards from the start pose and backwards from the end pose (``_dubins_lower_bound``); it
leaves about half of the Euclidean bound's points to evaluate. The stretch scan stops at the
last loop count that can still change sign. All root refinements of a step run in lockstep
(``_solve``: one Dubins call per Illinois iteration for the stretches and detours of all
members), and a root is taken once settled (choice, see ``SETTLED_M``: 2-7 iterations instead of
12-14; by < 1e-9 m; the grid and loiter choices above change results too). Members whose
stretch has no smooth sign change (it will almost surely fail) have their detour scanned before
the stretch refinement and refined with it; the loiter fallback runs only for the routes the
detour leaves without a path. Clearance is checked for each route's first candidate first, the
others only where it fails. ``timed_routes`` runs the fallbacks for all members of a formation
that need them in one batch, and takes the shortest links of all its routes from one Dubins call
(``_route_links``). The candidates are still taken in the same order of preference, so the
results equal the one-candidate-at-a-time, one-member-at-a-time computation (tested).
``FormationPaths`` memoises a formation's routes and timed paths over the leader's attempts
(row-independent batches make a memoised path equal a fresh one).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from gcs_planner.core.geo import wrap_pi
from gcs_planner.geometry.dubins import WORDS, DubinsPath, sample_batch, word_lengths
from gcs_planner.planning.coalition.model import Threat
from gcs_planner.planning.coalition.track import Leg

__all__ = [
    "FormationPaths",
    "arc_leg",
    "arc_start_pose",
    "chains_clear",
    "clearance_m",
    "entry_poses",
    "free_heading_lengths",
    "min_route",
    "min_routes",
    "sample_legs",
    "shortest_lengths",
    "stretch_batch",
    "timed_route",
    "timed_routes",
]

TWO_PI = 2.0 * math.pi
K_MAX = 4.0  # largest radius stretch factor before loiter loops are added
# Illinois refinements stop early once every root is settled (choice, see _solve): converged to
# |residual| <= SETTLED_M, or still >= STUCK_M after STUCK_AFTER iterations (a sign change across
# a jump, which the acceptance tests of 1 mm / 1 cm reject whatever the iteration count)
SETTLED_M, STUCK_M, STUCK_AFTER = 1e-9, 1.0, 6


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


def _pose(q) -> tuple[float, float, float]:
    return float(q[0]), float(q[1]), float(q[2])


def _path(q0, word_i: int, seg: np.ndarray, r0: float, r1: float) -> DubinsPath:
    word = WORDS[word_i]
    return DubinsPath(
        start=_pose(q0),
        word=word,
        lengths=tuple(float(v) for v in seg),
        radii=(float(r0), math.inf if word[1] == "S" else float(min(r0, r1)), float(r1)),
    )


def stretch_batch(
    q0: np.ndarray, q1: np.ndarray, length_m: np.ndarray, r_m: np.ndarray
) -> list[DubinsPath | None]:
    """Dubins paths q0[i] -> q1[i] of exactly length_m[i] with radius k r_m[i] (k >= 1) plus loops.

    Every sign change of (word length + loops - target) on a k grid is a candidate; all candidates
    are bisected together and each problem keeps its smallest k that converges (a sign change
    across a discontinuity does not). A problem with no converged candidate on the coarse grid
    gets the result of a dense grid (CCC words are valid on narrow k intervals). None where
    length_m[i] is below the shortest path.

    Compute: a problem whose coarse sign changes are all jumps (|f_hi - f_lo| >= r k: an arc
    wrapping by 2 pi, the usual cause of non-convergence) has its dense grid scanned up front and
    refined in the same batch as the coarse candidates; the dense result is used only if the
    coarse ones do not converge, so the results equal a dense pass after the coarse one.
    """
    plan = _StretchPlan(q0, q1, length_m, r_m)
    return plan.finish(_solve([plan.job])[0])


_KS_COARSE = np.geomspace(1.0, K_MAX, 60)
_KS_DENSE = np.geomspace(1.0, K_MAX, 300)


@dataclass
class _Job:
    """Illinois root problems in brackets [lo, hi] (n,) whose residual costs one Dubins call.

    pairs(x) gives the (q0, q1, r) rows of ``word_lengths`` at x, resid(x, seg) the residual (n,)
    from those rows' segment lengths; final: also return the segment lengths at the roots."""

    lo: np.ndarray
    hi: np.ndarray
    iters: int
    pairs: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]]
    resid: Callable[[np.ndarray, np.ndarray], np.ndarray]
    final: bool = False


def _solve(jobs: list[_Job | None]) -> list[tuple[np.ndarray, np.ndarray | None] | None]:
    """(roots, segment lengths at the roots if job.final) of every job (None for None), by the
    Illinois (modified regula falsi) method in lockstep: one ``word_lengths`` call per iteration
    for the rows of all jobs. Every operation is row by row, so each job gets exactly the roots of
    its own run. A row's root is taken after its job's iterations, or earlier once it is settled
    (choice: |f| <= SETTLED_M, or >= STUCK_M after STUCK_AFTER iterations); on the paper runs
    converged roots settle after 2-7 iterations instead of 12-14, the taken roots move by < 1e-9 m
    and no accepted root changes."""
    live = [j for j in jobs if j is not None]
    if not live:
        return [None] * len(jobs)
    sizes = [len(j.lo) for j in live]
    cuts = np.cumsum(sizes)[:-1]

    def fun(x: np.ndarray) -> np.ndarray:
        parts = np.split(x, cuts) if len(live) > 1 else [x]
        return np.concatenate([j.resid(p, s) for j, p, s in zip(live, parts, _dubins_rows(live, parts))])

    both = [j.lo for j in live] + [j.hi for j in live]  # f at lo and at hi: one Dubins call
    f = [j.resid(p, s) for j, p, s in zip(live + live, both, _dubins_rows(live + live, both))]
    lo, hi = np.concatenate(both[: len(live)]), np.concatenate(both[len(live) :])
    f_lo, f_hi = np.concatenate(f[: len(live)]), np.concatenate(f[len(live) :])
    stop = np.repeat([j.iters for j in live], sizes)
    roots, done = hi.copy(), np.zeros(len(hi), bool)
    for it in range(1, max(j.iters for j in live) + 1):
        x = hi - f_hi * (hi - lo) / np.where(f_hi != f_lo, f_hi - f_lo, 1.0)  # inside the bracket
        fx = fun(x)
        flip = np.sign(fx) != np.sign(f_hi)
        lo, f_lo = np.where(flip, hi, lo), np.where(flip, f_hi, 0.5 * f_lo)
        hi, f_hi = x, fx
        # a row's root is taken when it settles or its job's iterations are done (row by row, so a
        # root does not depend on the other rows), and the run ends when every row is taken
        a = np.abs(f_hi)
        new = ~done & ((stop == it) | (a <= SETTLED_M) | ((a >= STUCK_M) & (it >= STUCK_AFTER)))
        roots, done = np.where(new, hi, roots), done | new
        if done.all():
            break

    parts = np.split(roots, cuts)
    final = [j for j in live if j.final]
    segs = iter(_dubins_rows(final, [p for j, p in zip(live, parts) if j.final]) if final else [])
    solved = iter([(p, next(segs) if j.final else None) for j, p in zip(live, parts)])
    return [None if j is None else next(solved) for j in jobs]


def _dubins_rows(jobs: list[_Job], xs: list[np.ndarray]) -> list[np.ndarray]:
    """Segment lengths of the ``pairs`` rows of jobs[i] at xs[i], all in one ``word_lengths`` call."""
    rows = [j.pairs(x) for j, x in zip(jobs, xs)]
    if len(rows) == 1:
        return [word_lengths(*rows[0])]
    seg = word_lengths(*(np.concatenate([r[i] for r in rows]) for i in range(3)))
    return np.split(seg, np.cumsum([len(r[0]) for r in rows])[:-1])


class _StretchPlan:
    """stretch_batch in steps: the k scans (here), one Illinois job (``job``), then ``finish``.

    ``likely_none``: problems with no smooth sign change on either grid, whose stretch almost
    surely fails (FormationPaths starts their fallbacks in the same Illinois run)."""

    def __init__(self, q0: np.ndarray, q1: np.ndarray, length_m: np.ndarray, r_m: np.ndarray) -> None:
        self.q0, self.q1 = np.atleast_2d(q0).astype(float), np.atleast_2d(q1).astype(float)
        self.length_m = np.atleast_1d(length_m).astype(float)
        self.r_m = np.broadcast_to(np.asarray(r_m, float), len(self.q0)).copy()
        args = self.q0, self.q1, self.length_m, self.r_m
        n = len(self.q0)
        self.out: list[DubinsPath | None] = [None] * n
        cands, jumps, short = _stretch_scan(*args, _KS_COARSE, self.out)
        self.open = [i for i in range(n) if self.out[i] is None and self.length_m[i] >= short[i] - 1e-3]
        self.smooth = {c[0] for c, jump in zip(cands, jumps) if not jump}
        self.ahead = [i for i in self.open if i not in self.smooth]
        dense, dense_jumps = _dense_scan(self.ahead, *args, self.out) if self.ahead else ([], [])
        self.dense_out: list[DubinsPath | None] = [None] * n
        self.groups = [(cands, self.out), (dense, self.dense_out)]
        self.job = _stretch_job(self.groups, *args)
        smooth_dense = {c[0] for c, jump in zip(dense, dense_jumps) if not jump}
        self.likely_none = [
            i
            for i in range(n)
            if self.out[i] is None and (i not in self.open or (i in self.ahead and i not in smooth_dense))
        ]

    def finish(self, solved: tuple[np.ndarray, np.ndarray] | None) -> list[DubinsPath | None]:
        """The paths, given ``_solve``'s result for ``job``."""
        args = self.q0, self.q1, self.length_m, self.r_m
        _stretch_take(self.groups, *args, solved)
        for i in self.ahead:
            self.out[i] = self.out[i] or self.dense_out[i]
        late = [i for i in self.open if self.out[i] is None and i in self.smooth]
        if late:
            groups = [(_dense_scan(late, *args, self.out)[0], self.out)]
            _stretch_take(groups, *args, _solve([_stretch_job(groups, *args)])[0])
        return self.out


def _dense_scan(idx: list[int], q0, q1, length_m, r_m, out: list) -> tuple[list[tuple], list[bool]]:
    """_stretch_scan of problems idx on the dense k grid; candidates indexed like the full batch,
    and whether each is a jump."""
    sub: list[DubinsPath | None] = [None] * len(idx)
    cands, jumps, _ = _stretch_scan(q0[idx], q1[idx], length_m[idx], r_m[idx], _KS_DENSE, sub)
    for j, path in enumerate(sub):
        if path is not None:
            out[idx[j]] = path
    return [(idx[c[0]], *c[1:]) for c in cands], jumps


def _stretch_scan(q0, q1, length_m, r_m, ks, out: list) -> tuple[list[tuple], list[bool], np.ndarray]:
    """Candidates (problem, word, k_lo, k_hi, loops) of every problem on one k grid (ks[0] = 1).

    A problem whose length is its shortest path gets that path in out. Also returns, per
    candidate, whether its sign change is a jump (|f_hi - f_lo| >= r k_lo), and the shortest
    lengths (k = 1)."""
    n = len(q0)
    nk = len(ks)
    segs = word_lengths(np.repeat(q0, nk, 0), np.repeat(q1, nk, 0), np.tile(ks, n) * np.repeat(r_m, nk))
    segs = segs.reshape(n, nk, 6, 3)
    table = segs.sum(3)
    cands, jumps = [], []
    for i in range(n):
        shortest = table[i, 0].min()
        if length_m[i] < shortest - 1e-3:
            continue
        if length_m[i] <= shortest + 1e-6:
            w = int(table[i, 0].argmin())
            out[i] = _path(q0[i], w, segs[i, 0, w], r_m[i], r_m[i])
            continue
        loop_len = TWO_PI * r_m[i] * ks
        finite = np.isfinite(table[i])
        n0 = max(0, int((length_m[i] - table[i].max(initial=0, where=finite)) // loop_len[-1]))
        # f grows with the loop count (monotone rounding), so from n_hi on, where every finite
        # f > 0 by a margin of a loop (>= 2 pi r), no count has a sign change: stop there
        n_hi = int(((length_m[i] - table[i]) / loop_len[:, None]).max(initial=0.0, where=finite)) + 2
        # the smallest loop count in n0 .. n0 + 199 with a sign change: the first one alone, then
        # the others in one (loops, k, word) pass (the same values as one count at a time)
        for counts in (np.arange(n0, n0 + 1), np.arange(n0 + 1, min(n0 + 200, n_hi))):
            f = table[i] + counts[:, None, None] * loop_len[:, None] - length_m[i]
            with np.errstate(invalid="ignore"):
                cross = (
                    np.isfinite(f[:, :-1]) & np.isfinite(f[:, 1:]) & (np.sign(f[:, :-1]) != np.sign(f[:, 1:]))
                )
            hit = np.flatnonzero(cross.any((1, 2)))
            if len(hit):
                loops = int(counts[hit[0]])
                fh = f[hit[0]]
                for ki, w in np.argwhere(cross[hit[0]]):
                    cands.append((i, w, ks[ki], ks[ki + 1], loops))
                    jumps.append(bool(abs(fh[ki + 1, w] - fh[ki, w]) >= r_m[i] * ks[ki]))
                break
    return cands, jumps, table[:, 0].min(1)


def _stretch_job(groups: list[tuple[list[tuple], list]], q0, q1, length_m, r_m) -> _Job | None:
    """The Illinois job of all candidates (problem, word, k_lo, k_hi, loops) of all groups."""
    allc = [c for cands, _ in groups for c in cands]
    if not allc:
        return None
    c = np.array(allc, dtype=float)
    pi, w, loops = c[:, 0].astype(int), c[:, 1].astype(int), c[:, 4]
    rows = np.arange(len(c))
    return _Job(
        c[:, 2],
        c[:, 3],
        14,
        lambda k: (q0[pi], q1[pi], k * r_m[pi]),
        lambda k, seg: seg[rows, w].sum(1) + loops * TWO_PI * r_m[pi] * k - length_m[pi],
        final=True,
    )


def _stretch_take(groups: list[tuple[list[tuple], list]], q0, q1, length_m, r_m, solved) -> None:
    """In each group's output list, every problem still without a path takes its smallest converged
    k (solved: ``_solve``'s roots and segment lengths for ``_stretch_job(groups)``)."""
    if solved is None:
        return
    hi, seg_all = solved
    c = np.array([c for cands, _ in groups for c in cands], dtype=float)
    pi, w, loops = c[:, 0].astype(int), c[:, 1].astype(int), c[:, 4]
    seg = seg_all[np.arange(len(c)), w]
    f = seg.sum(1) + loops * TWO_PI * r_m[pi] * hi - length_m[pi]
    seg[:, 0] += loops * TWO_PI * r_m[pi] * hi
    start = 0
    for cands, dest in groups:
        sel = np.arange(start, start + len(cands))
        start += len(cands)
        for j in sel[np.lexsort((hi[sel], pi[sel]))]:  # per problem, smallest converged k first
            i = pi[j]
            if dest[i] is None and abs(f[j]) < 1e-3:
                dest[i] = _path(q0[i], w[j], seg[j], hi[j] * r_m[i], hi[j] * r_m[i])


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
    """The first threat (along the path) that a sample falls inside, or None."""
    if not threats:
        return None
    c = np.array([[t.x, t.y] for t in threats])
    r = np.array([t.radius_m for t in threats])
    inside = np.hypot(xy[:, None, 0] - c[None, :, 0], xy[:, None, 1] - c[None, :, 1]) < r
    hits = np.flatnonzero(inside.any(1))
    return None if not len(hits) else threats[int(np.argmax(inside[hits[0]]))]


def chains_clear(chains: list[list[DubinsPath]], threats: list[Threat], ds_m: float) -> np.ndarray:
    """(len(chains),) bool: every sample of the chain of paths is outside every threat circle.

    The samples are exactly those of ``DubinsPath.sample_step(ds_m)`` (same linspace, same
    integration), so this equals ``clearance_m(concatenated samples) >= 0`` chain by chain; all
    paths of all chains are sampled in one vectorised pass (``sample_batch``) instead of one
    Python-level sampling per path."""
    ok = np.ones(len(chains), bool)
    flat = [p for ch in chains for p in ch]
    if not threats or not flat:
        return ok
    owner = np.repeat(np.arange(len(chains)), [len(ch) for ch in chains])
    xy = _sample_flat(flat, ds_m)[1]
    c = np.array([[t.x, t.y] for t in threats])
    r = np.array([t.radius_m for t in threats])
    inside = (np.hypot(xy[..., 0, None] - c[:, 0], xy[..., 1, None] - c[:, 1]) - r < 0).any((1, 2))
    ok[owner[inside]] = False
    return ok


def _sample_flat(flat: list[DubinsPath], ds_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every path sampled as ``DubinsPath.sample_step(ds_m)`` does, in one ``sample_batch`` call.

    Returns arc lengths s (P, M), poses (P, M, 3) (heading not wrapped) and the sample count per
    path (P,); rows are padded with the end point up to M.
    """
    total = np.array([p.length for p in flat])
    n = np.maximum(1, np.ceil(total / ds_m)).astype(int)
    i = np.arange(n.max() + 1)
    s = np.where(i < n[:, None], i * (total / n)[:, None], total[:, None])  # linspace(0, L, n + 1), padded
    poses = sample_batch(
        np.array([p.start for p in flat]),
        np.array([WORDS.index(p.word) for p in flat]),
        np.array([p.lengths for p in flat]),
        np.array([p.radii for p in flat]),
        s,
    )
    return s, poses, n + 1


def _shortest(q0, q1, r: float) -> DubinsPath:
    lens = word_lengths(q0, q1, r)[0]
    w = int(lens.sum(1).argmin())
    return _path(q0, w, lens[w], r, r)


def _route_links(routes: list[Route]) -> list[list[DubinsPath]]:
    """The shortest links of every route (``_shortest`` of each pair of consecutive poses), all
    in one Dubins call (row by row, so each link equals its own ``_shortest``)."""
    q0 = np.array([q for rt in routes for q in rt.poses[:-1]]).reshape(-1, 3)
    q1 = np.array([q for rt in routes for q in rt.poses[1:]]).reshape(-1, 3)
    r = np.array([rt.r_m for rt in routes for _ in rt.poses[1:]], dtype=float)
    if not len(r):
        return [[] for _ in routes]
    lens = word_lengths(q0, q1, r)
    w = lens.sum(2).argmin(1)
    flat = iter([_path(a, wi, seg[wi], ri, ri) for a, wi, seg, ri in zip(q0, w.tolist(), lens, r.tolist())])
    return [[next(flat) for _ in rt.poses[1:]] for rt in routes]


@dataclass
class Route:
    """A chain of poses (start, safe poses..., goal) whose shortest Dubins links clear the threats."""

    poses: list[np.ndarray]
    r_m: float
    length_m: float
    clear: bool
    centres: list[np.ndarray | None] | None = None  # threat centre of each pose (None: start/goal)

    def __post_init__(self) -> None:
        if self.centres is None:
            self.centres = [None] * len(self.poses)

    def pushed(self, sigma: float) -> list[np.ndarray]:
        """Poses with every safe point moved radially away from its threat by factor sigma."""
        out = []
        for q, c in zip(self.poses, self.centres):
            if c is None:
                out.append(q)
            else:
                out.append(np.array([*(c + sigma * (q[:2] - c)), q[2]]))
        return out


def min_route(
    q0, q1, r_m: float, threats: list[Threat], kappa: float, ds_m: float = 10.0, depth: int = 2
) -> Route:
    """Shortest route start -> goal around the threats by safe-point two-segment Dubins paths."""
    q0, q1 = np.asarray(q0, float), np.asarray(q1, float)
    direct = _shortest(q0, q1, r_m)
    xy = _samples(direct, ds_m)[:, :2]
    hit = _first_violated(xy, threats)
    if hit is None or depth == 0:
        return Route([q0, q1], r_m, direct.length, hit is None)
    chord = q1[:2] - q0[:2]
    d = chord / max(np.hypot(*chord), 1e-9)
    n = np.array([-d[1], d[0]])
    centre = np.array([hit.x, hit.y])
    safes = []
    for k in (kappa, kappa * 1.5):  # safe points, nearer the original path first
        cands = [centre + k * hit.radius_m * n, centre - k * hit.radius_m * n]
        cands.sort(key=lambda p: float(np.min(np.hypot(*(xy - p).T))))
        safes += [np.array([p[0], p[1], math.atan2(d[1], d[0])]) for p in cands]
    m = len(safes)
    # both links of every candidate in one batched Dubins call
    lens = word_lengths(np.r_[np.tile(q0, (m, 1)), safes], np.r_[safes, np.tile(q1, (m, 1))], r_m)
    for c, safe in enumerate(safes):  # the first candidate that clears is taken (the paper's rule)
        links = []
        for row, a in ((c, q0), (m + c, safe)):
            w = int(lens[row].sum(1).argmin())
            links.append(_path(a, w, lens[row, w], r_m, r_m))
        ok = [_first_violated(_samples(p, ds_m)[:, :2], threats) is None for p in links]
        if not any(ok) and depth < 2:
            continue
        parts = [
            Route([a, b], r_m, p.length, True)
            if good
            else min_route(a, b, r_m, threats, kappa, ds_m, depth - 1)
            for good, p, (a, b) in zip(ok, links, ((q0, safe), (safe, q1)))
        ]
        if all(part.clear for part in parts):
            a, b = parts
            centres = [*a.centres[:-1], centre, *b.centres[1:]]
            return Route(a.poses + b.poses[1:], r_m, a.length_m + b.length_m, True, centres)
    return Route([q0, q1], r_m, direct.length, False)


def min_routes(
    q0: np.ndarray, q1: np.ndarray, r_m: np.ndarray, threats: list[Threat], kappa: float, ds_m: float = 10.0
) -> list[Route]:
    """min_route for many pairs: one batched Dubins call; only paths that hit a threat are re-routed."""
    lens = word_lengths(q0, q1, r_m, r_m)
    w = lens.sum(2).argmin(1)
    direct = [_path(q0[i], w[i], lens[i, w[i]], r_m[i], r_m[i]) for i in range(len(q0))]
    clear = chains_clear([[d] for d in direct], threats, ds_m)
    return [
        Route([q0[i], q1[i]], float(r_m[i]), direct[i].length, True)
        if clear[i]
        else min_route(q0[i], q1[i], float(r_m[i]), threats, kappa, ds_m)
        for i in range(len(q0))
    ]


class FormationPaths:
    """One formation's threat-avoiding routes and timed paths, memoised over the leader's attempts.

    poses (n, 3): candidates' start poses at t_e^s; goals (K, 3): task entry poses; r_m (n,) turn
    radii. Within one formation these and the known threats are fixed, so a route depends only on
    (candidate, task) and a timed path only on (candidate, task, required length): after a member is
    excluded, the next attempt plans only the (candidate, task, length) triples it has not seen.
    Every step is computed row by row inside its batch (``min_routes``, ``stretch_batch``,
    ``chains_clear``, ``timed_routes``), so a memoised path equals a fresh computation exactly.
    """

    def __init__(
        self,
        poses: np.ndarray,
        goals: np.ndarray,
        r_m: np.ndarray,
        threats: list[Threat],
        kappa: float,
        ds_m: float,
    ) -> None:
        self.poses, self.goals, self.r_m = poses, goals, r_m
        self.threats, self.kappa, self.ds_m = threats, kappa, ds_m
        self._routes: dict[tuple[int, int], Route] = {}
        self._timed: dict[tuple[int, int, float], tuple[list[DubinsPath], bool]] = {}

    def routes(self, assign: np.ndarray) -> list[Route]:
        """Minimum threat-avoiding route of candidate assign[k] to task k, for every task k."""
        keys = [(int(i), k) for k, i in enumerate(assign)]
        new = [k for k, key in enumerate(keys) if key not in self._routes]
        if new:
            a = np.asarray(assign)[new]
            found = min_routes(self.poses[a], self.goals[new], self.r_m[a], self.threats, self.kappa)
            for k, route in zip(new, found):
                self._routes[keys[k]] = route
        return [self._routes[key] for key in keys]

    def lengths(self, length_m: np.ndarray) -> np.ndarray:
        """length_m (n, K) with the route length of every (candidate, task) routed so far."""
        out = np.array(length_m, copy=True)
        for (i, k), route in self._routes.items():
            out[i, k] = route.length_m
        return out

    def timed(self, assign: np.ndarray, want_m: np.ndarray) -> tuple[list[list[DubinsPath]], list[bool]]:
        """Segments of length want_m[k] from candidate assign[k] to task k, and whether they clear.

        A direct clear route is radius-stretched (all such members in one batch); the others, and
        stretched paths that cross a threat, go through ``timed_routes``'s fallbacks."""
        assign = np.asarray(assign)
        routes = self.routes(assign)
        keys = [(int(i), k, float(want_m[k])) for k, i in enumerate(assign)]
        todo = [k for k, key in enumerate(keys) if key not in self._timed]
        direct = [k for k in todo if len(routes[k].poses) == 2 and routes[k].clear]
        batch: dict[int, DubinsPath | None] = {}
        spec, early = [], None
        if direct:
            starts = np.array([routes[k].poses[0] for k in direct]).reshape(-1, 3)
            plan = _StretchPlan(starts, self.goals[direct], want_m[direct], self.r_m[assign[direct]])
            # members whose stretch will almost surely fail: their fallbacks' scans now, and all
            # roots in one lockstep Illinois run (used only if the stretch does fail)
            spec = [direct[j] for j in plan.likely_none]
            early = _Fallbacks([routes[k] for k in spec], [want_m[k] for k in spec]) if spec else None
            solved = _solve([plan.job, *(early.jobs if early else [])])
            batch = dict(zip(direct, plan.finish(solved[0])))
        stretched = [k for k in direct if batch[k] is not None]
        ok = dict(zip(stretched, chains_clear([[batch[k]] for k in stretched], self.threats, self.ds_m)))
        rest = [k for k in todo if not ok.get(k, False)]
        for k in todo:
            if ok.get(k, False):
                self._timed[keys[k]] = ([batch[k]], True)
        if rest:  # the other members' timing fallbacks, all at once (a direct stretch is passed on)
            found_early = {}
            if early:
                need = [j for j, k in enumerate(spec) if k in rest]
                found = early.finish(solved[1:], self.threats, 10.0, need)
                found_early = {rest.index(spec[j]): found[j] for j in need}
            found = timed_routes(
                [routes[k] for k in rest],
                [want_m[k] for k in rest],
                self.threats,
                stretched=[(batch[k],) if k in batch else None for k in rest],
                fallen=found_early,
            )
            for k, result in zip(rest, found):
                self._timed[keys[k]] = result
        out = [self._timed[key] for key in keys]
        return [segs for segs, _ in out], [clear for _, clear in out]


def _links_lengths(poses_sets: list[list[np.ndarray]], r_m: float) -> np.ndarray:
    """Total shortest length of each chain of poses (all chains the same size), one batched call."""
    a = np.array([p[:-1] for p in poses_sets]).reshape(-1, 3)
    b = np.array([p[1:] for p in poses_sets]).reshape(-1, 3)
    return shortest_lengths(a, b, r_m).reshape(len(poses_sets), -1).sum(1)


def timed_route(
    route: Route,
    length_m: float,
    threats: list[Threat],
    ds_m: float = 10.0,
    stretched: tuple[DubinsPath | None] | None = None,
) -> tuple[list[DubinsPath], bool]:
    """Dubins segments along `route` of total length_m (stretching one link); and whether they clear.

    stretched: ``(path,)`` when the caller already has ``stretch_batch``'s result for a two-pose
    route at length_m (path may be None), so the first fallback is not computed twice.
    """
    return timed_routes([route], [length_m], threats, ds_m, [stretched])[0]


def timed_routes(
    routes: list[Route],
    lengths_m: list[float],
    threats: list[Threat],
    ds_m: float = 10.0,
    stretched: list[tuple[DubinsPath | None] | None] | None = None,
    fallen: dict[int, list[DubinsPath] | None] | None = None,
) -> list[tuple[list[DubinsPath], bool]]:
    """timed_route for many routes (the members of one formation), with the same results.

    The stretching and push steps run route by route. The detour, then the loiter fallback, run
    once for all routes that still need them, so their Dubins calls are shared. fallen: the
    fallbacks' result of some routes (by index), already computed by the caller.
    """
    out: list = [None] * len(routes)
    last_resort: list = [None] * len(routes)
    given = stretched or [None] * len(routes)
    for i, links in enumerate(_route_links(routes)):
        out[i], last_resort[i] = _stretch_or_push(routes[i], links, lengths_m[i], threats, ds_m, given[i])
    pending = [i for i in range(len(routes)) if out[i] is None]
    found = {i: segs for i, segs in (fallen or {}).items() if i in pending}
    todo = [i for i in pending if i not in found]
    if todo:
        plans = _Fallbacks([routes[i] for i in todo], [lengths_m[i] for i in todo])
        found.update(zip(todo, plans.finish(_solve(plans.jobs), threats, ds_m)))
    for i in pending:
        out[i] = (found[i], True) if found[i] is not None else (last_resort[i], False)
    return out


class _Fallbacks:
    """The detour, then the loiter fallback, of some routes. The detour is scanned up front and its
    Illinois job (``jobs``) solved with other jobs if the caller wishes; ``finish`` gives what
    ``_detours``, then ``_delays_on_start_circle`` for the routes it leaves without any exact path
    (not for routes whose exact detours all cross a threat: choice, see the module docstring),
    give. (The loiter scan is not started early: it is needed for few detoured routes and costs
    more than its share of a lockstep run saves.)"""

    def __init__(self, routes: list[Route], lengths_m: list[float]) -> None:
        self.routes, self.lengths_m = routes, lengths_m
        self.detour = _DetourPlan(routes, lengths_m)
        self.jobs = [self.detour.job]

    def finish(self, solved: list, threats: list[Threat], ds_m: float, only=None) -> list:
        """Segments or None per route (routes in ``only``, default all; None for the others)."""
        out = self.detour.finish(solved[0], threats, ds_m, only)
        left = [
            k
            for k in (range(len(self.routes)) if only is None else only)
            if out[k] is None and k not in self.detour.blocked
        ]
        if left:
            found = _delays_on_start_circle(
                [self.routes[k] for k in left], [self.lengths_m[k] for k in left], threats, ds_m
            )
            for k, segs in zip(left, found):
                out[k] = segs
        return out


def _stretch_or_push(
    route: Route, links: list[DubinsPath], length_m: float, threats: list[Threat], ds_m: float, stretched
):
    """The first timing steps: ((segments, clear) or None, the segments to use if every step fails);
    links: the route's shortest links (``_route_links``)."""
    extra = length_m - sum(p.length for p in links)
    if extra <= 1e-6:
        return (links, route.clear), links
    fallback = None
    for j in [len(links) - 1, *range(len(links) - 1)]:
        a, b = route.poses[j], route.poses[j + 1]
        if stretched is not None and len(links) == 1:
            p = stretched[0]
        else:
            p = stretch_batch(a[None], b[None], np.array([links[j].length + extra]), np.array([route.r_m]))[0]
        if p is None:
            continue
        trial = links[:j] + [p] + links[j + 1 :]
        ok = clearance_m(_samples(p, ds_m)[:, :2], threats) >= 0.0
        if ok:
            return (trial, route.clear), trial
        fallback = fallback or trial
    if len(route.poses) > 2:  # lengthen by pushing the safe points outwards (larger kappa), on a grid
        sig = np.geomspace(1.0, 8.0, 200)
        total = _links_lengths([route.pushed(x) for x in sig], route.r_m)
        below = np.flatnonzero(total <= length_m)
        if len(below) and below[-1] < len(sig) - 1:
            poses = route.pushed(sig[below[-1]])
            links = [_shortest(a, b, route.r_m) for a, b in zip(poses[:-1], poses[1:])]
            rest = length_m - sum(p.length for p in links)
            p = stretch_batch(
                poses[-2][None], poses[-1][None], np.array([links[-1].length + rest]), np.array([route.r_m])
            )[0]
            if p is not None:
                trial = [*links[:-1], p]
                xy = np.concatenate([_samples(q, ds_m)[:, :2] for q in trial])
                if clearance_m(xy, threats) >= 0.0:
                    return (trial, True), trial
    return None, fallback or links


def _delays_on_start_circle(
    routes: list[Route], lengths_m: list[float], threats: list[Threat], ds_m: float
) -> list[list[DubinsPath] | None]:
    """Loiter fallback: fly s along the first link, an arc of length a on a turning circle there, then
    the shortest route on, with s + a + L = length_m (scan of a over up to 3 loops, Illinois refine);
    s in 0, 1/4, 1/2, 3/4 of the first link, left then right turn, the first two roots of each.
    None for a route where nothing clears the threats. The eight scans of every route share one
    batched Dubins call, all roots are refined together, and the candidates are checked in one
    pass; each route takes its first clear candidate in that order."""
    plan = _LoiterPlan(routes, lengths_m)
    return plan.finish(_solve([plan.job])[0], threats, ds_m)


class _LoiterPlan:
    """_delays_on_start_circle in steps: the scan (here), one Illinois job, then ``finish``."""

    def __init__(self, routes: list[Route], lengths_m: list[float]) -> None:
        owner, leads, starts, targets, kappas = [], [], [], [], []
        firsts = _route_links([Route(rt.poses[:2], rt.r_m, 0.0, True) for rt in routes])
        for k, (route, length_m, (first,)) in enumerate(zip(routes, lengths_m, firsts)):
            for frac in (0.0, 0.25, 0.5, 0.75):
                lead = _truncate(first, frac * first.length)
                q0 = np.asarray(lead.end) if lead.length > 0 else route.poses[0]
                for side in (1.0, -1.0):
                    owner.append(k)
                    leads.append(lead)
                    starts.append(q0)
                    targets.append(length_m - lead.length)
                    kappas.append(side / route.r_m)
        self.n, self.lengths_m, self.leads = len(routes), lengths_m, leads
        owner, starts, targets, kappas = (
            np.array(owner),
            np.array(starts),
            np.array(targets),
            np.array(kappas),
        )
        goal = np.array([routes[k].poses[-1] for k in owner])
        r = np.array([routes[k].r_m for k in owner])
        a = np.array([np.linspace(0.0, 3 * TWO_PI * routes[k].r_m, 600) for k in owner])  # (combos, 600)
        self.owner, self.starts, self.kappas, self.goal, self.r = owner, starts, kappas, goal, r

        def f(combo: np.ndarray, x: np.ndarray) -> np.ndarray:
            pose = _advance_arc(starts[combo], kappas[combo], x)
            return x + shortest_lengths(pose, goal[combo], r[combo]) - targets[combo]

        grid_combo, grid_a = np.repeat(np.arange(len(starts)), a.shape[1]), a.ravel()
        pose = _advance_arc(starts[grid_combo], kappas[grid_combo], grid_a)
        lower = _lower_bound(pose, goal[grid_combo], r[grid_combo], grid_a - targets[grid_combo]).reshape(
            a.shape
        )
        F = _scan(lower, lambda i: f(grid_combo[i], grid_a[i]))
        cross = (np.sign(F[:, :-1]) != np.sign(F[:, 1:])) & (
            np.abs(F[:, 1:] - F[:, :-1]) < np.pi * r[:, None]
        )
        cands = [(b, c) for b in range(len(starts)) for c in np.flatnonzero(cross[b])[:2]]
        self.job = None
        if cands:
            combo, ci = np.array(cands).T
            self.combo = combo
            self.job = _Job(
                a[combo, ci],
                a[combo, ci + 1],
                12,
                lambda x: (_advance_arc(starts[combo], kappas[combo], x), goal[combo], r[combo]),
                lambda x, seg: x + seg.sum(axis=2).min(axis=1) - targets[combo],
            )

    def finish(self, solved, threats: list[Threat], ds_m: float, only=None) -> list[list[DubinsPath] | None]:
        """Each route's first clear candidate (routes in ``only``, default all), given ``_solve``'s
        result for ``job``."""
        out: list[list[DubinsPath] | None] = [None] * self.n
        if solved is None:
            return out
        keep = np.ones(len(self.combo), bool) if only is None else np.isin(self.owner[self.combo], list(only))
        combo, sol = self.combo[keep], solved[0][keep]
        if not len(combo):
            return out
        r, starts, kappas = self.r, self.starts, self.kappas
        arcs = [
            DubinsPath(_pose(starts[b]), "LSL" if kappas[b] > 0 else "RSR", (x, 0.0, 0.0), (rb, math.inf, rb))
            for b, x, rb in zip(combo, sol, r[combo].tolist())
        ]
        ends = np.array([arc.end for arc in arcs])
        lens = word_lengths(ends, self.goal[combo], r[combo])
        w = lens.sum(2).argmin(1)
        trials = [
            [p for p in (self.leads[b], arc, _path(ends[j], w[j], lens[j, w[j]], r[b], r[b])) if p.length > 0]
            for j, (b, arc) in enumerate(zip(combo, arcs))
        ]
        owner = self.owner[combo]
        exact = [
            abs(sum(p.length for p in trial) - self.lengths_m[k]) <= 1e-2 for trial, k in zip(trials, owner)
        ]
        for k, j in _first_clear(trials, owner, exact, threats, ds_m).items():
            out[k] = trials[j]
        return out


def _detours(
    routes: list[Route], lengths_m: list[float], threats: list[Threat], ds_m: float
) -> list[list[DubinsPath] | None]:
    """Lengthen through a via pose at distance rho and bearing theta from the goal, heading at it:
    for each of 24 bearings, solve L(prev -> via(rho)) + L(via(rho) -> goal) = need over rho
    (scan, Illinois refine); the first solution whose two links clear the threats is taken.
    For every route at once: both links of every grid point / candidate of every route go through
    one batched Dubins call and all candidates are checked for clearance in one pass (the order
    of preference within a route is unchanged)."""
    plan = _DetourPlan(routes, lengths_m)
    return plan.finish(_solve([plan.job])[0], threats, ds_m)


class _DetourPlan:
    """_detours in steps: the scan (here), one Illinois job, then ``finish``."""

    def __init__(self, routes: list[Route], lengths_m: list[float]) -> None:
        prev = np.array([route.poses[-2] for route in routes])
        goal = np.array([route.poses[-1] for route in routes])
        r = np.array([route.r_m for route in routes])
        heads = _route_links([Route(rt.poses[:-1], rt.r_m, 0.0, True) for rt in routes])
        need = np.array([length_m - sum(p.length for p in head) for length_m, head in zip(lengths_m, heads)])
        theta = np.linspace(0, TWO_PI, 24, endpoint=False)
        rho = np.array([np.linspace(rk, max(nk, 2 * rk), 30) for rk, nk in zip(r, need)])  # (routes, 30)
        self.n, self.lengths_m, self.heads, self.prev, self.goal, self.r = (
            len(routes),
            lengths_m,
            heads,
            prev,
            goal,
            r,
        )

        def links(g: np.ndarray, v: np.ndarray) -> np.ndarray:
            """Segment lengths (2, n, 6, 3) of prev -> v and v -> goal."""
            return word_lengths(*self._pairs(g, v)).reshape(2, len(v), 6, 3)

        def f(g: np.ndarray, rho: np.ndarray, th: np.ndarray) -> np.ndarray:
            a, b = links(g, self._via(g, rho, th)).sum(3).min(2)
            return a + b - need[g]

        shape = (len(routes), len(theta), rho.shape[1])
        G = np.repeat(np.arange(len(routes)), shape[1] * shape[2])
        RHO = np.broadcast_to(rho[:, None, :], shape).ravel()
        TH = np.broadcast_to(theta[None, :, None], shape).ravel()
        v = self._via(G, RHO, TH)
        lower = _lower_bound(prev[G], v, r[G], RHO - need[G])
        F = _scan(lower.reshape(-1, shape[2]), lambda i: f(G[i], RHO[i], TH[i])).reshape(shape)
        cross = (np.sign(F[..., :-1]) != np.sign(F[..., 1:])) & (
            np.abs(F[..., 1:] - F[..., :-1]) < np.pi * r[:, None, None]
        )
        g, ti, ri = [], [], []
        for k in range(len(routes)):
            t_k, r_k = np.nonzero(cross[k])
            first = np.argsort(r_k, kind="stable")[:16]  # the nearest via rings first
            g += [k] * len(first)
            ti.append(t_k[first])
            ri.append(r_k[first])
        self.job = None
        if g:
            g, ti, ri = np.array(g), np.concatenate(ti), np.concatenate(ri)
            th = theta[ti]
            self.g, self.th = g, th
            self.job = _Job(
                rho[g, ri],
                rho[g, ri + 1],
                12,
                lambda x: self._pairs(g, self._via(g, x, th)),
                lambda x, seg: (lambda a, b: a + b - need[g])(*seg.reshape(2, len(x), 6, 3).sum(3).min(2)),
                final=True,
            )

    def _via(self, g: np.ndarray, rho: np.ndarray, th: np.ndarray) -> np.ndarray:
        """Via poses of route g[i] at rho[i], th[i]."""
        goal = self.goal
        vx, vy = goal[g, 0] + rho * np.cos(th), goal[g, 1] + rho * np.sin(th)
        return np.column_stack([vx, vy, np.arctan2(goal[g, 1] - vy, goal[g, 0] - vx)])

    def _pairs(self, g: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """word_lengths rows of the links prev -> v, then v -> goal."""
        return (
            np.concatenate([self.prev[g], v]),
            np.concatenate([v, self.goal[g]]),
            np.concatenate([self.r[g]] * 2),
        )

    def finish(self, solved, threats: list[Threat], ds_m: float, only=None) -> list[list[DubinsPath] | None]:
        """Each route's first clear candidate (routes in ``only``, default all), given ``_solve``'s
        result for ``job``."""
        out: list[list[DubinsPath] | None] = [None] * self.n
        self.blocked: set[int] = set()  # routes whose exact detours all cross a threat
        if solved is None:
            return out
        sol, seg = solved
        g, r = self.g, self.r
        lens_all = seg.reshape(2, len(sol), 6, 3)
        order = []  # per route: the candidates nearest its smallest root first
        for k in range(self.n) if only is None else sorted(only):
            idx = np.flatnonzero(g == k)
            if len(idx):
                order.append(idx[np.argsort(np.abs(sol[idx] - sol[idx].min()))])
        if not order:
            return out
        order = np.concatenate(order)
        g, v, lens = g[order], self._via(g[order], sol[order], self.th[order]), lens_all[:, order]
        w = lens.sum(3).argmin(2)
        trials = []
        for j, k in enumerate(g):
            ends = ((0, self.prev[k]), (1, v[j]))
            trials.append(
                [*self.heads[k], *(_path(a, w[h, j], lens[h, j, w[h, j]], r[k], r[k]) for h, a in ends)]
            )
        chains = [[p for p in trial if p.length > 0] for trial in trials]
        exact = [abs(sum(p.length for p in trial) - self.lengths_m[k]) <= 1e-2 for trial, k in zip(trials, g)]
        for k, j in _first_clear(chains, g, exact, threats, ds_m).items():
            out[k] = chains[j]
        self.blocked = {int(k) for k, e in zip(g, exact) if e and out[k] is None}
        return out


def _first_clear(chains: list[list[DubinsPath]], owner, exact: list[bool], threats, ds_m: float) -> dict:
    """{owner: index of its first chain (in list order) that is exact and clears the threats}.

    The first exact chain of every owner is checked first, the others only for owners it leaves
    without one (usually the first candidate clears, so most chains are never sampled)."""
    cands = [j for j in range(len(chains)) if exact[j]]
    firsts: dict = {}
    for j in cands:
        firsts.setdefault(owner[j], j)
    pick: dict = {}
    rest = [j for j in cands if firsts[owner[j]] != j]
    for batch in (list(firsts.values()), rest):
        batch = [j for j in batch if owner[j] not in pick]
        for j, ok in zip(batch, chains_clear([chains[j] for j in batch], threats, ds_m)):
            if ok and owner[j] not in pick:
                pick[owner[j]] = j
    return pick


def _reach_lower_bound(q: np.ndarray, p: np.ndarray, r: np.ndarray) -> np.ndarray:
    """A lower bound [m] of the length of any path of curvature <= 1/r from poses q (n, 3) to points p (n, 2).

    For a point outside both turning circles the shortest such path is a turn then a straight
    tangent (CS, Dubins 1957; the free-heading optimum), so min over both turn directions of
    arc + tangent bounds every fixed-heading Dubins path too. Arcs within 1e-6 rad of a full turn
    count as 0 (as ``word_lengths`` snaps them); inside or on a turning circle the bound is the
    Euclidean distance."""
    x, y, h = q[:, 0], q[:, 1], q[:, 2]
    dx0, dy0 = p[:, 0] - x, p[:, 1] - y
    rs, rc = r * np.sin(h), r * np.cos(h)
    best, outside = np.full(len(q), np.inf), np.ones(len(q), bool)
    for s in (1.0, -1.0):
        dx, dy = dx0 + s * rs, dy0 - s * rc  # point relative to the turning circle's centre
        dist = np.hypot(dx, dy)
        outside &= dist > r * (1.0 + 1e-9)
        tangent = np.sqrt(np.maximum(dist * dist - r * r, 0.0))
        leave = np.arctan2(dy, dx) + s * np.arcsin(np.minimum(r / np.maximum(dist, 1e-9), 1.0))
        turn = np.mod(s * (leave - h), TWO_PI)
        best = np.minimum(best, np.where(turn > TWO_PI - 1e-6, 0.0, turn) * r + tangent)
    euclid = np.hypot(dx0, dy0)
    return np.where(outside, np.maximum(best, euclid), euclid)


def _dubins_lower_bound(q0: np.ndarray, q1: np.ndarray, r: np.ndarray) -> np.ndarray:
    """A lower bound [m] of the Dubins length q0 -> q1 (n, 3) with radius r (n,): the larger of the
    reach bounds forwards from q0 to q1's point and backwards (reversed q1 heading) to q0's point."""
    back = np.column_stack([q1[:, 0], q1[:, 1], q1[:, 2] + math.pi])
    return np.maximum(_reach_lower_bound(q0, q1[:, :2], r), _reach_lower_bound(back, q0[:, :2], r))


def _lower_bound(q0: np.ndarray, q1: np.ndarray, r: np.ndarray, rest: np.ndarray) -> np.ndarray:
    """A lower bound of Dubins length (q0 -> q1) + rest (n,): Euclidean, replaced by
    ``_dubins_lower_bound`` (about 10x the cost) only where the Euclidean one is <= 1 mm."""
    out = np.hypot(q1[:, 0] - q0[:, 0], q1[:, 1] - q0[:, 1]) + rest
    m = np.flatnonzero(out <= 1e-3)
    out[m] = _dubins_lower_bound(q0[m], q1[m], r[m]) + rest[m]
    return out


def _scan(lower: np.ndarray, fun) -> np.ndarray:
    """A root scan grid F (rows, cols) whose sign changes along each row are the candidate roots.

    lower <= F is a cheap lower bound (``_dubins_lower_bound`` instead of Dubins lengths). Where lower > 1 mm
    the sign of F is known (+), so F is evaluated (fun(flat indices)) only where it may be <= 0
    and at their row neighbours, which the jump test |F[j+1] - F[j]| needs; elsewhere lower
    stands in. Sign changes and their F values are exactly those of the full grid.
    """
    may = lower <= 1e-3
    need = may.copy()
    need[:, 1:] |= may[:, :-1]
    need[:, :-1] |= may[:, 1:]
    F = lower.copy()
    idx = np.flatnonzero(need)
    if len(idx):
        F.ravel()[idx] = fun(idx)
    return F


def _truncate(path: DubinsPath, s_m: float) -> DubinsPath:
    """The first s_m metres of a Dubins path."""
    ends = np.cumsum(path.lengths)
    lengths = np.clip(s_m - np.r_[0.0, ends[:2]], 0.0, np.asarray(path.lengths))
    return DubinsPath(path.start, path.word, tuple(float(v) for v in lengths), path.radii)


def _advance_arc(q0: np.ndarray, kappa: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Poses (n, 3) after flying arc lengths s (n,) from q0 (n, 3) on circles of curvature kappa (n,)."""
    h = q0[:, 2] + kappa * s
    return np.column_stack(
        [
            q0[:, 0] + (np.sin(h) - np.sin(q0[:, 2])) / kappa,
            q0[:, 1] - (np.cos(h) - np.cos(q0[:, 2])) / kappa,
            h,
        ]
    )


def sample_segments(
    paths: list[DubinsPath], t0_s: float, speed_mps: float, ds_m: float, kind: str, info=None
) -> Leg:
    """Sample a chain of Dubins paths at <= ds_m into a timed Leg starting at t0_s."""
    return sample_legs([paths], t0_s, np.array([speed_mps]), ds_m, [kind], [info])[0]


def sample_legs(
    chains: list[list[DubinsPath]], t0_s: float, speed_mps: np.ndarray, ds_m: float, kinds: list[str], infos
) -> list[Leg]:
    """sample_segments for many chains at once (one vectorised sampling of all their paths)."""
    s, q, n = _sample_flat([p for ch in chains for p in ch], ds_m)
    q[..., 2] = wrap_pi(q[..., 2])  # as DubinsPath.sample
    legs, j = [], 0
    for chain, speed, kind, info in zip(chains, speed_mps, kinds, infos):
        pts, ss, s_off = [], [], 0.0
        for i, p in enumerate(chain):
            first = 1 if i else 0  # a segment starts where the previous one ended
            pts.append(q[j, first : n[j]])
            ss.append(s[j, first : n[j]] + s_off)
            s_off += p.length
            j += 1
        qc, sc = np.concatenate(pts), np.concatenate(ss)
        legs.append(Leg(t0_s + sc / speed, qc[:, :2], qc[:, 2], kind, dict(info or {})))
    return legs


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
