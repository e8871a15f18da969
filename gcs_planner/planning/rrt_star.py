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
- The tree grows in one compiled (numba) loop, an edge and a node at a time, drawing from the
  caller's generator as ``rng.random()`` does; the goal connection and the shortcut stay in Python.
- The start->goal straight edge is tried first (open field: no tree needed). After the goal is
  first reached, ``extra_iterations`` more samples refine the path; the result is then shortcut
  greedily (drop a vertex when the edge that skips it is valid).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from gcs_planner.core.compiled import compiled
from gcs_planner.geometry.obstacles import Obstacles
from gcs_planner.geometry.vec3 import add, dot, row, scale, sub

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


class EdgeCheck(NamedTuple):
    """What an edge must clear, as arrays a compiled loop reads: the altitude band, every cylinder's
    radius + buffer + margin (``need``) and the box around its axis where a segment can come that
    close, every dome's radius + margin. Built by ``edge_check``."""

    z_lo: float
    z_hi: float
    cx: np.ndarray
    cy: np.ndarray
    z_min: np.ndarray
    z_max: np.ndarray
    need: np.ndarray
    x_above: np.ndarray
    x_below: np.ndarray
    y_above: np.ndarray
    y_below: np.ndarray
    dome_centre: np.ndarray
    dome_need: np.ndarray


def edge_check(obstacles: Obstacles, z_band: tuple[float, float], margin_m: float) -> EdgeCheck:
    """The edge check for one set of obstacles, band and margin (what every edge shares)."""
    need = obstacles.radius_m + obstacles.buffer_m + margin_m
    reach = need + 1e-6  # rounding of a point on the segment
    return EdgeCheck(
        z_band[0] - 1e-9,
        z_band[1] + 1e-9,
        obstacles.cx,
        obstacles.cy,
        obstacles.z_min_m,
        obstacles.z_max_m,
        need,
        obstacles.cx + reach,
        obstacles.cx - reach,
        obstacles.cy + reach,
        obstacles.cy - reach,
        obstacles.dome_centre,
        obstacles.dome_radius_m + margin_m,
    )


def edges_valid(check: EdgeCheck, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """True (n,) where segments a -> b (n, 3) clear every obstacle and keep both ends in the band."""
    a, b = np.broadcast_arrays(np.asarray(a, dtype=float), np.asarray(b, dtype=float))
    return _edges_clear(np.ascontiguousarray(a), np.ascontiguousarray(b), check)


@compiled
def _edges_clear(a, b, check) -> np.ndarray:
    ok = np.empty(len(a), dtype=np.bool_)
    for i in range(len(a)):
        ok[i] = _edge_clear(row(a, i), row(b, i), check)
    return ok


@compiled
def _edge_clear(a: tuple, b: tuple, check) -> bool:
    """Does the segment a -> b keep both ends in the band and clear every cylinder (only those whose
    box it meets are measured) and dome? ``Obstacles``' distances, one segment at a time."""
    if not (check.z_lo <= a[2] <= check.z_hi and check.z_lo <= b[2] <= check.z_hi):
        return False
    d = (b[0] - a[0], b[1] - a[1], b[2] - a[2])
    x_lo, x_hi, y_lo, y_hi = min(a[0], b[0]), max(a[0], b[0]), min(a[1], b[1]), max(a[1], b[1])
    for q in range(len(check.need)):
        near = check.x_above[q] > x_lo and check.x_below[q] < x_hi
        near = near and check.y_above[q] > y_lo and check.y_below[q] < y_hi
        if near and not _axis_distance(a, d, check, q) > check.need[q]:
            return False
    for h in range(len(check.dome_need)):
        if not _dome_distance(a, d, check.dome_centre[h]) > check.dome_need[h]:
            return False
    return True


@compiled
def _axis_distance(a: tuple, d: tuple, check, q: int) -> float:
    """``obstacles._axis_distance`` of one segment a -> a + d and cylinder q's axis."""
    cx, cy, z_min, z_max = check.cx[q], check.cy[q], check.z_min[q], check.z_max[q]
    if abs(d[2]) < 1e-12:
        lo, hi = 0.0, 1.0
        empty = not (z_min <= a[2] <= z_max)
    else:
        t1, t2 = (z_min - a[2]) / d[2], (z_max - a[2]) / d[2]
        lo, hi = max(0.0, min(t1, t2)), min(1.0, max(t1, t2))
        empty = lo > hi
    if empty:
        return np.inf
    dxy2 = d[0] * d[0] + d[1] * d[1]
    t = ((cx - a[0]) * d[0] + (cy - a[1]) * d[1]) / dxy2 if dxy2 > 1e-18 else 0.0
    t = min(max(t, lo), max(lo, hi))
    return np.hypot(a[0] + t * d[0] - cx, a[1] + t * d[1] - cy)


@compiled
def _dome_distance(a: tuple, d: tuple, centre) -> float:
    """``Obstacles.dome_distances`` of one segment a -> a + d and one dome centre."""
    rel = (centre[0] - a[0], centre[1] - a[1], centre[2] - a[2])
    dd = d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
    t = (rel[0] * d[0] + rel[1] * d[1] + rel[2] * d[2]) / (dd if dd > 1e-18 else 1.0)
    t = min(max(t, 0.0), 1.0)
    x, y, z = a[0] + t * d[0] - centre[0], a[1] + t * d[1] - centre[1], a[2] + t * d[2] - centre[2]
    return np.sqrt(x * x + y * y + z * z)


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
    check = edge_check(obstacles, (float(box_lo[2]), float(box_hi[2])), cfg.margin_m)
    if edges_valid(check, start[None], goal[None])[0]:
        return RRTResult(np.vstack([start, goal]), float(np.linalg.norm(goal - start)), 0, 2)
    box_lo = np.asarray(box_lo, float)
    span = np.asarray(box_hi, float) - box_lo
    volume = float(np.prod(np.maximum(span, 1.0)))
    gamma = 2.0 * (1.0 + 1.0 / 3.0) ** (1.0 / 3.0) * (volume / (4.0 / 3.0 * math.pi)) ** (1.0 / 3.0)
    nodes, parent, cost, n, it = _grow_tree(
        start,
        goal,
        box_lo,
        span,
        gamma,
        float(cfg.step_m),
        cfg.max_iterations,
        cfg.extra_iterations,
        cfg.goal_bias,
        check,
        rng,
    )
    # connect the goal to the cheapest valid node within one step
    d_goal = np.linalg.norm(nodes[:n] - goal, axis=1)
    cand = np.flatnonzero(d_goal <= cfg.step_m)
    if len(cand):
        cand = cand[edges_valid(check, nodes[cand], goal[None])]
    if not len(cand):
        return RRTResult(None, math.inf, it, n)
    total = cost[cand] + d_goal[cand]
    j = int(cand[np.argmin(total)])
    chain = [goal]
    while j >= 0:
        chain.append(nodes[j])
        j = int(parent[j])
    path = shortcut(np.array(chain[::-1]), lambda a, b: edges_valid(check, a, b))
    return RRTResult(path, float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum()), it, n)


