"""Coalition paths (timed Dubins, threat avoidance) and the division-of-labour ACO / baselines."""

from __future__ import annotations

import itertools
import math

import msgspec
import numpy as np
import pytest

from gcs_planner.geometry.dubins import (
    WORDS,
    DubinsPath,
    shortest_path_free_heading,
    stretch_to_length,
    word_lengths,
)
from gcs_planner.planning.coalition import paths
from gcs_planner.planning.coalition.aco import CoalitionProblem, evaluate, make_solution, repair, solve_aco
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


def test_the_batched_stretch_is_the_reference_stretch_to_length():
    """paths.stretch_batch is the planner's fast path; geometry/dubins.py's stretch_to_length is
    the readable reference: with the same k_max, the same word, radii and length (or none)."""
    rng = np.random.default_rng(5)
    n = 30
    q0 = np.column_stack([rng.uniform(0, 4000, (n, 2)), rng.uniform(-3, 3, n)])
    q1 = paths.entry_poses((2500.0, 2500.0), np.radians(rng.uniform(0, 360, n)), 200.0)
    extra = np.concatenate([rng.uniform(0.0, 2500.0, n - 5), rng.uniform(20_000.0, 60_000.0, 5)])  # loops
    want = paths.shortest_lengths(q0, q1, 150.0) + extra
    found = 0
    for a, b, target, fast in zip(q0, q1, want, paths.stretch_batch(q0, q1, want, np.full(n, 150.0))):
        reference = stretch_to_length(tuple(a), tuple(b), float(target), 150.0, k_max=paths.K_MAX)
        assert (fast is None) == (reference is None)
        if fast is not None:
            found += 1
            assert fast.word == reference.word and np.allclose(fast.radii, reference.radii, rtol=1e-6)
            assert fast.length == pytest.approx(reference.length, abs=1e-3)
    assert found >= n - 5


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


# ---- fast paths of the formation compute: they must give exactly what the plain computations give


def _random_chains(rng, n_chains=12):
    """Chains of 1-3 consecutive Dubins paths (random words, radii, loops) from random poses."""
    chains = []
    for _ in range(n_chains):
        q = np.r_[rng.uniform(0, 3000, 2), rng.uniform(-7, 7)]
        chain = []
        for _ in range(rng.integers(1, 4)):
            goal = np.r_[q[:2] + rng.uniform(-1500, 1500, 2), rng.uniform(-3, 3)]
            r = rng.uniform(60, 250)
            lens = word_lengths(q, goal, r)[0]
            w = int(rng.choice(np.flatnonzero(np.isfinite(lens.sum(1)))))
            seg = lens[w].copy()
            seg[0] += rng.integers(0, 2) * 2 * math.pi * r  # sometimes a loiter loop
            word = WORDS[w]
            chain.append(DubinsPath(tuple(q), word, tuple(seg), (r, math.inf if word[1] == "S" else r, r)))
            q = np.array(chain[-1].end)
        chains.append(chain)
    return chains


def test_batched_clearance_and_leg_sampling_equal_per_path_sampling():
    rng = np.random.default_rng(11)
    chains = _random_chains(rng)
    per_path = [np.concatenate([p.sample_step(10.0)[1] for p in ch]) for ch in chains]
    threats = [Threat(x, y, r) for x, y, r in zip(*rng.uniform(0, 3000, (2, 6)), rng.uniform(100, 400, 6))]
    # a threat whose boundary passes exactly through a sample: touching is clear in both
    touch = per_path[0][7, :2]
    threats.append(
        Threat(
            touch[0] + 300.0, touch[1], float(np.hypot(*(per_path[0][:, :2] - touch - [300.0, 0.0]).T).min())
        )
    )
    slow = np.array([paths.clearance_m(xy[:, :2], threats) >= 0.0 for xy in per_path])
    fast = paths.chains_clear(chains, threats, 10.0)
    assert slow.any() and not slow.all()  # both outcomes are exercised
    np.testing.assert_array_equal(fast, slow)
    speeds = rng.uniform(40, 60, len(chains))
    legs = paths.sample_legs(
        chains, 12.5, speeds, 10.0, ["strike"] * len(chains), [{"k": i} for i in range(len(chains))]
    )
    for ch, speed, leg, i in zip(chains, speeds, legs, itertools.count()):
        s_ref, q_ref, off = [], [], 0.0
        for j, p in enumerate(ch):
            s, q = p.sample_step(10.0)
            s_ref.append((s if j == 0 else s[1:]) + off)
            q_ref.append(q if j == 0 else q[1:])
            off += p.length
        q_ref = np.concatenate(q_ref)
        np.testing.assert_array_equal(leg.t, 12.5 + np.concatenate(s_ref) / speed)
        np.testing.assert_array_equal(leg.xy, q_ref[:, :2])
        np.testing.assert_array_equal(leg.heading, q_ref[:, 2])
        assert leg.info == {"k": i}


