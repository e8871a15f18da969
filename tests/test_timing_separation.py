"""Timing-aware separation: planned crossings keep their separation when flown off schedule, and the
hashed traffic look-up returns what a brute-force search does."""

from __future__ import annotations

import numpy as np
import pytest

from gcs_planner.core.config import parse
from gcs_planner.core.errors import UserError
from gcs_planner.core.geo import Origin
from gcs_planner.geometry.timing import closest_under_timing_one
from gcs_planner.model.scenario import Scenario, Vehicle
from gcs_planner.planning import priority_swarm
from gcs_planner.planning.deconflict4d.conflicts import pair_closest_approach
from gcs_planner.planning.traffic import Traffic

DT = 0.5
SPEED = 12.0


def _line(t0: float, p0, velocity, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Grid slices and positions of a vehicle at p0 at time t0 [s] moving at constant velocity."""
    k = np.arange(int(round(t0 / DT)), int(round(t0 / DT)) + n)
    return k, np.asarray(p0, float) + (k * DT - t0)[:, None] * np.asarray(velocity, float)


def _crossing(miss_m: float) -> tuple[Traffic, np.ndarray, np.ndarray]:
    """Traffic flying east through the origin at t = 20 s; a particle flying north at x = 0,
    timed to pass ``miss_m`` behind it (closest approach of a 90-degree crossing)."""
    traffic = Traffic(DT)
    traffic.add(*_line(0.0, (-240.0, 0.0, 50.0), (SPEED, 0.0, 0.0), 81), 5.0, SPEED)
    lag_s = miss_m / SPEED * np.sqrt(2.0)  # a 90-degree crossing misses by v * lag / sqrt(2)
    slices, pos = _line(0.0, (0.0, -SPEED * (20.0 - lag_s), 50.0), (0.0, SPEED, 0.0), 81)
    return traffic, slices, pos[None]


def _true_miss(pos: np.ndarray, shift_s: float) -> float:
    """Closest approach [m] when the particle flies shift_s late (traffic on time), sampled finely."""
    t = np.arange(0.0, 40.0, 0.001)
    traffic = np.column_stack([-240.0 + SPEED * t, np.zeros_like(t)])
    particle = np.column_stack([np.zeros_like(t), pos[0, 0, 1] + SPEED * (t - shift_s)])
    return float(np.linalg.norm(traffic - particle, axis=1).min())


def test_a_crossing_clear_on_time_conflicts_off_schedule_and_the_timing_margin_sees_it():
    traffic, slices, pos = _crossing(miss_m=9.0)
    valid = np.ones(pos.shape[:2], dtype=bool)
    need = 5.0 + 2.0  # separation + base margin
    assert _true_miss(pos, 0.0) == pytest.approx(9.0, abs=0.05)
    late = min(_true_miss(pos, s) for s in (-0.5, 0.5))
    assert late < need  # half a second off schedule: the plain 2 m margin no longer holds
    depth, count = traffic.violations(slices, pos, valid, 5.0, 2.0, timing_s=0.0)
    assert count[0] == 0 and depth[0] == 0.0  # the old model sees nothing wrong
    depth, count = traffic.violations(slices, pos, valid, 5.0, 2.0, timing_s=0.5)
    assert count[0] > 0 and 0.0 < depth[0] <= count[0] * (need - late + 0.1)  # the new one flags it


def test_a_crossing_wide_enough_for_the_timing_error_passes():
    traffic, slices, pos = _crossing(miss_m=14.0)
    assert min(_true_miss(pos, s) for s in np.linspace(-0.5, 0.5, 11)) > 7.0
    _, count = traffic.violations(slices, pos, np.ones(pos.shape[:2], dtype=bool), 5.0, 2.0, timing_s=0.5)
    assert count[0] == 0


def test_timing_does_not_widen_side_by_side_or_hovering_traffic():
    """A time shift moves a vehicle along its own track: parallel neighbours stay as far apart,
    and a hovering vehicle is passed as closely whenever it is passed."""
    traffic = Traffic(DT)
    traffic.add(*_line(0.0, (0.0, 0.0, 50.0), (SPEED, 0.0, 0.0), 40), 5.0, SPEED)
    traffic.add(*_line(0.0, (100.0, 40.0, 50.0), (0.0, 0.0, 0.0), 40), 5.0, SPEED)
    slices, side = _line(0.0, (0.0, 8.0, 50.0), (SPEED, 0.0, 0.0), 40)  # 8 m abeam, same speed
    _, count = traffic.violations(slices, side[None], np.ones((1, 40), bool), 5.0, 2.0, timing_s=1.0)
    assert count[0] == 0
    slices, past = _line(0.0, (-20.0, 48.0, 50.0), (SPEED, 0.0, 0.0), 40)  # passes the hover 8 m off
    _, count = traffic.violations(slices, past[None], np.ones((1, 40), bool), 5.0, 2.0, timing_s=1.0)
    assert count[0] == 0


def test_closest_under_timing_matches_brute_force():
    rng = np.random.default_rng(0)
    d0, u, w = rng.normal(size=(200, 3)) * 5, rng.normal(size=(200, 3)) * 6, rng.normal(size=(200, 3)) * 3
    w[:20] = 0.0
    u[20:40] = 0.0
    w[40:60] = 0.7 * u[40:60]  # parallel: no interior stationary point
    s, e = np.meshgrid(np.linspace(0, 1, 201), np.linspace(-1, 1, 401), indexing="ij")
    brute = np.array(
        [np.linalg.norm(d0[i] + s[..., None] * u[i] + e[..., None] * w[i], axis=-1).min() for i in range(200)]
    )
    got = np.array([closest_under_timing_one(tuple(a), tuple(b), tuple(c)) for a, b, c in zip(d0, u, w)])
    assert np.all(got <= brute + 1e-9) and np.all(brute - got < 0.05)


def _random_traffic(rng, cell_m: float, n: int, first: int, length: tuple, box: tuple, step_m: float):
    """Traffic of n random walks (start slice below ``first``, ``length`` samples, starting in box)
    and the walks themselves: (slices, positions, separation) each."""
    traffic, uavs = Traffic(DT, cell_m=cell_m), []
    for _ in range(n):
        k0 = int(rng.integers(0, first))
        k = np.arange(k0, k0 + int(rng.integers(*length)))
        pos = rng.uniform(*box, 3) + np.cumsum(rng.normal(size=(len(k), 3)) * step_m, 0)
        sep = float(rng.uniform(3.0, 8.0))
        traffic.add(k, pos, sep, SPEED)
        uavs.append((k, pos, sep))
    return traffic, uavs


def test_hashed_traffic_finds_the_four_nearest_of_a_brute_force_search():
    rng = np.random.default_rng(1)
    traffic, uavs = _random_traffic(rng, 15.0, 60, 40, (5, 40), ([-60, -60, 20], [60, 60, 40]), 3.0)
    samples = [(kk, p) for k, pos, _ in uavs for kk, p in zip(k, pos)]
    sl = np.array([s[0] for s in samples])
    tp = np.array([s[1] for s in samples])
    q_slices = rng.integers(0, 80, 500)
    q_pos = rng.uniform([-70, -70, 15], [70, 70, 45], (500, 3))
    for radius in (6.0, 19.0, 40.0):  # within one cell, a few, many
        row, j = traffic.neighbours(q_slices, q_pos, radius)
        expect = []
        for q in range(500):
            d = np.where(sl == q_slices[q], np.linalg.norm(tp - q_pos[q], axis=1), np.inf)
            near = np.flatnonzero(d < radius)
            expect += [(q, int(i)) for i in near[np.argsort(d[near], kind="stable")][:4]]
        assert list(zip(row.tolist(), j.tolist())) == expect


@pytest.mark.parametrize("timing_s", [0.0, 0.75])
def test_compiled_violations_sum_what_a_pair_by_pair_computation_does(timing_s):
    """Traffic.violations (a compiled chain walk) against the model written out pair by pair: the
    four nearest same-slice traffic samples of each valid particle sample, their closest approach
    over the slice under the timing error (geometry/timing.py), the shortfall summed per particle."""
    rng = np.random.default_rng(2)
    traffic, uavs = _random_traffic(rng, 30.0, 40, 20, (10, 50), ([-25, -25, 28], [25, 25, 32]), 2.0)
    slices = np.arange(5, 45)
    pos = rng.uniform([-25, -25, 28], [25, 25, 32], (6, 1, 3)) + np.cumsum(rng.normal(size=(6, 40, 3)) * 2, 1)
    valid = rng.random((6, 40)) < 0.9
    radius = max(u[2] for u in uavs) + 2.0 + timing_s * SPEED + 2.0 * SPEED * DT
    depth, count = traffic.violations(slices, pos, valid, 5.0, 2.0, timing_s)
    want_depth, want_count, crowded = np.zeros(6), np.zeros(6), 0
    for p, i in zip(*np.nonzero(valid)):
        near = []  # (distance, uav, index in its samples)
        for u, (k, tp, _) in enumerate(uavs):
            at = np.flatnonzero(k == slices[i])
            if len(at) and np.linalg.norm(tp[at[0]] - pos[p, i]) < radius:
                near.append((np.linalg.norm(tp[at[0]] - pos[p, i]), u, at[0]))
        crowded += len(near) > 4
        for _, u, at in sorted(near)[:4]:
            k, tp, sep = uavs[u]
            both = i + 1 < 40 and valid[p, i + 1] and at + 1 < len(k)
            a0, b0 = pos[p, i], tp[at]
            a1, b1 = (pos[p, i + 1], tp[at + 1]) if both else (a0, b0)
            d0 = b0 - a0
            w = (b1 - b0) * timing_s / DT
            miss = closest_under_timing_one(tuple(d0), tuple((b1 - a1) - d0), tuple(w))
            short = max(sep, 5.0) + 2.0 - miss
            if short > 0:
                want_depth[p] += short
                want_count[p] += 1
    assert want_count.sum() > 10 and crowded > 10  # the draw has conflicts, and more than four near
    assert np.array_equal(count, want_count)
    np.testing.assert_allclose(depth, want_depth, rtol=1e-9, atol=1e-9)


def _crossing_scenario(timing_s: float) -> tuple[Scenario, priority_swarm.Config]:
    """Two UAVs whose straight routes cross at the same place and time."""
    base = dict(type="multirotor", speed_mps=SPEED, turn_radius_m=20.0, min_alt_m=40.0, max_alt_m=60.0,
                separation_m=5.0)  # fmt: skip
    vehicles = [
        Vehicle(id="east", sysid=1, start=(-300.0, 0.0, 50.0), goal=(300.0, 0.0, 50.0), priority=2.0, **base),
        Vehicle(id="north", sysid=2, start=(0.0, -300.0, 50.0), goal=(0.0, 300.0, 50.0), **base),
    ]
    scenario = Scenario(name="crossing", origin=Origin(47.4, 8.5, 488.0), planner={}, vehicles=vehicles)
    table = {"name": "priority_swarm", "waypoints": 3, "particles": 16, "iterations": 25, "rounds": 1,
             "rrt_iterations": 60, "timing_error_s": timing_s}  # fmt: skip
    return scenario, parse(priority_swarm.Config, table, "planner")


def _closest_off_schedule(plan, shift_s: float) -> float:
    """Closest approach [m] of the two planned paths when the second flies shift_s late."""
    a, b = plan.vehicles
    t = np.arange(0.0, max(a.path_times_s[-1], b.path_times_s[-1]) + abs(shift_s), 0.01)
    pa = np.column_stack([np.interp(t, a.path_times_s, a.path[:, k]) for k in range(3)])
    pb = np.column_stack([np.interp(t - shift_s, b.path_times_s, b.path[:, k]) for k in range(3)])
    return float(np.linalg.norm(pa - pb, axis=1).min())


def test_planned_with_the_timing_margin_the_crossing_survives_the_time_error():
    shifts = np.linspace(-1.0, 1.0, 21)
    scenario, cfg = _crossing_scenario(timing_s=1.0)
    plan = priority_swarm.plan(scenario, cfg, np.random.default_rng(0))
    assert plan.metrics["feasible_count"] == 2
    assert min(_closest_off_schedule(plan, s) for s in shifts) >= 5.0
    scenario, cfg = _crossing_scenario(timing_s=0.0)
    exact = priority_swarm.plan(scenario, cfg, np.random.default_rng(0))
    assert exact.metrics["feasible_count"] == 2
    assert min(_closest_off_schedule(exact, s) for s in shifts) < 5.0  # the old margin breaks


def test_the_4d_pair_check_sees_the_time_error():
    """The same 90-degree crossing, 9 m apart on time: the 4-D planner's pair check under 0.5 s."""
    lag = 9.0 / SPEED * np.sqrt(2.0)
    times = np.array([[[0.0, 40.0], [0.0, 40.0]]])
    points = np.array(
        [[[[-240.0, 0, 50], [240.0, 0, 50]], [[0, -SPEED * (20 - lag), 50], [0, SPEED * (20 + lag), 50]]]]
    )
    pairs = np.array([[0, 1]])
    exact, _ = pair_closest_approach(points, times, pairs)
    off, _ = pair_closest_approach(points, times, pairs, timing_s=0.5)
    assert exact[0, 0] == pytest.approx(9.0, abs=1e-6)
    assert off[0, 0] == pytest.approx(9.0 - 0.5 * SPEED / np.sqrt(2.0), abs=1e-6)


def test_timing_error_is_a_checked_planner_key():
    with pytest.raises(UserError, match=r"planner.timing_error_s must be a number >= 0.0, got -1.0"):
        parse(priority_swarm.Config, {"name": "priority_swarm", "timing_error_s": -1.0}, "planner")
