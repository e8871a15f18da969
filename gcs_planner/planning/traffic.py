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
neighbour query would return them; the pairs are sorted only where a query has more than four.
"""

from __future__ import annotations

import numpy as np

from gcs_planner.geometry.timing import closest_under_timing_t, dot3

__all__ = ["TIMING_ERROR_S", "Traffic"]

# How far apart in time two vehicles' schedule errors may be where they meet [s]: measured on the
# mock (docs/timing-separation.md), the default of the planners' ``timing_error_s``.
TIMING_ERROR_S = 0.75

_CELL_BITS = 6  # cells per axis in the table: 64, aliased 64 cells apart (extra candidates)
_BLOCKS = 1 << 2 * _CELL_BITS
_NEAREST = 4  # traffic samples counted per particle sample
_EMPTY = np.zeros(0, dtype=np.int64)


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
        self.xyz = np.zeros((3, 0))  # sample positions, component-first
        self.slice = _EMPTY
        self.sep = np.zeros(0)
        self.next = _EMPTY  # the same vehicle's sample at the next slice (-1 at its last)
        self.n_entries = 0
        # per hash entry: its sample << 32 | the next entry of the same table cell (-1 at its last),
        # so that following a chain reads one place per step
        self.entries = _EMPTY
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
        self.xyz = np.concatenate([self.xyz, np.zeros((3, new - cap))], axis=1)
        self.slice, self.next = (
            np.concatenate([a, np.full(new - cap, -1, dtype=np.int64)]) for a in (self.slice, self.next)
        )
        self.sep = np.concatenate([self.sep, np.zeros(new - cap)])

    def _grow_entries(self, extra: int) -> None:
        cap = len(self.entries)
        if self.n_entries + extra <= cap:
            return
        new = max(2 * cap, self.n_entries + extra, 4096)
        self.entries = np.concatenate([self.entries, np.full(new - cap, -1, dtype=np.int64)])

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
        self.xyz[:, idx] = pos.T
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
        self.entries[ent] = sample[order] << 32 | nxt & 0xFFFFFFFF
        last = np.append(first[1:], True)
        self.head[key[last]] = ent[last]
        self.n_entries += m
        self.n += k
        self.v_max = max(self.v_max, *(u[3] for u in uavs))
        self.sep_max = max(self.sep_max, *(u[2] for u in uavs))

    def neighbours(
        self, slices: np.ndarray, pos: np.ndarray, radius_m: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """Pairs (query row, traffic sample) of the same slice closer than ``radius_m``: the
        ``_NEAREST`` nearest per query, ordered by query then distance (then sample). slices (Q,),
        pos (Q, 3)."""
        row, j, d2 = self._near_pairs(slices, pos, radius_m)
        order = np.lexsort((j, d2, row))
        return row[order], j[order]

    def _near_pairs(
        self, slices: np.ndarray, pos: np.ndarray, radius_m: float
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``neighbours``' pairs and squared distances, in no particular order: only a query with
        more than ``_NEAREST`` pairs needs its pairs sorted."""
        extra = max(radius_m - self.reach_m, 0.0)  # beyond what a sample's entries cover
        span = int(np.ceil(2.0 * extra / self.cell_m)) + 1 if extra > 0 else 1
        cx, cy = self._cells(pos[:, :2] - extra)
        inside = np.flatnonzero((slices >= 0) & (slices < self.slices))  # no traffic after its last slice
        cx, cy, sl = cx[inside], cy[inside], slices[inside]
        if span == 1:
            q = inside
            cand = self.head[_block(cx, cy) * self.slices + sl]
        else:
            off = np.arange(span)
            ox, oy = (o.ravel() for o in np.meshgrid(off, off, indexing="ij"))
            key = _block(cx[:, None] + ox, cy[:, None] + oy) * self.slices + sl[:, None]
            cand = self.head[key.ravel()]
            q = np.repeat(inside, len(ox))
        rows, samples = [], []
        while len(q):
            live = cand >= 0
            q, cand = q[live], cand[live]
            rows.append(q)
            entry = self.entries.take(cand)
            samples.append(entry >> 32)
            cand = entry << 32 >> 32
        if not rows:
            return _EMPTY, _EMPTY, np.zeros(0)
        row, j = np.concatenate(rows), np.concatenate(samples)
        x, y, z = self.xyz
        q = pos.take(row, axis=0)
        d2 = (x.take(j) - q[:, 0]) ** 2 + (y.take(j) - q[:, 1]) ** 2
        d2 += (z.take(j) - q[:, 2]) ** 2
        near = d2 < radius_m**2
        row, j, d2 = row[near], j[near], d2[near]
        if span > 1:  # a sample entered in several of the cells read: sort, drop the repeats
            order = np.lexsort((j, d2, row))
            row, j, d2 = row[order], j[order], d2[order]
            fresh = np.ones(len(row), dtype=bool)
            fresh[1:] = (row[1:] != row[:-1]) | (j[1:] != j[:-1])
            row, j, d2 = row[fresh], j[fresh], d2[fresh]
        crowded = np.flatnonzero(np.bincount(row, minlength=len(pos))[row] > _NEAREST)
        if not len(crowded):
            return row, j, d2
        order = crowded[
            np.lexsort((j[crowded], d2[crowded], row[crowded]))
        ]  # the crowded queries, nearest first
        ranked = row[order]
        keep = np.ones(len(row), dtype=bool)
        keep[order[np.arange(len(order)) - np.searchsorted(ranked, ranked) >= _NEAREST]] = False
        return row[keep], j[keep], d2[keep]

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
        p, k, _ = pos.shape
        zero = np.zeros(p)
        idx = np.flatnonzero(valid.ravel())
        if not self.n or not len(idx):
            return zero, zero.copy()
        v_max = max(self.v_max, 1e-6)
        radius = max(self.sep_max, sep_m) + margin_m + timing_s * v_max + 2.0 * v_max * self.dt_s
        flat_pos = pos.reshape(-1, 3)
        # take: several times faster than fancy indexing for rows of a 2-D array (the method, not
        # np.take: no dispatch on a path called ~900,000 times a plan)
        row, j, d2 = self._near_pairs(np.tile(slices, p)[idx], flat_pos.take(idx, axis=0), radius)
        if not len(row):
            return zero, zero.copy()
        # vectors component-first (3, pairs): a reduction over a last axis of 3 is slow
        flat = idx[row]  # particle sample = particle * k + slice offset
        part = flat // k
        nxt = self.next[j]
        after = np.minimum(flat + 1, len(flat_pos) - 1)
        has_next = (flat - part * k + 1 < k) & valid.ravel()[after] & (nxt >= 0)
        a0 = flat_pos.take(flat, axis=0).T
        b0 = self.xyz.take(j, axis=1)
        a1 = np.where(has_next, flat_pos.take(after, axis=0).T, a0)
        b1 = np.where(has_next, self.xyz.take(np.where(nxt >= 0, nxt, j), axis=1), b0)
        d0 = b0 - a0
        dv = (b1 - a1) - d0
        vv = dot3(dv, dv)
        tau = np.clip(-dot3(d0, dv) / np.where(vv > 0, vv, 1.0), 0.0, 1.0)
        closest = d0 + tau * dv
        dmin = np.sqrt(dot3(closest, closest))
        need = np.maximum(self.sep[j], sep_m) + margin_m
        if timing_s > 0:  # under any relative schedule error up to timing_s (geometry/timing.py)
            w = (b1 - b0) * (timing_s / self.dt_s)
            near = dmin - np.sqrt(dot3(w, w)) < need  # a shift by w moves it at most |w|
            dmin[near] = closest_under_timing_t(d0[:, near], dv[:, near], w[:, near])
        short = np.maximum(0.0, need - dmin)
        # summed per particle in the nearest-first order of neighbours(); a pair short of nothing
        # adds 0 to its sum, so only the others need that order
        hit = np.flatnonzero(short != 0.0)
        hit = hit[np.lexsort((j[hit], d2[hit], row[hit]))]
        depth = np.bincount(part[hit], weights=short[hit], minlength=p)
        count = np.bincount(part[hit], weights=(short[hit] > 0).astype(float), minlength=p)
        return depth, count
