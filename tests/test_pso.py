"""The shared PSO engine: convergence, determinism, bounds, elites, budgets, schedules, mutation."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gcs_planner.planning.pso import CauchyMutation, PSOConfig, inertia_weight, minimize


def sphere(x: np.ndarray) -> np.ndarray:
    return np.sum((x - 1.0) ** 2, axis=1)


def rosenbrock(x: np.ndarray) -> np.ndarray:
    return np.sum(100.0 * (x[:, 1:] - x[:, :-1] ** 2) ** 2 + (1.0 - x[:, :-1]) ** 2, axis=1)


def test_sphere_converges_to_minimum():
    lo, hi = np.full(5, -10.0), np.full(5, 10.0)
    res = minimize(sphere, lo, hi, PSOConfig(particles=30, iterations=200), np.random.default_rng(1))
    assert res.best_cost < 1e-6
    np.testing.assert_allclose(res.best_x, 1.0, atol=1e-3)
    assert np.all(np.diff(res.history) <= 0)  # gbest never gets worse
    assert res.history[-1] == res.best_cost


def test_rosenbrock_2d_converges():
    lo, hi = np.full(2, -2.0), np.full(2, 2.0)
    cfg = PSOConfig(particles=40, iterations=300, inertia="exponential", alpha=0.03)
    res = minimize(rosenbrock, lo, hi, cfg, np.random.default_rng(3))
    assert res.best_cost < 1e-4
    np.testing.assert_allclose(res.best_x, [1.0, 1.0], atol=0.05)


def test_same_seed_same_run_different_seed_differs():
    lo, hi = np.full(4, -5.0), np.full(4, 5.0)
    cfg = PSOConfig(particles=10, iterations=20, mutation=CauchyMutation(beta=0.5))
    a = minimize(rosenbrock, lo, hi, cfg, np.random.default_rng(7))
    b = minimize(rosenbrock, lo, hi, cfg, np.random.default_rng(7))
    c = minimize(rosenbrock, lo, hi, cfg, np.random.default_rng(8))
    np.testing.assert_array_equal(a.history, b.history)
    np.testing.assert_array_equal(a.best_x, b.best_x)
    assert not np.array_equal(a.history, c.history)


def test_positions_and_velocities_respect_bounds():
    lo, hi = np.array([0.0, -1.0, 5.0]), np.array([1.0, 1.0, 6.0])
    seen = []

    def cost(x):
        seen.append(x.copy())
        return -np.sum(x, axis=1) * 1e3  # pulls hard towards (and past) the upper corner

    cfg = PSOConfig(particles=20, iterations=30, v_max=np.array([0.01, 0.5, 0.5]), c1=2.0, c2=2.0)
    res = minimize(cost, lo, hi, cfg, np.random.default_rng(0))
    xs = np.stack(seen)
    assert np.all(xs >= lo) and np.all(xs <= hi)
    steps = np.abs(np.diff(xs, axis=0))
    assert np.all(steps[..., 0] <= 0.01 + 1e-12)  # per-dimension velocity clamp
    np.testing.assert_allclose(res.best_x[1:], hi[1:])


def test_mutation_output_is_clamped_to_bounds():
    lo, hi = np.full(3, 1.0), np.full(3, 2.0)
    seen = []

    def cost(x):
        seen.append(x.copy())
        return sphere(x)

    for stage in ("before_velocity", "after_move"):
        cfg = PSOConfig(particles=15, iterations=10, mutation=CauchyMutation(beta=0.0), mutation_stage=stage)
        minimize(cost, lo, hi, cfg, np.random.default_rng(2))
    xs = np.stack(seen)
    assert np.all(xs >= lo) and np.all(xs <= hi)


def test_budget_counted_and_enforced():
    calls = []

    def cost(x):
        calls.append(len(x))
        return sphere(x)

    lo, hi = np.full(2, -1.0), np.full(2, 1.0)
    res = minimize(cost, lo, hi, PSOConfig(particles=8, iterations=25), np.random.default_rng(0))
    assert res.evaluations == sum(calls) == 8 * 25
    assert res.iterations == len(res.history) == 25
    calls.clear()
    cfg = PSOConfig(particles=8, iterations=25, restarts=2, max_evaluations=100)
    res = minimize(cost, lo, hi, cfg, np.random.default_rng(0))
    assert res.evaluations == sum(calls) == 96 and res.stopped_by_budget
    assert res.iterations == 12


def test_supplied_initial_particles_are_used():
    lo, hi = np.full(3, -10.0), np.full(3, 10.0)
    first = []

    def cost(x):
        if not first:
            first.append(x.copy())
        return sphere(x)

    init = np.array([[1.0, 1.0, 1.0], [20.0, 0.0, 0.0]])  # second row outside: clamped
    res = minimize(cost, lo, hi, PSOConfig(particles=6, iterations=1), np.random.default_rng(0), init=init)
    np.testing.assert_array_equal(first[0][0], [1.0, 1.0, 1.0])
    np.testing.assert_array_equal(first[0][1], [10.0, 0.0, 0.0])
    assert res.best_cost == 0.0 and res.iterations == 1
    with pytest.raises(ValueError, match="init must be"):
        minimize(cost, lo, hi, PSOConfig(particles=1, iterations=1), np.random.default_rng(0), init=init)


def test_restart_keeps_elites_and_global_best():
    lo, hi = np.full(2, -5.0), np.full(2, 5.0)
    batches = []

    def cost(x):
        batches.append(x.copy())
        return sphere(x)

    cfg = PSOConfig(particles=10, iterations=5, restarts=1, elite_fraction=0.3)
    res = minimize(cost, lo, hi, cfg, np.random.default_rng(4))
    assert res.rounds == 2 and res.iterations == 10
    # the first batch of round 2 starts with the 3 best personal bests of round 1
    per_particle_best = np.min([sphere(b) for b in batches[:5]], axis=0)
    best3 = np.sort(per_particle_best)[:3]
    np.testing.assert_allclose(np.sort(sphere(batches[5][:3])), best3)
    assert np.all(np.diff(res.history) <= 0)  # gbest carried across the restart
    assert res.pbest_cost[0] == res.best_cost and np.all(np.diff(res.pbest_cost) >= 0)


def test_inertia_schedules():
    t_max = 100
    lin = PSOConfig(inertia="linear")
    exp = PSOConfig(inertia="exponential", alpha=0.03)
    assert inertia_weight(PSOConfig(inertia="constant", w_max=0.7), 50, t_max) == 0.7
    assert inertia_weight(lin, 1, t_max) == pytest.approx(0.9)
    assert inertia_weight(lin, t_max, t_max) == pytest.approx(0.4)
    assert inertia_weight(exp, 1, t_max) == pytest.approx(0.9)
    assert inertia_weight(exp, 100, t_max) == pytest.approx(0.5 * math.exp(-99 * 0.03) + 0.4)
    assert inertia_weight(exp, 100, t_max) == pytest.approx(0.4257, abs=1e-4)


def test_cauchy_mutation_scale_decays():
    rng = np.random.default_rng(0)
    x = np.ones((2000, 3))
    mut = CauchyMutation(beta=0.5)
    d1 = np.median(np.abs(mut(x, 1, 100, rng) - x))
    d10 = np.median(np.abs(mut(x, 10, 100, rng) - x))
    assert d1 == pytest.approx(1.0, rel=0.15)  # median |standard Cauchy| = 1
    assert d10 == pytest.approx(math.exp(-4.5), rel=0.15)
    absolute = CauchyMutation(beta=0.0, relative=False, scale=np.array([0.0, 1.0, 0.0]))
    out = absolute(np.zeros((50, 3)), 1, 100, rng)
    assert np.all(out[:, [0, 2]] == 0.0) and np.any(out[:, 1] != 0.0)


def test_progress_called_every_iteration_and_config_errors():
    calls = []
    lo, hi = np.zeros(1), np.ones(1)
    minimize(
        sphere,
        lo,
        hi,
        PSOConfig(particles=3, iterations=4),
        np.random.default_rng(0),
        progress=lambda f, m: calls.append(f),
    )
    assert calls == [0.25, 0.5, 0.75, 1.0]
    with pytest.raises(ValueError, match="inertia"):
        PSOConfig(inertia="cubic")
    with pytest.raises(ValueError, match="cost returned shape"):
        minimize(
            lambda x: np.zeros(2), lo, hi, PSOConfig(particles=3, iterations=1), np.random.default_rng(0)
        )


def test_gbest_greedy_mutation_counts_one_extra_row_and_only_improves():
    lo, hi = np.full(3, -5.0), np.full(3, 5.0)
    sizes = []

    def cost(x):
        sizes.append(len(x))
        return sphere(x)

    cfg = PSOConfig(
        particles=6,
        iterations=30,
        mutation=CauchyMutation(beta=0.1, relative=False, scale=0.5),
        mutation_stage="gbest_greedy",
    )
    res = minimize(cost, lo, hi, cfg, np.random.default_rng(9))
    assert sizes == [6] + [7] * 29  # the trial rides along with the next swarm evaluation
    assert res.evaluations == 6 * 30 + 29
    assert np.all(np.diff(res.history) <= 0)
    # the engine's own gbest equals the best row it ever evaluated (trials included)
    assert res.best_cost == pytest.approx(float(sphere(res.best_x[None, :])[0]))
