"""RRT* in 3-D among vertical cylinders (with buffers), domes and an altitude band; seeded.

The standard RRT* (Karaman & Frazzoli 2011) as seed 000 uses it for initial paths (the paper's
printed steer direction and near-set centre are typos; this is the standard algorithm):
sample (goal-biased), nearest, steer by ``step_m``, collision-check the edge, choose the cheapest
collision-free parent among the near set, rewire the near set through the new node and pass the
cost decrease on to the rewired subtrees.

Choices where the paper is open (documented for reproducibility):
- Edges are valid when every cylinder is cleared by ``radius + buffer + margin_m`` (buffers are
  treated as hard here so the initial paths sit outside the threat band) and both ends lie in the
  altitude band (a straight edge between two in-band points stays in the band).
- Sampling box: the scenario bounds if given, else the start/goal box padded by ``pad_m``;
  altitudes uniform in the band. Goal bias 10 %.
- Near radius ``min(gamma (log n / n)^(1/3), 3 step_m)`` with gamma from the sampling volume.
- Nearest/near queries: a brute-force scan of the nodes. The trees hold hundreds to a few thousand
  nodes, where a scan costs less than a k-d tree's query (200 nodes: 8 us against cKDTree's 13 us,
  which also had to be rebuilt as the tree grew).
- The start->goal straight edge is tried first (open field: no tree needed). After the goal is
  first reached, ``extra_iterations`` more samples refine the path; the result is then shortcut
  greedily (drop a vertex when the edge that skips it is valid).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gcs_planner.geometry.obstacles import Obstacles

__all__ = ["RRTConfig", "RRTResult", "rrt_star", "shortcut"]


@dataclass(frozen=True)
class RRTConfig:
    step_m: float = 40.0
    max_iterations: int = 3000
    extra_iterations: int = 300
    goal_bias: float = 0.1
    margin_m: float = 2.0


@dataclass(frozen=True)
class RRTResult:
    path: np.ndarray | None  # (K, 3) start..goal, None when no path was found
    cost_m: float
    iterations: int
    nodes: int


def edges_valid(
    obstacles: Obstacles, a: np.ndarray, b: np.ndarray, z_band: tuple[float, float], margin_m: float
) -> np.ndarray:
    """True (...) where segments a -> b (..., 3) clear every obstacle's buffer + margin and stay in band."""
    return _EdgeCheck(obstacles, z_band, margin_m)(a, b)


