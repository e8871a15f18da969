"""Dubins module against brute-force numeric checks and the classic normalised formulas."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gcs_planner.geometry.dubins import (
    WORDS,
    lift,
    min_length_for_climb,
    sample_batch,
    shortest_batch,
    shortest_path,
    shortest_path_free_heading,
    stretch_to_length,
    word_lengths,
)


def _wrapdiff(a, b):
    return (np.asarray(a) - np.asarray(b) + math.pi) % (2 * math.pi) - math.pi


def _random_problems(n, seed, unequal):
    rng = np.random.default_rng(seed)
    q0 = np.column_stack([rng.uniform(-200, 200, (n, 2)), rng.uniform(-math.pi, math.pi, n)])
    q1 = np.column_stack([rng.uniform(-200, 200, (n, 2)), rng.uniform(-math.pi, math.pi, n)])
    r0 = rng.uniform(10, 60, n)
    r1 = rng.uniform(10, 60, n) if unequal else r0
    return q0, q1, r0, r1


def _check_path(path, q1, r_min, step=0.25):
    """End pose, continuity, curvature bound and length = sum of segments, numerically."""
    end = np.array(path.end)
    assert np.hypot(*(end[:2] - np.asarray(q1[:2]))) < 1e-6
    assert abs(_wrapdiff(end[2], q1[2])) < 1e-6
    s, poses = path.sample_step(step)
    ds = np.diff(s)
    chord = np.hypot(*np.diff(poses[:, :2], axis=0).T)
    assert np.all(chord <= ds + 1e-9)  # no jumps in position
    dh = np.abs(_wrapdiff(poses[1:, 2], poses[:-1, 2]))
    assert np.all(dh <= ds / r_min + 1e-9)  # curvature <= 1/R, no jumps in heading
    # polyline length converges to the path length from below (chord error ~ ds^2/(24 R^2))
    assert chord.sum() == pytest.approx(path.length, rel=1e-4)
    assert path.length == pytest.approx(sum(path.lengths))


@pytest.mark.parametrize("unequal", [False, True])
def test_every_word_reaches_goal_with_bounded_curvature(unequal):
    q0, q1, r0, r1 = _random_problems(30, seed=1 if unequal else 2, unequal=unequal)
    checked = dict.fromkeys(WORDS, 0)
    for i in range(len(q0)):
        lengths = word_lengths(q0[i], q1[i], r0[i], r1[i])[0].sum(axis=1)
        for w, word in enumerate(WORDS):
            if not np.isfinite(lengths[w]):
                continue
            path = shortest_path(tuple(q0[i]), tuple(q1[i]), r0[i], r1[i], words=(word,))
            _check_path(path, q1[i], min(r0[i], r1[i]))
            checked[word] += 1
    assert all(c > 0 for c in checked.values()), checked


def test_close_poses_exercise_ccc_words():
    path = shortest_path((0.0, 0.0, 0.0), (10.0, 0.0, math.pi), 20.0)
    assert path.word in ("LRL", "RLR")
    _check_path(path, (10.0, 0.0, math.pi), 20.0)
    unequal = shortest_path((0.0, 0.0, 0.0), (12.0, 3.0, math.pi), 20.0, 35.0, words=("LRL",))
    _check_path(unequal, (12.0, 3.0, math.pi), 20.0)


def _classic_shortest(q0, q1, r):
    """Textbook equal-radius Dubins (Shkel & Lumelsky normalised formulas), independent code."""
    mod = lambda a: a % (2 * math.pi)  # noqa: E731
    dx, dy = q1[0] - q0[0], q1[1] - q0[1]
    d = math.hypot(dx, dy) / r
    th = math.atan2(dy, dx) if d > 0 else 0.0
    a, b = mod(q0[2] - th), mod(q1[2] - th)
    sa, sb, ca, cb, cab = math.sin(a), math.sin(b), math.cos(a), math.cos(b), math.cos(a - b)
    best = math.inf
    p2 = 2 + d * d - 2 * cab + 2 * d * (sa - sb)
    if p2 >= 0:
        tmp = math.atan2(cb - ca, d + sa - sb)
        best = min(best, mod(-a + tmp) + math.sqrt(p2) + mod(b - tmp))
    p2 = 2 + d * d - 2 * cab + 2 * d * (sb - sa)
    if p2 >= 0:
        tmp = math.atan2(ca - cb, d - sa + sb)
        best = min(best, mod(a - tmp) + math.sqrt(p2) + mod(-b + tmp))
    p2 = -2 + d * d + 2 * cab + 2 * d * (sa + sb)
    if p2 >= 0:
        p = math.sqrt(p2)
        tmp = math.atan2(-ca - cb, d + sa + sb) - math.atan2(-2.0, p)
        best = min(best, mod(-a + tmp) + p + mod(-b + tmp))
    p2 = d * d - 2 + 2 * cab - 2 * d * (sa + sb)
    if p2 >= 0:
        p = math.sqrt(p2)
        tmp = math.atan2(ca + cb, d - sa - sb) - math.atan2(2.0, p)
        best = min(best, mod(a - tmp) + p + mod(b - tmp))
    tmp = (6 - d * d + 2 * cab + 2 * d * (sa - sb)) / 8
    if abs(tmp) <= 1:
        p = mod(2 * math.pi - math.acos(tmp))
        t = mod(a - math.atan2(ca - cb, d - sa + sb) + p / 2)
        best = min(best, t + p + mod(a - b - t + p))
    tmp = (6 - d * d + 2 * cab + 2 * d * (sb - sa)) / 8
    if abs(tmp) <= 1:
        p = mod(2 * math.pi - math.acos(tmp))
        t = mod(-a - math.atan2(ca - cb, d + sa - sb) + p / 2)
        best = min(best, t + p + mod(b - a - t + p))
    return best * r


def test_shortest_matches_classic_formulas_and_word_sweep():
    q0, q1, r0, _ = _random_problems(300, seed=3, unequal=False)
    q1[:40, :2] = q0[:40, :2] + np.random.default_rng(4).uniform(-30, 30, (40, 2))  # close poses: CCC
    all_words = word_lengths(q0, q1, r0).sum(axis=2)
    for i in range(len(q0)):
        path = shortest_path(tuple(q0[i]), tuple(q1[i]), r0[i])
        assert path.length == pytest.approx(all_words[i].min(), abs=1e-9)
        assert path.length == pytest.approx(_classic_shortest(q0[i], q1[i], r0[i]), abs=1e-6)


def test_free_heading_no_longer_than_any_swept_heading():
    rng = np.random.default_rng(5)
    for _ in range(20):
        q0 = (0.0, 0.0, float(rng.uniform(-math.pi, math.pi)))
        goal = tuple(rng.uniform(-120, 120, 2))
        r0 = float(rng.uniform(10, 40))
        r1 = r0 if _ % 2 else float(rng.uniform(10, 40))
        path = shortest_path_free_heading(q0, goal, r0, r1)
        sweep = np.linspace(-math.pi, math.pi, 5000, endpoint=False) + 1e-4  # grid unlike the module's
        q1 = np.column_stack([np.full(5000, goal[0]), np.full(5000, goal[1]), sweep])
        brute = word_lengths(np.array(q0), q1, r0, r1).sum(axis=2).min()
        assert path.length <= brute + 1e-6
        assert np.hypot(path.end[0] - goal[0], path.end[1] - goal[1]) < 1e-6


def test_stretch_hits_required_length_with_radius_at_least_minimum():
    rng = np.random.default_rng(6)
    for _ in range(10):
        q0 = (0.0, 0.0, float(rng.uniform(-math.pi, math.pi)))
        q1 = (*rng.uniform(-300, 300, 2), float(rng.uniform(-math.pi, math.pi)))
        base = shortest_path(q0, q1, 20.0, 30.0)
        target = base.length * float(rng.uniform(1.05, 3.0))
        path = stretch_to_length(q0, q1, target, 20.0, 30.0)
        assert path is not None
        assert path.length == pytest.approx(target, abs=1e-5)
        assert path.radii[0] >= 20.0 - 1e-9 and path.radii[2] >= 30.0 - 1e-9
        _check_path(path, q1, 20.0)
    assert stretch_to_length((0, 0, 0), (100, 0, 0), 50.0, 20.0) is None  # shorter than the straight line


def test_stretch_adds_loiter_loops_when_radius_is_not_enough():
    path = stretch_to_length((0.0, 0.0, 0.0), (100.0, 0.0, 0.0), 3000.0, 20.0, k_max=2.0)
    assert path is not None and path.length == pytest.approx(3000.0, abs=1e-5)
    assert path.lengths[0] > 2 * math.pi * path.radii[0]
    _check_path(path, (100.0, 0.0, 0.0), 20.0, step=1.0)


def test_lift_reports_climb_violation():
    path = shortest_path((0.0, 0.0, 0.0), (100.0, 0.0, 0.0), 20.0)
    ok = lift(path, 10.0, 20.0, math.radians(10))
    assert ok.climb_violation_rad == 0.0 and ok.climb_rad == pytest.approx(math.atan(0.1))
    bad = lift(path, 10.0, 60.0, math.radians(10))
    assert bad.climb_violation_rad == pytest.approx(math.atan(0.5) - math.radians(10))
    pts = bad.sample(np.linspace(0, path.length, 11))
    assert np.allclose(pts[:, 2], np.linspace(10, 60, 11))
    assert bad.length_3d == pytest.approx(math.hypot(100, 50))
    assert min_length_for_climb(50.0, math.radians(10)) == pytest.approx(50 / math.tan(math.radians(10)))


def test_invalid_radius_raises():
    with pytest.raises(ValueError, match="radii"):
        word_lengths(np.zeros(3), np.ones(3), 0.0)


def test_batch_shortest_and_sampling_match_single_paths():
    q0, q1, r0, r1 = _random_problems(50, seed=8, unequal=True)
    word, lengths, radii = shortest_batch(q0, q1, r0, r1)
    s = np.linspace(0, 1, 7)[None, :] * lengths.sum(axis=1)[:, None]
    poses = sample_batch(q0, word, lengths, radii, s)
    for i in range(len(q0)):
        single = shortest_path(tuple(q0[i]), tuple(q1[i]), r0[i], r1[i])
        assert WORDS[word[i]] == single.word
        assert np.allclose(lengths[i], single.lengths)
        ref = single.sample(s[i])
        assert np.allclose(poses[i, :, :2], ref[:, :2], atol=1e-7)
        assert np.allclose(_wrapdiff(poses[i, :, 2], ref[:, 2]), 0, atol=1e-9)