def test_word_lengths_of_a_batch_equal_row_by_row_calls():
    rng = np.random.default_rng(12)
    q0 = np.column_stack([rng.uniform(-500, 500, (40, 2)), rng.uniform(-9, 9, 40)])
    q1 = np.column_stack([rng.uniform(-500, 500, (40, 2)), rng.uniform(-9, 9, 40)])
    q1[:5] = q0[:5]  # coincident poses
    q1[5:10, :2] = q0[5:10, :2] + 1e-3  # nearly coincident
    r0, r1 = rng.uniform(20, 200, 40), rng.uniform(20, 200, 40)
    batch = word_lengths(q0, q1, r0, r1)
    rows = np.array([word_lengths(a, b, x, y)[0] for a, b, x, y in zip(q0, q1, r0, r1)])
    np.testing.assert_array_equal(batch, rows)
    assert np.isinf(batch).any() and np.isfinite(batch).any()
    ccc = batch[:, 4:].sum(2)
    assert np.isfinite(ccc).any(1).any() and (~np.isfinite(ccc).any(1)).any()
    far = q1.copy()
    far[:, :2] += 3000.0  # no CCC word anywhere
    np.testing.assert_array_equal(
        word_lengths(q0, far, r0, r1), [word_lengths(a, b, x, y)[0] for a, b, x, y in zip(q0, far, r0, r1)]
    )


def test_pruned_root_scan_keeps_every_sign_change_of_the_full_grid():
    """_scan evaluates F only where its Euclidean lower bound may be <= 0 (the detour's scan)."""
    prev, goal, r = np.array([1198.4, 1341.9, 5.474]), np.array([1200.0, 500.0, math.pi]), 200.0
    need = 1772.8
    rho, theta = np.meshgrid(np.linspace(r, need, 60), np.linspace(0, 2 * math.pi, 48, endpoint=False))
    via = np.column_stack(
        [goal[0] + rho.ravel() * np.cos(theta.ravel()), goal[1] + rho.ravel() * np.sin(theta.ravel())]
    )
    via = np.column_stack([via, np.arctan2(goal[1] - via[:, 1], goal[0] - via[:, 0])])
    n = len(via)
    full = (
        paths.shortest_lengths(np.broadcast_to(prev, (n, 3)), via, r)
        + paths.shortest_lengths(via, np.broadcast_to(goal, (n, 3)), r)
        - need
    ).reshape(rho.shape)
    lower = (np.hypot(via[:, 0] - prev[0], via[:, 1] - prev[1]) + rho.ravel() - need).reshape(rho.shape)
    assert (lower <= full + 1e-9).all()  # the bound is a bound
    evaluated = []
    F = paths._scan(lower, lambda i: (evaluated.append(len(i)), full.ravel()[i])[1])
    assert 0 < evaluated[0] < n  # some points skipped, some evaluated

    def crossings(G):
        return (np.sign(G[:, :-1]) != np.sign(G[:, 1:])) & (np.abs(G[:, 1:] - G[:, :-1]) < math.pi * r)

    c_full, c_fast = crossings(full), crossings(F)
    assert c_full.any()
    np.testing.assert_array_equal(c_fast, c_full)
    ti, ri = np.nonzero(c_full)
    np.testing.assert_array_equal(F[ti, ri], full[ti, ri])
    np.testing.assert_array_equal(F[ti, ri + 1], full[ti, ri + 1])