class _EdgeCheck:
    """``edges_valid`` for one set of obstacles, band and margin, with what every check shares
    computed once (RRT* asks about one edge at a time, so per-call work is what counts).

    Only the (segment, cylinder) pairs whose axis lies within the clearance of the segment's xy
    bounding box can fail; the exact distance is computed for those alone (most edges have none).
    """

    def __init__(self, obstacles: Obstacles, z_band: tuple[float, float], margin_m: float) -> None:
        self.obs, self.margin_m = obstacles, margin_m
        self.z_lo, self.z_hi = z_band[0] - 1e-9, z_band[1] + 1e-9
        self.need = obstacles.radius_m + obstacles.buffer_m + margin_m
        reach = self.need + 1e-6  # rounding of a point on the segment
        self.x_above, self.x_below = obstacles.cx + reach, obstacles.cx - reach
        self.y_above, self.y_below = obstacles.cy + reach, obstacles.cy - reach

    def __call__(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
        if a.ndim == 1 and b.ndim == 1 and not len(self.obs.dome_radius_m):
            return self._one(a, b)
        ok = np.ones(np.broadcast_shapes(a.shape, b.shape)[:-1], dtype=bool)
        if len(self.obs.radius_m):
            ok &= self._clear_of_cylinders(a, b)
        if len(self.obs.dome_radius_m):
            ok &= np.all(self.obs.dome_distances(a, b) > self.obs.dome_radius_m + self.margin_m, axis=-1)
        for p in (a, b):
            ok &= (p[..., 2] >= self.z_lo) & (p[..., 2] <= self.z_hi)
        return ok

    def _one(self, a: np.ndarray, b: np.ndarray) -> np.bool_:
        """One segment, no domes: the band first, then the cylinders near its bounding box."""
        ax, ay, az = a.tolist()
        bx, by, bz = b.tolist()
        if not (self.z_lo <= az <= self.z_hi and self.z_lo <= bz <= self.z_hi):
            return np.False_
        if not len(self.need):
            return np.True_
        cand = np.flatnonzero(
            (self.x_above > min(ax, bx))
            & (self.x_below < max(ax, bx))
            & (self.y_above > min(ay, by))
            & (self.y_below < max(ay, by))
        )
        if not len(cand):
            return np.True_
        m = len(cand)
        d = self.obs.cylinder_distances_pairs(np.broadcast_to(a, (m, 3)), np.broadcast_to(b, (m, 3)), cand)
        return np.bool_(np.all(d > self.need[cand]))

    def star(self, nodes: np.ndarray, p: np.ndarray) -> np.ndarray:
        """``self(nodes, p)`` for tree nodes (m, 3) and one point p (3,), all in the band (each is
        the end of a valid edge or the start): the band is not checked again, and one point's
        bounds need no broadcasting. RRT* asks this once an iteration (its near set)."""
        if len(self.obs.dome_radius_m):
            return self(nodes, np.broadcast_to(p, nodes.shape))
        px, py = float(p[0]), float(p[1])
        x, y = nodes[:, :1], nodes[:, 1:2]
        box = np.minimum(x, px), np.maximum(x, px), np.minimum(y, py), np.maximum(y, py)
        return self._clear_in_boxes(nodes, np.broadcast_to(p, nodes.shape), *box)

    def _clear_of_cylinders(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """True (...) where segments a -> b clear every cylinder's radius + buffer + margin."""
        a, b = np.broadcast_arrays(a, b)
        shape = a.shape[:-1]
        a, b = a.reshape(-1, 3), b.reshape(-1, 3)
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        return self._clear_in_boxes(a, b, lo[:, :1], hi[:, :1], lo[:, 1:2], hi[:, 1:2]).reshape(shape)

    def _clear_in_boxes(self, a, b, x_lo, x_hi, y_lo, y_hi) -> np.ndarray:
        """True (m,) where segments a -> b (m, 3), with xy bounding boxes (m, 1) each, clear every
        cylinder: exact distances only for the cylinders whose reach meets a segment's box."""
        cand = (self.x_above > x_lo) & (self.x_below < x_hi) & (self.y_above > y_lo) & (self.y_below < y_hi)
        edge, cyl = np.nonzero(cand)
        ok = np.ones(len(a), dtype=bool)
        if len(edge):
            blocked = ~(self.obs.cylinder_distances_pairs(a[edge], b[edge], cyl) > self.need[cyl])
            ok[edge[blocked]] = False
        return ok


def rrt_star(
    start: np.ndarray,
    goal: np.ndarray,
    obstacles: Obstacles,
    box_lo: np.ndarray,
    box_hi: np.ndarray,
    rng: np.random.Generator,
    cfg: RRTConfig = RRTConfig(),
) -> RRTResult:
    """Plan start -> goal (both (3,), inside the band box_lo[2]..box_hi[2])."""
    start, goal = np.asarray(start, float), np.asarray(goal, float)
    band = (float(box_lo[2]), float(box_hi[2]))

    valid = _EdgeCheck(obstacles, band, cfg.margin_m)

    if valid(start, goal):
        return RRTResult(np.vstack([start, goal]), float(np.linalg.norm(goal - start)), 0, 2)
    n_max = cfg.max_iterations + 1
    nodes = np.empty((n_max, 3))
    parent = np.full(n_max, -1)
    cost = np.zeros(n_max)
    nodes[0] = start
    n = 1
    span = box_hi - box_lo
    volume = float(np.prod(np.maximum(span, 1.0)))
    gamma = 2.0 * (1.0 + 1.0 / 3.0) ** (1.0 / 3.0) * (volume / (4.0 / 3.0 * math.pi)) ** (1.0 / 3.0)
    first_hit = None
    it = 0
    for it in range(1, cfg.max_iterations + 1):
        if first_hit is not None and it - first_hit >= cfg.extra_iterations:
            break
        # rng.uniform(box_lo, box_hi)'s arithmetic on the same draws, without its per-call dispatch
        target = goal if rng.random() < cfg.goal_bias else box_lo + span * rng.random(3)
        near_i = _nearest(nodes[:n], target)
        d = target - nodes[near_i]
        dist = _length(d)
        new = target if dist <= cfg.step_m else nodes[near_i] + d * (cfg.step_m / dist)
        if not valid(nodes[near_i], new):
            continue
        radius = min(gamma * (math.log(n + 1) / (n + 1)) ** (1.0 / 3.0), 3.0 * cfg.step_m)
        dist_all = _lengths(nodes[:n] - new)
        inside = dist_all <= max(radius, 1e-6)
        inside[near_i] = True  # the nearest node is always a candidate parent
        near = np.flatnonzero(inside)
        seg = dist_all[near]
        ok = valid.star(nodes[near], new)
        through = np.where(ok, cost[near] + seg, np.inf)
        best = int(np.argmin(through))
        k = n
        nodes[k], parent[k], cost[k] = new, near[best], through[best]
        n += 1
        improve = ok & (cost[k] + seg < cost[near] - 1e-9)
        for j, c_new in zip(near[improve], (cost[k] + seg)[improve]):
            _reparent(parent, cost, n, int(j), k, float(c_new))
        if first_hit is None and _length(goal - new) <= cfg.step_m and valid(new, goal):
            first_hit = it
    # connect the goal to the cheapest valid node within one step
    d_goal = np.linalg.norm(nodes[:n] - goal, axis=1)
    cand = np.flatnonzero(d_goal <= cfg.step_m)
    if len(cand):
        ok = valid(nodes[cand], np.broadcast_to(goal, (len(cand), 3)))
        cand = cand[ok]
    if not len(cand):
        return RRTResult(None, math.inf, it, n)
    total = cost[cand] + d_goal[cand]
    j = int(cand[np.argmin(total)])
    chain = [goal]
    while j >= 0:
        chain.append(nodes[j])
        j = int(parent[j])
    path = shortcut(np.array(chain[::-1]), lambda a, b: valid(a, b))
    return RRTResult(path, float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum()), it, n)


def shortcut(path: np.ndarray, valid) -> np.ndarray:
    """Greedy shortcut: from each kept vertex jump to the farthest vertex reachable by a valid edge."""
    keep = [0]
    i = 0
    while i < len(path) - 1:
        later = np.arange(len(path) - 1, i, -1)
        ok = valid(np.broadcast_to(path[i], (len(later), 3)), path[later])
        i = int(later[np.argmax(ok)]) if ok.any() else i + 1
        keep.append(i)
    return path[keep]


def _nearest(nodes: np.ndarray, x: np.ndarray) -> int:
    """Index of the node closest to ``x``."""
    d = nodes - x
    return int(np.argmin((d * d).sum(axis=1)))


def _length(v: np.ndarray) -> float:
    """|v| of one vector: np.linalg.norm's arithmetic without its per-call dispatch (RRT* asks
    once or twice an iteration; docs/results/priority_swarm_scale.md)."""
    return math.sqrt(v.dot(v))


def _lengths(v: np.ndarray) -> np.ndarray:
    """Row lengths of (n, 3) vectors, as np.linalg.norm(v, axis=1) computes them."""
    return np.sqrt((v * v).sum(axis=1))


def _reparent(parent: np.ndarray, cost: np.ndarray, n: int, j: int, new_parent: int, new_cost: float) -> None:
    """Give node j a cheaper parent and pass the cost decrease on to its whole subtree."""
    delta = cost[j] - new_cost
    parent[j] = new_parent
    frontier = np.array([j])
    cost[j] = new_cost
    while len(frontier):
        children = np.flatnonzero(np.isin(parent[:n], frontier))
        cost[children] -= delta
        frontier = children
