"""Coalition paths (timed Dubins, threat avoidance) and the division-of-labour ACO / baselines."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from gcs_planner.geometry.dubins import shortest_path_free_heading
from gcs_planner.planning.coalition import paths
from gcs_planner.planning.coalition.aco import CoalitionProblem, evaluate, make_solution, solve_aco
from gcs_planner.planning.coalition.baselines import solve_polynomial
from gcs_planner.planning.coalition.model import ASSESS, STRIKE, CoalitionParams, Threat


def _wrap(a):
    return (a + math.pi) % (2 * math.pi) - math.pi


def test_stretch_batch_hits_exact_length_and_entry_pose():
    rng = np.random.default_rng(1)
    q0 = np.column_stack([rng.uniform(0, 4000, (12, 2)), rng.uniform(-3, 3, 12)])
    q1 = paths.entry_poses((2500.0, 2500.0), np.radians(np.arange(0, 360, 30)), 200.0)
    short = paths.shortest_lengths(q0, q1, 150.0)
    want = short.max() + rng.uniform(0.0, 2500.0, 12)  # includes cases needing loiter loops
    out = paths.stretch_batch(q0, q1, want, np.full(12, 150.0))
    for p, target, goal in zip(out, want, q1):
        assert p is not None
        assert p.length == pytest.approx(target, abs=1e-3)
        end = np.array(p.end)
        assert np.hypot(*(end[:2] - goal[:2])) < 1e-3
        assert abs(_wrap(end[2] - goal[2])) < 1e-5
        assert min(p.radii) >= 150.0 - 1e-9  # curvature limit kept (k >= 1)
    assert paths.stretch_batch(q0[:1], q1[:1], short[:1] - 5.0, 150.0)[0] is None


def test_free_heading_lengths_match_library_search():
    rng = np.random.default_rng(2)
    q0 = np.column_stack([rng.uniform(-2000, 2000, (5, 2)), rng.uniform(-3, 3, 5)])
    goal = np.array([300.0, -200.0])
    fast = paths.free_heading_lengths(q0, goal, 150.0)
    for q, f in zip(q0, fast):
        assert f == pytest.approx(shortest_path_free_heading(tuple(q), tuple(goal), 150.0).length, abs=0.5)


def test_threat_avoiding_timed_route_clears_and_keeps_length():
    threats = [Threat(2000.0, 2000.0, 300.0)]
    route = paths.min_route((0.0, 0.0, 0.8), (4000.0, 4000.0, 0.8), 150.0, threats, kappa=1.3)
    assert route.clear and len(route.poses) == 3  # start -> safe point -> goal
    safe = route.poses[1][:2]
    assert np.hypot(*(safe - [2000.0, 2000.0])) == pytest.approx(1.3 * 300.0)
    for extra in (0.0, 300.0, 1500.0):
        segs, ok = paths.timed_route(route, route.length_m + extra, threats)
        assert ok
        assert sum(s.length for s in segs) == pytest.approx(route.length_m + extra, abs=1e-2)
        xy = np.concatenate([s.sample_step(5.0)[1][:, :2] for s in segs])
        assert paths.clearance_m(xy, threats) >= 0.0


def _problem(rng, n=7, kinds=(STRIKE, STRIKE, STRIKE, ASSESS), offsets=(0.0, 0.0, 0.0, 0.0)):
    K = len(kinds)
    return CoalitionProblem(
        length_m=rng.uniform(800, 4000, (n, K)),
        speed_mps=rng.choice([50.0, 60.0], n),
        range_left_m=np.full(n, 15000.0),
        range_max_m=np.full(n, 18000.0),
        can_strike=np.r_[np.ones(n - 2, bool), False, False],
        can_assess=np.r_[np.zeros(n - 3, bool), True, True, True],
        kind=np.array(kinds),
        offset_s=np.array(offsets),
        reward=np.full(K, 10.0),
        decay_per_s=0.002,
        assess_delay_s=10.0,
        assess_duration_s=20.0,
        t0_s=40.0,
        t_start_s=41.4,
    )


def _brute_force(prob, params):
    n, K = prob.length_m.shape
    cap = prob.capable
    best = -np.inf
    for perm in itertools.permutations(range(n), K):
        if all(cap[i, k] for k, i in enumerate(perm)):
            best = max(best, float(evaluate(np.array(perm)[None], prob, params)[0][0]))
    return best


def test_aco_respects_capabilities_and_nearly_reaches_the_optimum():
    params = CoalitionParams()
    for seed in range(3):
        rng = np.random.default_rng(seed)
        prob = _problem(rng)
        sol = solve_aco(prob, params, rng)
        assert sol.covered
        assert len(set(sol.assign)) == len(sol.assign)  # one task per UAV
        assert prob.capable[sol.assign, np.arange(len(sol.assign))].all()
        assert _brute_force(prob, params) - 0.02 <= sol.J


def test_aco_beats_or_matches_polynomial_baseline_on_J():
    params = CoalitionParams()
    rng = np.random.default_rng(5)
    wins = 0
    for _ in range(5):
        prob = _problem(rng)
        eta = prob.t_start_s + prob.length_m.min(1) / prob.speed_mps
        poly = solve_polynomial(prob, params, eta)
        aco = solve_aco(prob, params, rng)
        assert poly.covered
        assert aco.J >= poly.J - 1e-9
        wins += aco.J > poly.J + 1e-6
    assert wins >= 1


def test_staggered_slots_and_assessment_timing_follow_the_latest_member():
    params = CoalitionParams()
    prob = _problem(np.random.default_rng(3), kinds=(STRIKE, STRIKE, ASSESS), offsets=(0.0, 5.0, 0.0))
    assign = np.array([0, 1, 6])
    J, parts, t_req = evaluate(assign[None], prob, params)
    eta = prob.t_start_s + prob.length_m[assign, [0, 1, 2]] / prob.speed_mps[assign]
    lam0 = max(eta[0], eta[1] - 5.0)
    assert t_req[0, 0] == pytest.approx(lam0)
    assert t_req[0, 1] == pytest.approx(lam0 + 5.0)
    assert t_req[0, 2] == pytest.approx(lam0 + 5.0 + prob.assess_delay_s)
    assert make_solution(np.array([0, -1, 6]), prob, params).covered is False