@pytest.mark.parametrize("fallback", ["_detours", "_delays_on_start_circle"])
def test_batched_timing_fallbacks_give_exact_clear_paths_to_the_goal(fallback):
    """A T2 member of the paper run: radius stretching has no solution, so the fallbacks are needed."""
    threats = [Threat(2600.0, 3450.0, 200.0), Threat(1900.0, 950.0, 150.0), Threat(1500.0, 1000.0, 120.0)]
    q0, q1, r, want = (
        np.array([1198.4071, 1341.8888, 5.474]),
        np.array([1200.0, 500.0, math.pi]),
        200.0,
        1772.84,
    )
    route = paths.min_route(q0, q1, r, threats, kappa=1.3)
    assert route.clear and len(route.poses) == 2
    assert paths.stretch_batch(q0[None], q1[None], np.array([want]), np.array([r]))[0] is None
    segs = getattr(paths, fallback)([route], [want], threats, 10.0)[0]
    assert segs is not None
    assert sum(p.length for p in segs) == pytest.approx(want, abs=1e-2)
    assert paths.chains_clear([segs], threats, 10.0)[0]
    assert paths.clearance_m(np.concatenate([p.sample_step(2.0)[1][:, :2] for p in segs]), threats) >= -1.0
    assert np.allclose(segs[0].start, q0)
    end = np.array(segs[-1].end)
    assert np.hypot(*(end[:2] - q1[:2])) < 1e-3 and abs(_wrap(end[2] - q1[2])) < 1e-6


def test_timed_routes_of_a_formation_equal_route_by_route_results():
    """Members' fallbacks run as one batch: each member gets exactly what it gets alone."""
    threats = [Threat(2600.0, 3450.0, 200.0), Threat(1900.0, 950.0, 150.0), Threat(1500.0, 1000.0, 120.0)]
    starts = [(1198.4071, 1341.8888, 5.474), (1248.8447, 1335.594, 5.3916), (1352.5437, 1529.6002, 4.4161)]
    goals = paths.entry_poses((1000.0, 500.0), np.radians([90.0, 60.0, 120.0]), 200.0)
    radii, wants = [200.0, 150.0, 200.0], [1772.84, 1700.0, 1792.28]
    routes = [paths.min_route(np.array(a), b, r, threats, 1.3) for a, b, r in zip(starts, goals, radii)]
    batch = paths.timed_routes(routes, wants, threats)
    alone = [paths.timed_routes([rt], [w], threats)[0] for rt, w in zip(routes, wants)]
    assert batch == alone  # DubinsPath is a dataclass: equal segments, words, lengths and radii
    assert any(ok for _, ok in batch)
    for (segs, ok), want in zip(batch, wants):
        if ok:
            assert sum(p.length for p in segs) == pytest.approx(want, abs=1e-2)


def _t2_members():
    threats = [Threat(2600.0, 3450.0, 200.0), Threat(1900.0, 950.0, 150.0), Threat(1500.0, 1000.0, 120.0)]
    poses = np.array(
        [
            (1198.4071, 1341.8888, 5.474),
            (1248.8447, 1335.594, 5.3916),
            (1352.5437, 1529.6002, 4.4161),
            (1389.1, 1251.0, 5.5),
            (300.0, 2200.0, -0.4),
            (2400.0, 300.0, 2.2),
        ]
    )
    goals = paths.entry_poses((1000.0, 500.0), np.radians([90.0, 60.0, 120.0, 150.0, 30.0, 0.0]), 200.0)
    r = np.array([200.0, 150.0, 200.0, 200.0, 150.0, 200.0])
    return threats, poses, goals, r