@compiled
def _grow_tree(
    start, goal, box_lo, span, gamma, step, max_iterations, extra_iterations, goal_bias, check, rng
) -> tuple:
    """The tree (nodes, parents, costs, node count, iterations run): sample (goal-biased), steer
    from the nearest node, keep a clear edge, choose the cheapest clear parent in the near set,
    rewire the near set through the new node; in scalar loops (docs/planners.md, "Compiled
    kernels")."""
    n_max = max_iterations + 1
    nodes = np.empty((n_max, 3))
    parent = np.full(n_max, -1)
    cost = np.zeros(n_max)
    near = np.empty(n_max, dtype=np.int64)  # the near set of this iteration: node, edge length,
    seg = np.empty(n_max)  # clear or not, and the cost through the new node
    ok = np.empty(n_max, dtype=np.bool_)
    through = np.empty(n_max)
    nodes[0] = start
    g = (goal[0], goal[1], goal[2])
    n, first_hit, it = 1, -1, 0
    for it in range(1, max_iterations + 1):
        if first_hit >= 0 and it - first_hit >= extra_iterations:
            break
        if rng.random() < goal_bias:
            target = g
        else:  # rng.uniform(box_lo, box_hi)'s arithmetic on the same draws, x then y then z
            target = (
                box_lo[0] + span[0] * rng.random(),
                box_lo[1] + span[1] * rng.random(),
                box_lo[2] + span[2] * rng.random(),
            )
        near_i = _nearest(nodes, n, target)
        from_node = row(nodes, near_i)
        d = sub(target, from_node)
        dist = _length(d)
        new = target if dist <= step else add(from_node, scale(d, step / dist))
        if not _edge_clear(from_node, new, check):
            continue
        radius = max(min(gamma * (math.log(n + 1) / (n + 1)) ** (1.0 / 3.0), 3.0 * step), 1e-6)
        m = 0
        for j in range(n):
            length = _length(sub(row(nodes, j), new))
            if length <= radius or j == near_i:  # the nearest node is always a candidate parent
                near[m], seg[m] = j, length
                ok[m] = _edge_clear(row(nodes, j), new, check)
                through[m] = cost[j] + length if ok[m] else np.inf
                m += 1
        best = 0
        for q in range(1, m):
            if through[q] < through[best]:
                best = q
        k = n
        nodes[k, 0], nodes[k, 1], nodes[k, 2] = new
        parent[k], cost[k] = near[best], through[best]
        n += 1
        for q in range(m):  # which to rewire, on the costs before any is rewired
            ok[q] = ok[q] and cost[k] + seg[q] < cost[near[q]] - 1e-9
        for q in range(m):
            if ok[q]:
                _reparent(parent, cost, n, near[q], k, cost[k] + seg[q])
        if first_hit < 0 and _length(sub(g, new)) <= step and _edge_clear(new, g, check):
            first_hit = it
    return nodes, parent, cost, n, it


@compiled
def _nearest(nodes, n, x) -> int:
    """Index of the first of the n nodes closest to ``x``."""
    best, at = np.inf, 0
    for j in range(n):
        d = sub(row(nodes, j), x)
        d2 = dot(d, d)
        if d2 < best:
            best, at = d2, j
    return at


@compiled
def _length(v) -> float:
    """|v|, summed (x + y) + z as numpy's norm and dot do."""
    return math.sqrt(dot(v, v))


@compiled
def _reparent(parent, cost, n, j, new_parent, new_cost) -> None:
    """Give node j a cheaper parent and pass the cost decrease on to its whole subtree, level by
    level (a node's children are the nodes whose parent is on the level above)."""
    delta = cost[j] - new_cost
    parent[j] = new_parent
    cost[j] = new_cost
    level = np.zeros(n, dtype=np.bool_)
    level[j] = True
    more = True
    while more:
        below = np.zeros(n, dtype=np.bool_)
        more = False
        for c in range(n):
            if parent[c] >= 0 and level[parent[c]]:
                below[c] = True
                cost[c] -= delta
                more = True
        level = below


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
