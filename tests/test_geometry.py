"""Obstacle distances and separation checks against brute-force dense sampling."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from gcs_planner.core.geo import Origin
from gcs_planner.geometry.dubins import shortest_path
from gcs_planner.geometry.obstacles import HARD_PENALTY, Obstacles, altitude_violation
from gcs_planner.model.plan import Plan, VehiclePlan
from gcs_planner.model.scenario import Cylinder, Hemisphere, Scenario, Vehicle
from gcs_planner.safety.separation import Trajectory, check_plan, find_conflicts, turn_radii


def _random_obstacles(rng, q=6):
    cyl = [
        Cylinder(
            x=float(rng.uniform(-50, 50)),
            y=float(rng.uniform(-50, 50)),
            radius_m=float(rng.uniform(2, 15)),
            z_min_m=float(z0),
            z_max_m=float(z0 + rng.uniform(5, 60)),
            buffer_m=3.0,
        )
        for z0 in rng.uniform(0, 40, q)
    ]
    domes = [Hemisphere(x=float(rng.uniform(-50, 50)), y=float(rng.uniform(-50, 50)), radius_m=20.0)]
    return Obstacles.from_scenario(cyl, domes)


def test_segment_distances_match_dense_sampling():
    rng = np.random.default_rng(0)
    obs = _random_obstacles(rng)
    a = rng.uniform([-80, -80, 0], [80, 80, 80], (40, 3))
    b = rng.uniform([-80, -80, 0], [80, 80, 80], (40, 3))
    b[:5, 2] = a[:5, 2]  # level segments
    got = obs.cylinder_distances(a, b)  # (40, Q)
    t = np.linspace(0, 1, 5001)[:, None, None]
    pts = a + t * (b - a)  # (T, 40, 3)
    dxy = np.hypot(pts[..., 0, None] - obs.cx, pts[..., 1, None] - obs.cy)
    in_band = (pts[..., 2, None] >= obs.z_min_m) & (pts[..., 2, None] <= obs.z_max_m)
    brute = np.where(in_band, dxy, np.inf).min(axis=0)
    finite = np.isfinite(brute)
    assert np.array_equal(np.isfinite(got), finite) or np.all(np.abs(got[finite] - brute[finite]) < 0.05)
    assert np.allclose(got[finite], brute[finite], atol=0.05)
    assert np.all(got[finite] <= brute[finite] + 1e-9)  # exact minimum is never above a sampled one
    dome = np.linalg.norm(pts[..., None, :] - obs.dome_centre, axis=-1).min(axis=0)
    assert np.allclose(obs.dome_distances(a, b), dome, atol=0.05)
    # batch shape (P, W, 3) works the same as flat
    assert np.allclose(obs.clearance(a.reshape(4, 10, 3), b.reshape(4, 10, 3)).ravel(), obs.clearance(a, b))


def test_threat_cost_pieces():
    obs = Obstacles.from_scenario([Cylinder(x=0, y=0, radius_m=10, z_max_m=50, buffer_m=5)])
    a = np.array([[-30, 12, 20], [-30, 20, 20], [-30, 8, 20], [-30, 0, 60]], dtype=float)
    b = a + [60, 0, 0]
    cost = obs.threat(a, b)
    assert cost[0] == pytest.approx(3.0)  # inside the buffer: (R + S) - d
    assert cost[1] == 0.0  # clear
    assert cost[2] == pytest.approx(HARD_PENALTY + 2.0)  # inside the cylinder
    assert cost[3] == 0.0  # above the top
    assert np.array_equal(altitude_violation([5, 50, 130], 10, 120), [5, 0, 10])


def _line(vid, p0, p1, t0, t1, sep=5.0, n=11):
    t = np.linspace(t0, t1, n)
    p = np.asarray(p0) + np.linspace(0, 1, n)[:, None] * (np.asarray(p1) - np.asarray(p0))
    return Trajectory(vid, t, p, sep)


def test_head_on_conflict_found_between_slices():
    # two vehicles fly at each other, offset 3 m laterally; closest approach at t = 5.13 s (not on a slice)
    a = _line("a", [-51.3, 0, 30], [48.7, 0, 30], 0.0, 10.0)
    b = _line("b", [51.3, 3, 30], [-48.7, 3, 30], 0.0, 10.0)
    (c,) = find_conflicts([a, b], step_s=0.5)
    assert c.t_s == pytest.approx(5.13, abs=1e-6)
    assert c.distance_m == pytest.approx(3.0, abs=1e-6)
    far = _line("c", [-50, 20, 30], [50, 20, 30], 0.0, 10.0)
    assert find_conflicts([a, far]) == []
    later = _line("d", [51.3, 3, 30], [-48.7, 3, 30], 20.0, 30.0)  # same track, after a has landed
    assert find_conflicts([a, later]) == []
    with pytest.raises(ValueError, match="step_s"):
        find_conflicts([a, b], step_s=1.0)


def test_conflicts_match_brute_force_on_random_traffic():
    rng = np.random.default_rng(3)
    trajs = []
    for k in range(25):
        p0, p1 = rng.uniform(0, 200, (2, 3))
        t0 = rng.uniform(0, 10)
        trajs.append(_line(f"v{k}", p0, p1, t0, t0 + rng.uniform(10, 30), sep=rng.uniform(5, 15)))
    got = {(c.i, c.j): c.distance_m for c in find_conflicts(trajs, step_s=0.5)}
    t = np.linspace(0, 40, 16001)
    pos = np.stack([tr.position_at(t) for tr in trajs], axis=1)
    brute = {}
    for i in range(len(trajs)):
        for j in range(i + 1, len(trajs)):
            d = np.linalg.norm(pos[:, i] - pos[:, j], axis=1)
            need = max(trajs[i].separation_m, trajs[j].separation_m)
            if np.nanmin(d, initial=np.inf) < need - 0.01:
                brute[(i, j)] = np.nanmin(d)
    assert set(brute) <= set(got)
    for key, d in brute.items():
        assert got[key] == pytest.approx(d, abs=0.06)


def test_turn_radii_of_circle_samples():
    th = np.linspace(0, 1.5, 30)
    xy = 25.0 * np.column_stack([np.cos(th), np.sin(th)])
    assert np.allclose(turn_radii(xy), 25.0)
    assert np.all(np.isinf(turn_radii(np.column_stack([np.arange(5.0), np.zeros(5)]))))


def _scenario(cylinders=()):
    veh = [
        Vehicle(
            "a", 1, "multirotor", (0, 0, 0), (100, 0, 30), speed_mps=10, turn_radius_m=10, separation_m=5
        ),
        Vehicle(
            "b", 2, "multirotor", (0, 50, 0), (100, 50, 30), speed_mps=10, turn_radius_m=10, separation_m=5
        ),
    ]
    return Scenario("t", Origin(47, 8, 0), {"name": "x"}, veh, cylinders=list(cylinders))


def _vp(vid, sysid, path, speed=10.0):
    path = np.asarray(path, dtype=float)
    t = np.concatenate([[0], np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1)) / speed])
    return VehiclePlan(vid, sysid, path, t, np.full(len(t), speed), path, t)


def test_check_plan_finds_each_kind_of_violation():
    sc = _scenario([Cylinder(x=50, y=0, radius_m=5, z_max_m=100, buffer_m=2)])
    _, poses = shortest_path((0.0, 0.0, -1.5), (100.0, 0.0, 1.5), 10.0).sample_step(2.0)  # dips to y=-20
    good_a = _vp("a", 1, np.vstack([[0, 0, 0], np.column_stack([poses[:, :2], np.full(len(poses), 30.0)])]))
    good_b = _vp("b", 2, [[0, 50, 0], [0, 50, 30], [100, 50, 30]])
    report = check_plan(Plan(Origin(47, 8, 0), "t", [good_a, good_b]), sc)
    assert report.ok, report.summary()
    # a near-duplicate sample on an arc (numerical noise) is not a tight turn
    jitter = good_a.path.copy()
    k = len(jitter) // 3
    jitter = np.insert(jitter, k + 1, jitter[k] + [1e-9, -2e-9, 0.0], axis=0)
    noisy = _vp("a", 1, jitter)
    assert check_plan(Plan(Origin(47, 8, 0), "t", [noisy, good_b]), sc).ok
    through = _vp("a", 1, [[0, 0, 0], [0, 0, 30], [100, 0, 30]])
    low = _vp("b", 2, [[0, 50, 0], [0, 50, 5], [100, 50, 5], [100, 50, 30]])
    report = check_plan(Plan(Origin(47, 8, 0), "t", [through, low]), sc)
    assert "a" in report.collisions and "b" in report.altitude
    sharp = _vp("a", 1, [[0, 0, 0], [0, 0, 30], [30, -20, 30], [70, -20, 30], [100, 0, 30]])  # corners
    crossing = _vp("b", 2, [[0, 50, 0], [0, 50, 30], [50, -20, 30], [100, 50, 30]])
    report = check_plan(Plan(Origin(47, 8, 0), "t", [sharp, crossing]), sc)
    assert "a" in report.turn_radius
    fast = _vp("b", 2, [[0, 50, 0], [0, 50, 30], [100, 50, 30]], speed=20.0)
    report = check_plan(Plan(Origin(47, 8, 0), "t", [good_a, fast]), sc)
    assert "b" in report.timing and not report.ok
    climb = _vp("b", 2, [[0, 50, 0], [0, 50, 30], [20, 50, 60], [100, 50, 30]])
    assert (
        "b"
        in check_plan(Plan(Origin(47, 8, 0), "t", [good_a, climb]), sc, max_climb_rad=math.radians(30)).climb
    )


def test_a_vehicle_waiting_airborne_for_its_departure_is_traffic_at_its_start():
    """fly takes every multirotor up, then starts each route at its time: a vehicle delayed 10 s
    hovers at its start meanwhile. The checker sees B pass over A's start then only with
    waits_airborne (on the ground otherwise, the paper's model)."""
    sc = _scenario()
    a_start = np.array([50.0, -40.0, 30.0])
    a = _vp("a", 1, [a_start, [50.0, -140.0, 30.0]])
    a = dataclasses.replace(a, path_times_s=a.path_times_s + 10.0, times_s=a.times_s + 10.0)
    b = _vp("b", 2, [[0.0, -40.0, 30.0], [100.0, -40.0, 30.0]])  # over A's start at t = 5 s
    plan = Plan(Origin(47, 8, 0), "t", [a, b])
    assert check_plan(plan, sc).ok
    waiting = [dataclasses.replace(v, waits_airborne=True) for v in sc.vehicles]
    hovering = dataclasses.replace(sc, vehicles=waiting)
    conflicts = check_plan(plan, hovering).conflicts
    assert [(c[0], c[1]) for c in conflicts] == [("a", "b")] and abs(conflicts[0][2] - 5.0) < 0.5, conflicts