def test_formation_paths_memo_equals_a_fresh_computation():
    """The leader's attempts share routes and timed paths by (candidate, task, length): whatever the
    memo returns must be what a fresh computation gives, and a new length must not hit the memo."""
    threats, poses, _, _ = _t2_members()
    poses = poses[:5]
    goals = paths.entry_poses((1000.0, 500.0), np.radians([90.0, 60.0, 120.0]), 200.0)
    r = np.array([200.0, 150.0, 200.0, 200.0, 150.0])

    def fresh_routes(assign):
        return paths.FormationPaths(poses, goals, r, threats, 1.3, 10.0).routes(assign)

    def fresh(assign, want):
        return paths.FormationPaths(poses, goals, r, threats, 1.3, 10.0).timed(assign, want)

    plans = paths.FormationPaths(poses, goals, r, threats, 1.3, 10.0)
    calls = [
        (np.array([0, 3, 2]), np.array([1772.84, 1778.0, 1792.28])),
        (np.array([0, 1, 4]), np.array([1772.84, 1700.0, 2300.0])),  # task 0: same pair and length
        (np.array([0, 3, 2]), np.array([1772.84, 1778.0, 1792.28])),  # all memoised
        (np.array([0, 3, 2]), np.array([1812.84, 1200.0, 1850.0])),  # new lengths: re-planned
        (np.array([3, 0, 1]), np.array([1500.0, 1600.0, 1700.0])),  # new pairs
    ]
    first = None
    for i, (assign, want) in enumerate(calls):
        # as the leader asks: never shorter than the route (max of the route and the timed length)
        want = np.maximum(want, [rt.length_m for rt in fresh_routes(assign)])
        calls[i] = (assign, want)
        got = plans.timed(assign, want)
        assert got == fresh(assign, want)
        memo_routes = plans.routes(assign)
        new_routes = fresh_routes(assign)
        for a, b in zip(memo_routes, new_routes):
            assert (a.r_m, a.length_m, a.clear) == (b.r_m, b.length_m, b.clear)
            assert np.array_equal(np.array(a.poses), np.array(b.poses))
        for segs, ok, w in zip(*got, want):
            if ok:
                assert sum(p.length for p in segs) == pytest.approx(w, abs=1e-2)
                assert paths.chains_clear([segs], threats, 10.0)[0]
        first = first or got
    again = plans.timed(*calls[0])
    assert all(a is b for a, b in zip(again[0], first[0]))  # served from the memo, not re-planned
    assert any(not ok for ok in first[1]) and any(ok for ok in first[1])


def test_repair_recovers_only_the_excluded_task_and_prefers_keeping_the_schedule():
    params = CoalitionParams()
    prob = _problem(np.random.default_rng(4))  # 7 candidates: 0-4 strike only, 5 and 6 assess
    sol = solve_aco(prob, params, np.random.default_rng(0))
    latest = int(np.argmax(prob.length_m[sol.assign[:3], [0, 1, 2]] / prob.speed_mps[sol.assign[:3]]))
    k = (latest + 1) % 3  # a striker that is not the reference: keeping the schedule is possible
    prob.length_m[sol.assign[k], k] = np.inf  # its timed path could not clear the threats
    fixed = repair(sol.assign, [k], sol.t_required_s, prob, params)
    assert fixed is not None and fixed[k] != sol.assign[k]
    assert prob.capable[fixed, np.arange(4)].all() and len(set(fixed)) == 4
    moved = np.flatnonzero(fixed != sol.assign)
    assert set(moved) <= {k, *range(4)} and len(moved) <= 2  # one move: a free candidate or a swap
    J, _, t_req = evaluate(np.array([fixed]), prob, params)
    # every single move that re-covers task k
    free = [c for c in range(7) if prob.capable[c, k] and c not in sol.assign]
    plans = [np.where(np.arange(4) == k, c, sol.assign) for c in free]
    for k2 in range(4):
        j, x = sol.assign[k2], sol.assign[k]
        if k2 != k and prob.capable[j, k] and prob.capable[x, k2]:
            plan = sol.assign.copy()
            plan[k], plan[k2] = j, x
            plans.append(plan)
    Js, _, reqs = evaluate(np.array(plans), prob, params)
    keep = (reqs == sol.t_required_s).all(1)
    assert keep.any() and (t_req[0] == sol.t_required_s).all()  # the schedule is kept ...
    assert J[0] == pytest.approx(Js[keep].max())  # ... by the best such move
    prob.can_strike[:] = False  # nothing can take the strike: no repair
    assert repair(sol.assign, [k], sol.t_required_s, prob, params) is None


def test_stretch_batch_of_a_batch_equals_problem_by_problem():
    """Row independence (FormationPaths memoises per member): a problem gets the same path in any
    batch, including problems that need the dense k grid."""
    rng = np.random.default_rng(11)
    q0 = np.column_stack([rng.uniform(0, 1500, (16, 2)), rng.uniform(-3, 3, 16)])
    q1 = paths.entry_poses((1000.0, 500.0), np.radians(np.arange(0, 360, 22.5)), 200.0)
    short = paths.shortest_lengths(q0, q1, 200.0)
    want = short + rng.uniform(50.0, 1200.0, 16)
    batch = paths.stretch_batch(q0, q1, want, np.full(16, 200.0))
    alone = [paths.stretch_batch(q0[i : i + 1], q1[i : i + 1], want[i : i + 1], 200.0)[0] for i in range(16)]
    assert batch == alone
    assert sum(p is not None for p in batch) >= 8


