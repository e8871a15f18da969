"""Timed samples of already-planned UAVs and the separation they leave a new path (priority swarm F5).

Every planned UAV adds its positions on the shared time grid (slice k = time k * dt_s). A new
path's samples are compared with the traffic samples of the same slice within reach: for each
pair the closest approach of the two linear motions over the slice must exceed the larger
separation plus a margin, else the shortfall counts.

With ``timing_s`` > 0 the closest approach is the one under any relative schedule error up to
``timing_s`` seconds (gcs_planner.geometry.timing: the traffic sample moved along its motion by
up to its displacement in that time), so a crossing keeps its separation when the vehicles fly
it that far off their schedules (docs/timing-separation.md). ``timing_s = 0`` is the plain one.

Neighbours are found in a spatial hash of (x cell, y cell, slice) -> a linked list of entries
(``head`` per hashed cell, a next entry per entry): every sample is entered in each cell that
the square of half-width ``cell_m / 2`` around it meets, so a query within that radius reads the
one cell its own point lies in (one random read per query). The table is laid out cell-major (a
cell's slices are adjacent), so the consecutive slices of one path read nearby memory. Adding
UAVs is one vectorised insertion, with no rebuild of what is there. At most the four nearest
traffic samples within reach count per particle sample, nearest first, as a k = 4 nearest-
neighbour query would return them.

The look-up and the separation check are compiled (numba): one pass per particle sample walks its
cell's chain and keeps the nearest four, where numpy passes over every candidate pair spent most of
their time on temporaries. Their arithmetic is the vectorised code's term for term (no fused
multiply-adds, sums in the same order), so plans stayed the same bit for bit.
"""

from __future__ import annotations

import numpy as np

from gcs_planner.core.compiled import compiled
from gcs_planner.geometry.nearest import keep_nearest
from gcs_planner.geometry.timing import closest_on_segment, closest_under_timing_one
from gcs_planner.geometry.vec3 import dot, row, scale, sub

__all__ = ["TIMING_ERROR_S", "Traffic"]

# How far apart in time two vehicles' schedule errors may be where they meet [s]: measured on the
# mock (docs/timing-separation.md), the default of the planners' ``timing_error_s``.
TIMING_ERROR_S = 0.75

_CELL_BITS = 6  # cells per axis in the table: 64, aliased 64 cells apart (extra candidates)
_BLOCKS = 1 << 2 * _CELL_BITS
_NEAREST = 4  # traffic samples counted per particle sample
_EMPTY = np.zeros(0, dtype=np.int64)
# a hash entry: its sample and the next entry of the same table cell (-1 at its last)
_ENTRY = np.dtype([("sample", "i4"), ("next", "i4")])


@compiled
def _block(cx: np.ndarray, cy: np.ndarray) -> np.ndarray:
    """Table block of an (x cell, y cell)."""
    mask = (1 << _CELL_BITS) - 1
    return (cy & mask) << _CELL_BITS | cx & mask


