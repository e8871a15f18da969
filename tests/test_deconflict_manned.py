"""Bayesian manned-aircraft prediction: conjugate update, region coverage, growth, modes."""

from __future__ import annotations

import numpy as np
import pytest

from gcs_planner.model.scenario import ScenarioError
from gcs_planner.planning import parse_scenario
from gcs_planner.planning.deconflict4d.manned import (
    MannedTrack,
    mode_weights,
    posterior,
    predict_zones,
    predictive,
    prior_from_history,
    prior_from_velocity,
    region_threshold,
)

DT = 1.0
POP_VEL = np.array([40.0, 5.0, 0.0])  # population mean velocity [m/s]
POP_SPREAD = np.array([4.0, 4.0, 0.5])  # between-aircraft sd of the mean velocity
NOISE = np.array([1.5, 1.0, 0.3])  # within-flight per-step velocity noise sd


def _flight(rng: np.random.Generator, steps: int) -> np.ndarray:
    """Positions (steps + 1, 3) of one simulated aircraft: own mean velocity plus step noise."""
    v = POP_VEL + rng.normal(size=3) * POP_SPREAD
    disp = (v + rng.normal(size=(steps, 3)) * NOISE) * DT
    return np.vstack([np.zeros(3), np.cumsum(disp, axis=0)])


def _inside(x, mean, scale, gamma) -> bool:
    d = x - mean
    return float(d @ np.linalg.solve(scale, d)) <= gamma


@pytest.mark.parametrize("horizon", [1, 5])
def test_predictive_region_covers_true_position_95_percent(horizon):
    rng = np.random.default_rng(2024)
    prior = prior_from_history([_flight(rng, 30) for _ in range(60)], DT)
    trials, hits = 2000, 0
    for _ in range(trials):
        track = _flight(rng, 12 + horizon)
        observed, future = track[:13], track[12 + horizon]
        post = posterior(prior, np.diff(observed, axis=0))
        mean, scale, dof = predictive(post, np.array([horizon]))
        hits += _inside(future - observed[-1], mean[0], scale[0], region_threshold(dof, 0.95))
    coverage = hits / trials
    assert 0.93 <= coverage <= 0.97, coverage  # binomial sd ~0.005 at 2000 trials


def test_wrong_confidence_changes_coverage():
    """The region really depends on the threshold: a 50 % region covers about half."""
    rng = np.random.default_rng(5)
    prior = prior_from_history([_flight(rng, 30) for _ in range(60)], DT)
    hits = 0
    for _ in range(1000):
        track = _flight(rng, 13)
        post = posterior(prior, np.diff(track[:13], axis=0))
        mean, scale, dof = predictive(post, np.array([1]))
        hits += _inside(track[13] - track[12], mean[0], scale[0], region_threshold(dof, 0.5))
    assert 0.44 <= hits / 1000 <= 0.56


def test_posterior_learns_the_observed_velocity():
    prior = prior_from_velocity([0.0, 0.0, 0.0], [1.0, 1.0, 1.0], strength=2.0, dt_s=DT)
    disp = np.tile([30.0, 0.0, 0.0], (50, 1))
    post = posterior(prior, disp)
    assert post.mu == pytest.approx([30.0 * 50 / 52, 0, 0])
    assert post.kappa == 52 and post.nu == prior.nu + 50


def _track(modes, velocity=(20.0, 0.0, 0.0)):
    times = np.arange(-10, 1) * DT
    pos = times[:, None] * np.asarray(velocity)
    return MannedTrack("ga", times, pos, DT, tuple(modes))


def test_zones_grow_with_horizon_and_include_safety_distance():
    cruise = prior_from_velocity([20.0, 0, 0], [0.5, 0.5, 0.2], 10.0, DT)
    (zone,) = predict_zones(_track([("cruise", cruise, 1.0)]), 0, t_end_s=30.0, safety_m=4.0)
    assert zone.times_s[0] == 0.0 and zone.times_s[-1] >= 30.0
    assert np.all(np.diff(zone.axes_m, axis=0) > 0)  # every semi-axis grows with the horizon
    assert zone.axes_m[0].min() > 4.0  # safety distance added to the first step's ellipsoid
    np.testing.assert_allclose(zone.centres_m[5], [100.0, 0, 0], atol=1.0)  # constant velocity ahead


def test_union_over_modes_and_unlikely_modes_dropped():
    cruise = prior_from_velocity([20.0, 0, 0], [0.5, 0.5, 0.2], 10.0, DT)
    descent = prior_from_velocity([18.0, 0, -3.0], [0.5, 0.5, 0.2], 10.0, DT)
    far = prior_from_velocity([-20.0, 0, 0], [0.5, 0.5, 0.2], 10.0, DT)
    zones = predict_zones(
        _track([("cruise", cruise, 0.5), ("descent", descent, 0.3), ("reverse", far, 0.2)]), 0, 20.0, 1.0
    )
    names = {z.name for z in zones}
    assert "ga:cruise" in names and "ga:reverse" not in names
    # a track that is descending makes the descent mode the likely one
    zones = predict_zones(
        _track([("cruise", cruise, 0.5), ("descent", descent, 0.5)], velocity=(18.0, 0, -3.0)), 0, 20.0, 1.0
    )
    best = max(zones, key=lambda z: z.weight)
    assert best.name == "ga:descent" and best.weight > 0.9


def test_a_mode_of_weight_0_gets_no_weight_and_all_0_is_refused():
    cruise = prior_from_velocity([20.0, 0, 0], [0.5, 0.5, 0.2], 10.0, DT)
    descent = prior_from_velocity([18.0, 0, -3.0], [0.5, 0.5, 0.2], 10.0, DT)
    track = _track([("cruise", cruise, 1.0), ("descent", descent, 0.0)], velocity=(18.0, 0, -3.0))
    np.testing.assert_array_equal(mode_weights(track), [1.0, 0.0])  # the data favour descent: no matter
    modes = [{"name": "a", "weight": 0.0}, {"name": "b", "weight": 0}]
    data = {"origin": {"lat_deg": 47.0, "lon_deg": 8.0}, "planner": {"name": "deconflict_4d"},
            "vehicles": [{"sysid": 1, "start": [0.0, 0.0, 20.0], "goal": [100.0, 0.0, 20.0]}],
            "manned": [{"id": "ga", "position_m": [0.0, 0.0, 50.0], "velocity_mps": [10.0, 0, 0],
                        "modes": modes}]}  # fmt: skip
    with pytest.raises(ScenarioError, match=r"manned\[0\]\.modes: every weight is 0"):
        parse_scenario(data)


def test_track_spacing_is_validated():
    prior = prior_from_velocity([20.0, 0, 0], [0.5, 0.5, 0.2], 10.0, DT)
    with pytest.raises(ValueError, match="dt_s"):
        MannedTrack("x", np.array([0.0, 1.0, 3.0]), np.zeros((3, 3)), 1.0, (("m", prior, 1.0),))
