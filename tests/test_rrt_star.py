"""RRT*: finds clear paths through a gap, stays in the band, is seeded, reports failure."""

from __future__ import annotations

import numpy as np

from gcs_planner.geometry.obstacles import Obstacles
from gcs_planner.model.scenario import Cylinder, Hemisphere
from gcs_planner.planning.rrt_star import RRTConfig, _grow_tree, edge_check, edges_valid, rrt_star

LO, HI = np.array([0.0, -150.0, 20.0]), np.array([400.0, 150.0, 80.0])


def _wall(gap_y=60.0, tall=200.0):
    """A row of towers across x = 200 with one gap centred at y = gap_y."""
    ys = [y for y in np.arange(-150, 151, 20.0) if abs(y - gap_y) > 25]
    return Obstacles.from_scenario(
        [Cylinder(x=200, y=float(y), radius_m=6, z_max_m=tall, buffer_m=3) for y in ys]
    )


def _independent_clear(obs, path, margin):
    """Dense point sampling of the path, checked with plain distance arithmetic (no shared code path)."""
    t = np.linspace(0, 1, 400)[:, None]
    for a, b in zip(path[:-1], path[1:]):
        pts = a + t * (b - a)
        for cx, cy, r, s, z0, z1 in zip(obs.cx, obs.cy, obs.radius_m, obs.buffer_m, obs.z_min_m, obs.z_max_m):
            inside = (pts[:, 2] >= z0) & (pts[:, 2] <= z1)
            d = np.hypot(pts[inside, 0] - cx, pts[inside, 1] - cy)
            if d.size and d.min() < r + s + margin - 0.05:
                return False
    return True


def test_finds_path_through_gap_and_is_deterministic():
    obs = _wall()
    start, goal = np.array([20.0, -100.0, 40.0]), np.array([380.0, -100.0, 50.0])
    res = rrt_star(
        start, goal, obs, LO, HI, np.random.default_rng(7), RRTConfig(step_m=30, max_iterations=1500)
    )
    assert res.path is not None
    assert np.allclose(res.path[0], start) and np.allclose(res.path[-1], goal)
    assert _independent_clear(obs, res.path, margin=2.0)
    assert np.all((res.path[:, 2] >= LO[2]) & (res.path[:, 2] <= HI[2]))
    # it must pass through the gap near y = 60
    cross = [
        a + (200 - a[0]) / (b[0] - a[0]) * (b - a)
        for a, b in zip(res.path[:-1], res.path[1:])
        if a[0] < 200 <= b[0]
    ]
    assert abs(cross[0][1] - 60) < 25
    assert res.cost_m == np.linalg.norm(np.diff(res.path, axis=0), axis=1).sum()
    again = rrt_star(
        start, goal, obs, LO, HI, np.random.default_rng(7), RRTConfig(step_m=30, max_iterations=1500)
    )
    assert np.array_equal(res.path, again.path)


def test_low_towers_are_overflown_when_band_allows():
    obs = _wall(tall=30.0)  # towers end at 30 m, band goes to 80 m
    res = rrt_star(
        np.array([20.0, -100.0, 60.0]), np.array([380.0, -100.0, 60.0]), obs, LO, HI, np.random.default_rng(1)
    )
    assert res.path is not None and len(res.path) == 2  # the straight edge is valid above the towers


def test_reports_no_path_when_goal_is_walled_in():
    ring = [
        Cylinder(x=300 + 30 * np.cos(a), y=30 * np.sin(a), radius_m=8, z_max_m=500)
        for a in np.linspace(0, 2 * np.pi, 16, endpoint=False)
    ]
    res = rrt_star(
        np.array([20.0, 0.0, 40.0]),
        np.array([300.0, 0.0, 40.0]),
        Obstacles.from_scenario(ring),
        LO,
        HI,
        np.random.default_rng(2),
        RRTConfig(step_m=30, max_iterations=400),
    )
    assert res.path is None and res.iterations == 400


def test_the_compiled_edge_check_answers_as_the_obstacle_distances():
    """Edge by edge, the tree's check (one segment at a time, only the cylinders whose box it meets)
    answers as ``Obstacles``' vectorised distances over every cylinder and dome, and the band:
    for segments that clear the towers, graze them, cross them, pass a gap, pass over a low tower,
    run level or vertical, or leave the band."""
    towers = _wall().cx.size
    low = [Cylinder(x=100, y=0, radius_m=10, z_min_m=30, z_max_m=50, buffer_m=2)]
    domes = [Hemisphere(x=300, y=80, z=0, radius_m=40)]
    obs = Obstacles.from_scenario(
        [Cylinder(x=200, y=float(y), radius_m=6, z_max_m=200, buffer_m=3) for y in _wall().cy] + low, domes
    )
    assert len(obs.cx) == towers + 1
    rng = np.random.default_rng(3)
    a = LO + (HI - LO) * rng.uniform(-0.1, 1.1, size=(4000, 3))
    b = LO + (HI - LO) * rng.uniform(-0.1, 1.1, size=(4000, 3))
    b[:400, 2] = a[:400, 2]  # level
    b[400:600, :2] = a[400:600, :2]  # vertical
    margin = 2.0
    want = (
        np.all(obs.cylinder_distances(a, b) > obs.radius_m + obs.buffer_m + margin, axis=-1)
        & np.all(obs.dome_distances(a, b) > obs.dome_radius_m + margin, axis=-1)
        & (a[:, 2] >= LO[2])
        & (a[:, 2] <= HI[2])
        & (b[:, 2] >= LO[2])
        & (b[:, 2] <= HI[2])
    )
    got = edges_valid(edge_check(obs, (LO[2], HI[2]), margin), a, b)
    assert np.array_equal(got, want)
    assert 0.05 < want.mean() < 0.95  # both answers are exercised


def test_the_tree_stays_a_tree_whose_costs_are_its_path_lengths_after_rewiring():
    """Every node's cost is its parent's plus the edge between them, and every node reaches the
    start through its parents, after thousands of rewirings (a cost not passed on to a subtree, or
    a parent set to a descendant, breaks one of them)."""
    obs = _wall()
    lo, hi = LO.astype(float), HI.astype(float)
    span = hi - lo
    check = edge_check(obs, (lo[2], hi[2]), 2.0)
    nodes, parent, cost, n, _ = _grow_tree(
        np.array([20.0, -100.0, 40.0]), np.array([380.0, -100.0, 50.0]), lo, span, 300.0, 30.0, 1500, 10**6,
        0.1, check, np.random.default_rng(7),
    )  # fmt: skip
    assert n > 1000
    k = np.arange(1, n)
    edge = np.linalg.norm(nodes[k] - nodes[parent[k]], axis=1)
    np.testing.assert_allclose(cost[k], cost[parent[k]] + edge, rtol=0, atol=1e-6)
    depth = np.zeros(n, dtype=int)
    at = np.arange(n)
    for _ in range(n):
        moving = at > 0
        if not moving.any():
            break
        at[moving] = parent[at[moving]]
        depth += moving
    assert not (at > 0).any() and (at >= 0).all()  # every chain ends at the start, none loops
    assert depth.max() > 5