def test_dubins_lower_bound_never_exceeds_the_shortest_path():
    """The scans' pruning bound (free-heading reach, both directions) is a bound on random cases,
    including goals close to or inside the turning circles."""
    rng = np.random.default_rng(21)
    n = 20000
    r = rng.uniform(50.0, 300.0, n)
    q0 = np.column_stack([rng.uniform(-1500, 1500, (n, 2)), rng.uniform(-7, 7, n)])
    q1 = np.column_stack([rng.uniform(-1500, 1500, (n, 2)), rng.uniform(-7, 7, n)])
    q1[: n // 2, :2] = q0[: n // 2, :2] + rng.uniform(-3, 3, (n // 2, 2)) * r[: n // 2, None]
    exact = paths.shortest_lengths(q0, q1, r)
    bound = paths._dubins_lower_bound(q0, q1, r)
    assert (bound <= exact + 1e-9).all()
    euclid = np.hypot(*(q1[:, :2] - q0[:, :2]).T)
    assert (bound >= euclid).all() and (bound > euclid + 1.0).mean() > 0.5  # tighter than Euclid


@pytest.mark.parametrize("fallback", ["_detours", "_delays_on_start_circle"])
def test_pruned_fallback_scans_equal_the_full_scans(fallback, monkeypatch):
    """Pruning by the lower bound never drops a candidate: random routes get the same paths (or the
    same None) as with every grid point evaluated."""
    rng = np.random.default_rng(5 if fallback == "_detours" else 6)
    threats = [Threat(1900.0, 950.0, 150.0), Threat(1500.0, 1000.0, 120.0), Threat(900.0, 1300.0, 180.0)]
    goals = paths.entry_poses((1000.0, 500.0), rng.uniform(0, 2 * math.pi, 6), 200.0)
    starts = np.column_stack([rng.uniform(200, 2200, (6, 2)), rng.uniform(-3, 3, 6)])
    radii = rng.choice([150.0, 200.0], 6)
    routes = [paths.min_route(a, b, r, threats, 1.3) for a, b, r in zip(starts, goals, radii)]
    wants = [rt.length_m + x for rt, x in zip(routes, rng.uniform(150.0, 1300.0, 6))]
    pruned = getattr(paths, fallback)(routes, wants, threats, 10.0)
    monkeypatch.setattr(paths, "_dubins_lower_bound", lambda q0, q1, r: np.full(len(q0), -np.inf))
    full = getattr(paths, fallback)(routes, wants, threats, 10.0)
    assert pruned == full
    assert any(p is not None for p in full)


def test_stretch_scan_stops_at_the_last_loop_count_that_can_change_sign():
    """_stretch_scan scans loop counts only while some length may still be short: its candidates
    equal those of the scan over all 200 counts (including problems with no candidate at all)."""
    rng = np.random.default_rng(12)
    n = 24
    q0 = np.column_stack([rng.uniform(0, 1500, (n, 2)), rng.uniform(-3, 3, n)])
    q1 = paths.entry_poses((1000.0, 500.0), rng.uniform(0, 2 * math.pi, n), 200.0)
    r = rng.choice([150.0, 200.0], n)
    want = paths.shortest_lengths(q0, q1, r) + rng.uniform(20.0, 6000.0, n)
    # plus a T2 member of the paper run whose length has no sign change at any k and loop count
    q0 = np.r_[q0, [[1352.5437, 1529.6002, 4.4161]]]
    q1 = np.r_[q1, paths.entry_poses((1000.0, 500.0), np.radians([60.0]), 200.0)]
    r, want = np.r_[r, 200.0], np.r_[want, 1772.84]
    n += 1
    for ks in (paths._KS_COARSE, paths._KS_DENSE):
        cands, jumps, _ = paths._stretch_scan(q0, q1, want, r, ks, [None] * n)
        nk = len(ks)
        seg = word_lengths(np.repeat(q0, nk, 0), np.repeat(q1, nk, 0), np.tile(ks, n) * np.repeat(r, nk))
        table = seg.reshape(n, nk, 6, 3).sum(3)
        full = []
        for i in range(n):
            loop = 2 * math.pi * r[i] * ks
            n0 = max(0, int((want[i] - table[i].max(initial=0, where=np.isfinite(table[i]))) // loop[-1]))
            f = table[i] + np.arange(n0, n0 + 200)[:, None, None] * loop[:, None] - want[i]
            with np.errstate(invalid="ignore"):
                cross = (
                    np.isfinite(f[:, :-1]) & np.isfinite(f[:, 1:]) & (np.sign(f[:, :-1]) != np.sign(f[:, 1:]))
                )
            hit = np.flatnonzero(cross.any((1, 2)))
            if len(hit):
                full += [(i, w, ks[k], ks[k + 1], n0 + hit[0]) for k, w in np.argwhere(cross[hit[0]])]
        assert [(int(i), int(w), k0, k1, int(c)) for i, w, k0, k1, c in cands] == [
            (int(i), int(w), k0, k1, int(c)) for i, w, k0, k1, c in full
        ]
        assert len({c[4] for c in full}) >= 2  # several loop counts are exercised
    assert n - 1 not in {c[0] for c in full}  # and a problem without any sign change


def test_lockstep_illinois_of_several_jobs_equals_each_job_alone():
    """_solve runs the stretch and detour refinements in lockstep (one Dubins call per iteration,
    14 and 12 iterations): each job's roots and segment lengths equal those of its own run."""
    threats, poses, goals, r = _t2_members()
    want = paths.shortest_lengths(poses, goals, r) + np.array([574.0, 420.0, 440.0, 800.0, 300.0, 950.0])
    stretch = paths._StretchPlan(poses, goals, want, r)
    routes = [paths.min_route(a, b, x, threats, 1.3) for a, b, x in zip(poses, goals, r)]
    detour = paths._DetourPlan(routes, list(want))
    assert stretch.job is not None and detour.job is not None
    assert stretch.job.iters != detour.job.iters
    together = paths._solve([stretch.job, None, detour.job])
    assert together[1] is None
    for job, got in zip((stretch.job, detour.job), (together[0], together[2])):
        alone = paths._solve([job])[0]
        np.testing.assert_array_equal(got[0], alone[0])
        np.testing.assert_array_equal(got[1], alone[1])


def test_formation_timed_paths_equal_member_by_member_timed_routes():
    """FormationPaths.timed (stretches in one batch, detours of members whose stretch will fail
    started early and refined with the stretches) gives each member exactly timed_route's result."""
    threats, poses, goals, r = _t2_members()
    plans = paths.FormationPaths(poses, goals, r, threats, 1.3, 10.0)
    assign = np.arange(6)
    routes = plans.routes(assign)
    want = np.array([rt.length_m for rt in routes]) + np.array([574.0, 420.0, 440.0, 800.0, 300.0, 950.0])
    segs, clear = plans.timed(assign, want)
    alone = [paths.timed_route(rt, w, threats) for rt, w in zip(routes, want)]
    assert segs == [s for s, _ in alone] and clear == [c for _, c in alone]
    direct = [k for k, rt in enumerate(routes) if len(rt.poses) == 2 and rt.clear]
    plan = paths._StretchPlan(poses[direct], goals[direct], want[direct], r[direct])
    assert plan.likely_none  # some members' detours are started early
    assert any(len(s) > 1 for s in segs) and any(len(s) == 1 for s in segs)


def test_refinement_early_stop_keeps_every_accepted_root(monkeypatch):
    """_solve stops once every root has converged (|f| <= SETTLED_M) or is stuck at a jump: the same
    roots are accepted as with all iterations, at the same place to within micrometres."""
    threats, poses, goals, r = _t2_members()
    want = paths.shortest_lengths(poses, goals, r) + np.array([574.0, 420.0, 440.0, 800.0, 300.0, 950.0])
    routes = [paths.min_route(a, b, x, threats, 1.3) for a, b, x in zip(poses, goals, r)]
    jobs = [paths._StretchPlan(poses, goals, want, r).job, paths._DetourPlan(routes, list(want)).job]
    early = paths._solve(jobs)
    monkeypatch.setattr(paths, "SETTLED_M", -1.0)  # never settled: every job runs all its iterations
    full = paths._solve(jobs)
    for job, (x_e, seg_e), (x_f, seg_f) in zip(jobs, early, full):
        f_e, f_f = job.resid(x_e, seg_e), job.resid(x_f, seg_f)
        np.testing.assert_array_equal(np.abs(f_e) < 1e-3, np.abs(f_f) < 1e-3)
        ok = np.abs(f_f) < 1e-3
        assert ok.any() and (~ok).any()  # converged roots and rejected jumps
        assert (np.abs(f_e[ok]) <= 1e-6).all()
        np.testing.assert_allclose(x_e[ok], x_f[ok], rtol=0, atol=1e-6)


def test_route_links_of_many_routes_equal_one_shortest_call_per_link():
    """_route_links takes every link of every route from one Dubins call: each link must equal its
    own ``_shortest`` (same word, segment lengths and radii), for routes of 1 to 4 poses."""
    rng = np.random.default_rng(5)
    routes = []
    for n in (2, 3, 4, 2, 1, 3):
        poses = [np.array([*rng.uniform(0, 3000, 2), rng.uniform(-3, 3)]) for _ in range(n)]
        routes.append(paths.Route(poses, float(rng.choice([150.0, 200.0])), 0.0, True))
    links = paths._route_links(routes)
    for route, got in zip(routes, links):
        want = [paths._shortest(a, b, route.r_m) for a, b in zip(route.poses[:-1], route.poses[1:])]
        assert got == want
    assert paths._route_links([routes[4]]) == [[]]


def test_loiter_fallback_is_skipped_when_every_exact_detour_crosses_a_threat(monkeypatch):
    """Choice: a route whose exact detours all cross a threat (a T2 member of the paper run that
    cannot wait 1040 m clear of the threat at (1900, 950)) gets no loiter scan; without threats the
    same detour clears and nothing is blocked."""
    threats = [Threat(2600.0, 3450.0, 200.0), Threat(1900.0, 950.0, 150.0)]
    q0 = np.array([1248.8447478704177, 1335.5940170526558, 5.391630811132146])
    q1 = paths.entry_poses((1000.0, 500.0), np.radians([60.0]), 200.0)[0]
    route, want = paths.min_route(q0, q1, 200.0, threats, kappa=1.3), 1772.8361768577583
    assert (
        route.clear
        and paths.stretch_batch(q0[None], q1[None], np.array([want]), np.array([200.0]))[0] is None
    )
    calls = []
    monkeypatch.setattr(paths, "_delays_on_start_circle", lambda *a: calls.append(a) or [None])
    fb = paths._Fallbacks([route], [want])
    assert fb.finish(paths._solve(fb.jobs), threats, 10.0) == [None]
    assert fb.detour.blocked == {0} and not calls
    fb = paths._Fallbacks([route], [want])
    segs = fb.finish(paths._solve(fb.jobs), [], 10.0)[0]
    assert segs is not None and not fb.detour.blocked and not calls
    assert sum(p.length for p in segs) == pytest.approx(want, abs=1e-2)


def test_default_colony_shape_finds_as_good_plans_as_the_earlier_10x15_colony():
    """Choice: 30 clusters x 6 iterations (a step costs the same for 10 or 30 clusters, so it is
    ~40% of the time of 10 x 15). On larger problems it must find plans at least as good on average."""
    params = CoalitionParams()
    assert (params.ants, params.iterations) == (30, 6)
    old = msgspec.structs.replace(params, ants=10, iterations=15)
    kinds, offsets = (STRIKE,) * 7 + (ASSESS,) * 3, (0.0,) * 10
    new_J, old_J = [], []
    for seed in range(8):
        prob = _problem(np.random.default_rng(seed), n=12, kinds=kinds, offsets=offsets)
        new_J.append(solve_aco(prob, params, np.random.default_rng(100 + seed)).J)
        old_J.append(solve_aco(prob, old, np.random.default_rng(100 + seed)).J)
    assert np.mean(new_J) >= np.mean(old_J) - 1e-3
    assert min(np.subtract(new_J, old_J)) > -0.02