class Traffic:
    """Timed samples of already-planned UAVs on the shared time grid, hashed by cell and slice."""

    def __init__(self, dt_s: float, cell_m: float = 40.0) -> None:
        self.dt_s, self.cell_m = dt_s, cell_m
        self.reach_m = 0.5 * cell_m  # the half-width of the square each sample is entered for
        self.n = 0
        self.xyz = np.zeros((0, 3))  # sample positions
        self.slice = _EMPTY
        self.sep = np.zeros(0)
        self.next = _EMPTY  # the same vehicle's sample at the next slice (-1 at its last)
        self.n_entries = 0
        self.entries = np.zeros(0, dtype=_ENTRY)
        self.slices = 0  # slices per block of the table
        self.head = np.zeros(0, dtype=np.int32)  # first entry per (block, slice), block-major
        self.v_max = 0.0
        self.sep_max = 0.0

    def __len__(self) -> int:
        return self.n

    def _grow(self, extra: int) -> None:
        cap = len(self.slice)
        if self.n + extra <= cap:
            return
        new = max(2 * cap, self.n + extra, 1024)
        self.xyz = np.concatenate([self.xyz, np.zeros((new - cap, 3))])
        self.slice, self.next = (
            np.concatenate([a, np.full(new - cap, -1, dtype=np.int64)]) for a in (self.slice, self.next)
        )
        self.sep = np.concatenate([self.sep, np.zeros(new - cap)])

    def _grow_entries(self, extra: int) -> None:
        cap = len(self.entries)
        if self.n_entries + extra <= cap:
            return
        new = max(2 * cap, self.n_entries + extra, 4096)
        self.entries = np.concatenate([self.entries, np.zeros(new - cap, dtype=_ENTRY)])

    def _grow_slices(self, needed: int) -> None:
        """Widen every block of the table to ``needed`` slices or more (a copy, rarely)."""
        if needed <= self.slices:
            return
        wide = max(needed, 2 * self.slices, 256)
        head = np.full((_BLOCKS, wide), -1, dtype=np.int32)
        head[:, : self.slices] = self.head.reshape(_BLOCKS, self.slices)
        self.head, self.slices = head.ravel(), wide

    def _cells(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        c = np.floor(xy / self.cell_m).astype(np.int64)
        return c[:, 0], c[:, 1]

    def add(self, slices: np.ndarray, pos: np.ndarray, sep_m: float, speed: float) -> None:
        """Add one UAV's samples at grid slices (K,) (each slice once) -> positions (K, 3)."""
        self.add_many([(slices, pos, sep_m, speed)])

    def add_many(self, uavs: list[tuple[np.ndarray, np.ndarray, float, float]]) -> None:
        """Add UAVs (slices (K,), positions (K, 3), separation, speed) in one insertion; the same
        samples, in the same order, as ``add`` one by one."""
        uavs = [(np.asarray(sl, dtype=np.int64), pos, sep, v) for sl, pos, sep, v in uavs]
        uavs = [u for u in uavs if len(u[0])]
        if not uavs:
            return
        sizes = np.array([len(u[0]) for u in uavs])
        k = int(sizes.sum())
        slices = np.concatenate([u[0] for u in uavs])
        pos = np.concatenate([np.asarray(u[1], dtype=float).reshape(-1, 3) for u in uavs])
        self._grow(k)
        self._grow_slices(int(slices.max()) + 1)
        idx = np.arange(self.n, self.n + k)
        self.xyz[idx] = pos
        self.slice[idx] = slices
        self.sep[idx] = np.repeat([u[2] for u in uavs], sizes)
        self.next[idx] = idx + 1
        self.next[self.n + np.cumsum(sizes) - 1] = -1  # each UAV's last sample
        lo_x, lo_y = self._cells(pos[:, :2] - self.reach_m)
        hi_x, hi_y = self._cells(pos[:, :2] + self.reach_m)
        keys, samples = [], []
        for dx in (0, 1):  # the cells the sample's square meets: 1 or 2 per axis (cell = 2 reach)
            for dy in (0, 1):
                on = (lo_x + dx <= hi_x) & (lo_y + dy <= hi_y)
                keys.append(_block(lo_x[on] + dx, lo_y[on] + dy) * self.slices + slices[on])
                samples.append(idx[on])
        key, sample = np.concatenate(keys), np.concatenate(samples)
        m = len(key)
        self._grow_entries(m)
        order = np.argsort(key, kind="stable")  # entries of one table cell in a run, oldest first
        key, ent = key[order], np.arange(self.n_entries, self.n_entries + m)
        first = np.ones(m, dtype=bool)
        first[1:] = key[1:] != key[:-1]
        nxt = np.empty(m, dtype=np.int64)  # each entry links to the one before it in its cell
        nxt[first] = self.head[key[first]]
        nxt[~first] = ent[:-1][~first[1:]]
        self.entries["sample"][ent] = sample[order]
        self.entries["next"][ent] = nxt
        last = np.append(first[1:], True)
        self.head[key[last]] = ent[last]
        self.n_entries += m
        self.n += k
        self.v_max = max(self.v_max, *(u[3] for u in uavs))
        self.sep_max = max(self.sep_max, *(u[2] for u in uavs))

    def _query(self, radius_m: float) -> tuple:
        """The hash table and the cells a query within ``radius_m`` reads, as ``_nearest`` takes them."""
        extra = max(radius_m - self.reach_m, 0.0)  # beyond what a sample's entries cover
        span = int(np.ceil(2.0 * extra / self.cell_m)) + 1 if extra > 0 else 1
        return self.head, self.entries, self.xyz, self.slices, self.cell_m, extra, span, radius_m**2

    def neighbours(
        self, slices: np.ndarray, pos: np.ndarray, radius_m: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """Pairs (query row, traffic sample) of the same slice closer than ``radius_m``: the
        ``_NEAREST`` nearest per query, ordered by query then distance (then sample). slices (Q,),
        pos (Q, 3)."""
        slices = np.asarray(slices, dtype=np.int64)
        return _all_nearest(self._query(radius_m), slices, np.asarray(pos, dtype=float))

    def violations(
        self,
        slices: np.ndarray,
        pos: np.ndarray,
        valid: np.ndarray,
        sep_m: float,
        margin_m: float,
        timing_s: float = 0.0,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Separation shortfall [m] summed per particle and the number of violating samples.

        slices (K,), pos (P, K, 3), valid (P, K): the particle samples on the grid; the margin is
        ``margin_m`` beyond the separation under any relative schedule error up to ``timing_s``.
        """
        depth, count = np.zeros(len(pos)), np.zeros(len(pos))
        if self.n:
            v_max = max(self.v_max, 1e-6)
            radius = max(self.sep_max, sep_m) + margin_m + timing_s * v_max + 2.0 * v_max * self.dt_s
            limits = (float(sep_m), float(margin_m), timing_s / self.dt_s)
            table = self._query(radius)
            _violations(table, self.next, self.sep, np.asarray(slices, dtype=np.int64), pos, valid, limits,
                        depth, count)  # fmt: skip
        return depth, count


@compiled
def _nearest(table: tuple, sl: int, q: tuple, js: np.ndarray, d2s: np.ndarray) -> int:
    """The ``_NEAREST`` traffic samples of slice ``sl`` within reach of point ``q``, nearest first
    (then by sample), into ``js`` / ``d2s``; returns how many."""
    head, entries, xyz, n_slices, cell_m, extra, span, r2 = table
    if sl < 0 or sl >= n_slices:  # no traffic after its last slice
        return 0
    cx0 = np.int64(np.floor((q[0] - extra) / cell_m))
    cy0 = np.int64(np.floor((q[1] - extra) / cell_m))
    n = 0
    for ox in range(span):
        for oy in range(span):
            e = np.int64(head[_block(cx0 + ox, cy0 + oy) * n_slices + sl])
            while e >= 0:
                j, e = np.int64(entries[e].sample), np.int64(entries[e].next)
                d2 = (xyz[j, 0] - q[0]) ** 2 + (xyz[j, 1] - q[1]) ** 2
                d2 += (xyz[j, 2] - q[2]) ** 2
                if d2 < r2 and j not in js[:n]:  # in reach, and not met in another cell already
                    n = keep_nearest(js, d2s, n, j, d2)
    return n


@compiled
def _all_nearest(table: tuple, slices: np.ndarray, pos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``Traffic.neighbours``: every query's ``_nearest`` as (query row, sample) pairs."""
    rows = np.empty(len(slices) * _NEAREST, dtype=np.int64)
    samples = np.empty_like(rows)
    js, d2s = np.empty(_NEAREST, dtype=np.int64), np.empty(_NEAREST)
    m = 0
    for r in range(len(slices)):
        n = _nearest(table, slices[r], row(pos, r), js, d2s)
        rows[m : m + n] = r
        samples[m : m + n] = js[:n]
        m += n
    return rows[:m], samples[:m]


@compiled
def _violations(table, nxt, sep, slices, pos, valid, limits, depth, count) -> None:
    """``Traffic.violations`` into ``depth`` / ``count`` (P,): for each valid particle sample, its
    nearest traffic samples' closest approach over the slice (both moving linearly to their next
    samples), under the timing error where ``shift`` (= timing_s / dt_s) > 0, short of the need."""
    sep_m, margin_m, shift = limits
    xyz = table[2]
    n_part, k, _ = pos.shape
    js, d2s = np.empty(_NEAREST, dtype=np.int64), np.empty(_NEAREST)
    for p in range(n_part):
        for i in range(k):
            if not valid[p, i]:
                continue
            a0 = (pos[p, i, 0], pos[p, i, 1], pos[p, i, 2])
            n = _nearest(table, slices[i], a0, js, d2s)
            follows = i + 1 < k and valid[p, i + 1]
            for m in range(n):  # nearest first: the order of the sums is the vectorised one's
                j = js[m]
                b0 = row(xyz, j)
                a1, b1 = a0, b0
                if follows and nxt[j] >= 0:
                    a1 = (pos[p, i + 1, 0], pos[p, i + 1, 1], pos[p, i + 1, 2])
                    b1 = row(xyz, nxt[j])
                d0 = sub(b0, a0)
                dv = sub(sub(b1, a1), d0)
                dmin = closest_on_segment(d0, dv, 0.0, 1.0)
                need = max(sep[j], sep_m) + margin_m
                if shift > 0:  # under any relative schedule error up to timing_s (geometry/timing.py)
                    w = scale(sub(b1, b0), shift)
                    if dmin - np.sqrt(dot(w, w)) < need:  # a shift by w moves it at most |w|
                        dmin = closest_under_timing_one(d0, dv, w)
                short = max(0.0, need - dmin)
                if short > 0.0:
                    depth[p] += short
                    count[p] += 1.0
