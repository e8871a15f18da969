"""Closest approach between timed polylines: analytic CPA against brute-force dense sampling."""

from __future__ import annotations

import numpy as np
import pytest

from gcs_planner.planning.deconflict4d.conflicts import (
    candidate_pairs,
    closest_approach,
    conflict_counts,
    pair_closest_approach,
)
from gcs_planner.planning.deconflict4d.trajectory import position_at


def _random_polyline(rng: np.random.Generator, n: int, t0: float) -> tuple[np.ndarray, np.ndarray]:
    pts = rng.uniform(-10, 10, size=(n, 3))
    times = t0 + np.concatenate([[0.0], np.cumsum(rng.uniform(0.3, 3.0, size=n - 1))])
    return pts, times


def _interp(pts: np.ndarray, times: np.ndarray, t: np.ndarray) -> np.ndarray:
    return np.stack([np.interp(t, times, pts[:, k]) for k in range(3)], axis=1)


def _brute(pa, ta, pb, tb, scale=None, samples=200_001):
    lo, hi = max(ta[0], tb[0]), min(ta[-1], tb[-1])
    t = np.linspace(lo, hi, samples)
    d = _interp(pa, ta, t) - _interp(pb, tb, t)
    if scale is not None:
        d = d / scale
    dist = np.linalg.norm(d, axis=1)
    return dist.min(), t[np.argmin(dist)], (hi - lo) / (samples - 1)


@pytest.mark.parametrize("seed", range(12))
def test_cpa_matches_dense_sampling(seed):
    rng = np.random.default_rng(seed)
    pa, ta = _random_polyline(rng, int(rng.integers(2, 7)), rng.uniform(0, 2))
    pb, tb = _random_polyline(rng, int(rng.integers(2, 7)), rng.uniform(0, 2))
    d, t = closest_approach(pa, ta, pb, tb)
    if min(ta[-1], tb[-1]) <= max(ta[0], tb[0]):  # never airborne together
        assert np.isinf(d)
        return
    brute, _, step = _brute(pa, ta, pb, tb)
    v_rel = 2 * 20 / 0.3 * np.sqrt(3)  # bound on relative speed of the random legs
    assert d <= brute + 1e-9  # exact minimum can only be lower than any sample
    assert brute - d <= v_rel * step / 2 + 1e-9
    # the reported time really achieves the distance
    got = np.linalg.norm(_interp(pa, ta, np.array([t])) - _interp(pb, tb, np.array([t])))
    assert got == pytest.approx(d, abs=1e-9)


def test_cpa_catches_fast_head_on_pass_between_samples():
    # 1 m separation, 10 m/s closing: a 0.3 s sampling step would miss the 0.0 m pass
    pa, ta = np.array([[0.0, 0, 10], [50.0, 0, 10]]), np.array([0.0, 10.0])
    pb, tb = np.array([[50.0, 0.0, 10], [0.0, 0.0, 10]]), np.array([0.05, 10.05])
    d, t = closest_approach(pa, ta, pb, tb)
    assert d == pytest.approx(0.0, abs=1e-9)
    assert t == pytest.approx(5.025)
    coarse = np.arange(0.05, 10.0, 0.3)
    sampled = np.linalg.norm(_interp(pa, ta, coarse) - _interp(pb, tb, coarse), axis=1).min()
    assert sampled > 1.0  # what a too-coarse time step would conclude


def test_cpa_no_common_time_is_infinite():
    pa, ta = np.array([[0.0, 0, 0], [1.0, 0, 0]]), np.array([0.0, 1.0])
    pb, tb = np.array([[0.0, 0, 0], [1.0, 0, 0]]), np.array([2.0, 3.0])
    d, _ = closest_approach(pa, ta, pb, tb)
    assert np.isinf(d)


@pytest.mark.parametrize("seed", range(6))
def test_whitened_cpa_matches_sampling(seed):
    rng = np.random.default_rng(100 + seed)
    pa, ta = _random_polyline(rng, 5, 0.0)
    pb, tb = _random_polyline(rng, 4, 0.5)
    scale = rng.uniform(0.5, 4.0, size=3)
    d, _ = closest_approach(pa, ta, pb, tb, np.broadcast_to(scale, (len(pb) - 1, 3)))
    brute, _, step = _brute(pa, ta, pb, tb, scale)
    assert d <= brute + 1e-9
    assert brute - d <= 2 * 20 / 0.3 * np.sqrt(3) / scale.min() * step / 2 + 1e-9


def test_pairs_batch_and_counts_agree_with_single_calls():
    rng = np.random.default_rng(7)
    n_b, n_u, n_w = 3, 6, 4
    pts = rng.uniform(-5, 5, size=(n_b, n_u, n_w, 3))
    times = np.cumsum(rng.uniform(0.5, 2.0, size=(n_b, n_u, n_w)), axis=-1)
    pairs = candidate_pairs(pts, times, np.full((n_b, n_u), 0.5))
    all_pairs = np.array([(i, j) for i in range(n_u) for j in range(i + 1, n_u)])
    d, _ = pair_closest_approach(pts, times, all_pairs)
    for b in range(n_b):
        for k, (i, j) in enumerate(all_pairs):
            single, _ = closest_approach(pts[b, i], times[b, i], pts[b, j], times[b, j])
            assert d[b, k] == pytest.approx(single)
            if single < 1.0:  # anything within reach must survive the box pre-filter
                assert any((pairs == [i, j]).all(axis=1))
    # the leg-box pruning is exact for every distance below the reach sum
    reach = np.full(n_u, 1.5)
    d_pruned, _ = pair_closest_approach(pts, times, all_pairs, reach)
    close = d < 3.0
    np.testing.assert_allclose(d_pruned[close], d[close])
    assert np.all(d_pruned[~close] >= 3.0)
    flags = d < 3.0
    counts = conflict_counts(n_u, all_pairs, flags, np.zeros((n_b, n_u, 0), bool), np.zeros(0, int))
    for b in range(n_b):
        for u in range(n_u):
            assert counts[b, u] == sum(flags[b, k] for k, p in enumerate(all_pairs) if u in p)


def test_blended_position_is_continuous_and_hits_straight_legs():
    pts = np.array([[0.0, 0, 0], [0, 0, 10], [20, 0, 10], [20, 20, 10]])
    times = np.array([0.0, 4.0, 10.0, 16.0])
    tau = np.array([1.25, 1.7, 1.7, 1.7])
    t = np.linspace(-1, 17, 4001)
    p = position_at(pts, times, tau, t)
    assert np.abs(np.diff(p, axis=0)).max() < 0.05  # no jumps
    mid = position_at(pts, times, tau, np.array([7.0]))  # middle of a straight leg
    np.testing.assert_allclose(mid[0], [10.0 / 3 * 3 - 0.0, 0, 10], atol=1e-9)


def test_the_time_sweep_over_legs_misses_no_overlap():
    """With unbounded reach only time decides which leg pairs are computed: the pruned walk (legs
    of j overlapping leg a of i found by a forward sweep) must equal computing every leg pair."""
    rng = np.random.default_rng(5)
    n_b, n_u, n_w = 2, 40, 6
    pts = rng.uniform(-30, 30, size=(n_b, n_u, n_w, 3))
    durations = rng.uniform(0.1, 4.0, size=(n_b, n_u, n_w - 1)) * (rng.random((n_b, n_u, n_w - 1)) > 0.1)
    times = rng.uniform(0, 6, size=(n_b, n_u, 1)) + np.concatenate(
        [np.zeros((n_b, n_u, 1)), np.cumsum(durations, axis=-1)], axis=-1
    )
    pairs = np.array([(i, j) for i in range(n_u) for j in range(i + 1, n_u)])
    d_all, t_all = pair_closest_approach(pts, times, pairs)
    d_swept, t_swept = pair_closest_approach(pts, times, pairs, np.full(n_u, np.inf))
    assert np.isfinite(d_all).sum() > 0.9 * d_all.size
    np.testing.assert_array_equal(d_swept, d_all)
    finite = np.isfinite(d_all)
    np.testing.assert_array_equal(t_swept[finite], t_all[finite])
