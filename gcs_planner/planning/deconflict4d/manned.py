"""Manned aircraft: Bayesian prediction of future positions and the moving no-fly zones.

The paper models the per-step position translation of manned aircraft j' in motion mode k as
``dp ~ N(mu_k, Sigma_k)`` with a prior from the Bayesian mean of historical flights, updated with
the observed track, and turns the predictive mean and covariance into an uncertainty region that
UAVs must avoid. Its equations are lost; this is the standard conjugate reading:

- Per mode, the per-step displacement (position change over ``dt_s``) is Gaussian with unknown
  mean and covariance under a Normal-Inverse-Wishart prior NIW(mu0, kappa0, Psi0, nu0).
  :func:`prior_from_history` fits it to historical tracks (empirical Bayes: mu0 the mean
  displacement, Psi0 / (nu0 - 4) the pooled within-track covariance, kappa0 the ratio of within-
  to between-track spread); :func:`prior_from_velocity` states it directly (scenario files).
- The observed track's displacements update it in closed form (:func:`posterior`).
- The displacement summed over the next h steps is then exactly multivariate Student-t:
  ``t_{nu_n - 2}(h mu_n, (h + h^2 / kappa_n) Psi_n / (nu_n - 2))`` in 3-D, so the covariance grows
  with the horizon (noise) and faster still while the mean velocity is uncertain (h^2 term).
- The region of confidence ``c`` is the ellipsoid ``(x - m)^T S^-1 (x - m) <= 3 F_{3, nu}^-1(c)``
  (exact for the Student-t; tends to the chi-square 7.815 of the digest for c = 0.95).
- Motion modes (e.g. cruise, descent) each have a prior; their posterior weights come from the
  marginal likelihood of the observed track; the no-fly region is the union of the ellipsoids of
  every mode whose weight is at least ``min_mode_weight``.
- Each ellipsoid is inflated by the safety distance by adding it to every semi-axis (this
  contains the exact Minkowski sum). Between prediction steps the centre moves linearly and the
  step-end ellipsoid (the larger, same axes) is used for the whole step: conservative.
The paper's bounded-uncertainty regime (set-based bounds) is not implemented.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import special

__all__ = [
    "MannedTrack",
    "NIWPrior",
    "Zone",
    "log_marginal_likelihood",
    "mode_weights",
    "posterior",
    "predictive",
    "predict_zones",
    "prior_from_history",
    "prior_from_velocity",
    "region_threshold",
]

DIM = 3


@dataclass(frozen=True)
class NIWPrior:
    """Normal-Inverse-Wishart parameters for the per-step displacement [m per step]."""

    mu: np.ndarray
    kappa: float
    psi: np.ndarray
    nu: float

    def __post_init__(self) -> None:
        if not self.kappa > 0 or not self.nu > DIM + 1:
            raise ValueError(f"NIW needs kappa > 0 and nu > {DIM + 1}, got kappa={self.kappa}, nu={self.nu}")


@dataclass(frozen=True)
class MannedTrack:
    """Observed positions (n, 3) [m] at times (n,) [s], spaced ``dt_s``, and the mode priors."""

    id: str
    times_s: np.ndarray
    positions_m: np.ndarray
    dt_s: float
    modes: tuple[tuple[str, NIWPrior, float], ...]  # (name, prior, prior weight)

    def __post_init__(self) -> None:
        steps = np.diff(self.times_s)
        if len(self.times_s) < 2 or not np.allclose(steps, self.dt_s, rtol=1e-6, atol=1e-6):
            raise ValueError(f"manned {self.id}: track needs >= 2 positions spaced dt_s={self.dt_s} s apart")

    @property
    def displacements(self) -> np.ndarray:
        return np.diff(self.positions_m, axis=0)


@dataclass(frozen=True)
class Zone:
    """One mode's moving no-fly region: centres (H, 3) at times (H,) [s]; the ellipsoid axes as
    rows of ``rot`` (3, 3) (the same at every horizon) and per step (H-1) the inflated semi-axes
    ``axes_m`` (H-1, 3) [m]."""

    owner: int
    name: str
    weight: float
    times_s: np.ndarray
    centres_m: np.ndarray
    rot: np.ndarray
    axes_m: np.ndarray


def prior_from_velocity(velocity_mps, sigma_mps, strength: float, dt_s: float) -> NIWPrior:
    """Prior stated directly: mean velocity, per-axis sd of the per-step velocity, pseudo-count.

    ``strength`` = kappa0 = nu0 - 4 (pseudo-observations behind both the mean and the noise).
    """
    sigma = np.asarray(sigma_mps, dtype=float) * dt_s
    nu = strength + DIM + 1
    return NIWPrior(
        mu=np.asarray(velocity_mps, dtype=float) * dt_s,
        kappa=float(strength),
        psi=np.diag(sigma**2) * (nu - DIM - 1),
        nu=float(nu),
    )


def prior_from_history(tracks: list[np.ndarray], dt_s: float, nu0: float | None = None) -> NIWPrior:
    """Empirical-Bayes NIW prior from historical tracks (each (n_i, 3) positions spaced dt_s).

    dt_s only documents the spacing (displacements are per step). ``nu0`` defaults to the number
    of historical displacements, capped at 200 (the noise estimate is that well supported).
    """
    del dt_s
    disp = [np.diff(np.asarray(t, dtype=float), axis=0) for t in tracks]
    if len(disp) < 2 or any(len(d) < 2 for d in disp):
        raise ValueError("prior_from_history needs >= 2 tracks of >= 3 positions each")
    means = np.array([d.mean(axis=0) for d in disp])
    within = sum((d - d.mean(axis=0)).T @ (d - d.mean(axis=0)) for d in disp) / sum(len(d) - 1 for d in disp)
    between = np.cov(means.T) - within / np.mean([len(d) for d in disp])
    ratio = np.trace(within) / max(np.trace(between), 1e-9 * np.trace(within))
    nu = float(nu0 if nu0 is not None else min(200, sum(len(d) for d in disp)))
    return NIWPrior(mu=means.mean(axis=0), kappa=float(ratio), psi=within * (nu - DIM - 1), nu=nu)


def posterior(prior: NIWPrior, disp: np.ndarray) -> NIWPrior:
    """Conjugate NIW update with observed displacements (n, 3)."""
    disp = np.asarray(disp, dtype=float).reshape(-1, DIM)
    n = len(disp)
    if n == 0:
        return prior
    mean = disp.mean(axis=0)
    scatter = (disp - mean).T @ (disp - mean)
    kappa = prior.kappa + n
    diff = mean - prior.mu
    return NIWPrior(
        mu=(prior.kappa * prior.mu + n * mean) / kappa,
        kappa=kappa,
        psi=prior.psi + scatter + prior.kappa * n / kappa * np.outer(diff, diff),
        nu=prior.nu + n,
    )


def log_marginal_likelihood(prior: NIWPrior, disp: np.ndarray) -> float:
    """log p(displacements | mode) under the NIW prior (closed form)."""
    disp = np.asarray(disp, dtype=float).reshape(-1, DIM)
    post = posterior(prior, disp)
    n = len(disp)
    return float(
        -n * DIM / 2 * math.log(math.pi)
        + special.multigammaln(post.nu / 2, DIM)
        - special.multigammaln(prior.nu / 2, DIM)
        + prior.nu / 2 * np.linalg.slogdet(prior.psi)[1]
        - post.nu / 2 * np.linalg.slogdet(post.psi)[1]
        + DIM / 2 * math.log(prior.kappa / post.kappa)
    )


def predictive(post: NIWPrior, steps: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Student-t predictive of the displacement summed over ``steps`` (H,) future steps.

    Returns mean (H, 3) [m], scale matrices (H, 3, 3) [m^2] and degrees of freedom; the
    covariance is ``scale * dof / (dof - 2)``.
    """
    h = np.asarray(steps, dtype=float).reshape(-1)
    dof = post.nu - DIM + 1
    coeff = h + h**2 / post.kappa
    return h[:, None] * post.mu, coeff[:, None, None] * post.psi / dof, dof


def region_threshold(dof: float, confidence: float) -> float:
    """Mahalanobis-squared bound of the ``confidence`` region of a 3-D Student-t."""
    if not 0 < confidence < 1:
        raise ValueError(f"confidence must be in (0, 1), got {confidence!r}")
    return float(DIM * special.fdtri(DIM, dof, confidence))


def mode_weights(track: MannedTrack) -> np.ndarray:
    """Posterior probability of each motion mode given the observed track (a prior weight of 0
    stays 0; the scenario gives at least one mode a weight above 0)."""
    logw = np.array(
        [
            math.log(w) + log_marginal_likelihood(p, track.displacements) if w > 0 else -math.inf
            for _, p, w in track.modes
        ]
    )
    w = np.exp(logw - logw.max())
    return w / w.sum()


def predict_zones(
    track: MannedTrack,
    owner: int,
    t_end_s: float,
    safety_m: float,
    confidence: float = 0.95,
    min_mode_weight: float = 0.01,
    step_s: float | None = None,
) -> list[Zone]:
    """Moving no-fly zones (one per plausible mode) from the last observation to ``t_end_s``.

    ``step_s`` (a multiple of the track's dt_s; default dt_s) is the spacing of the zone's
    polyline: between steps the centre moves linearly and the step-end ellipsoid is used, so a
    coarser step is cheaper to check and more conservative.
    """
    t_last = float(track.times_s[-1])
    every = max(1, round((step_s or track.dt_s) / track.dt_s))
    n_steps = max(1, math.ceil((t_end_s - t_last) / (track.dt_s * every))) * every
    steps = np.arange(0, n_steps + 1, every, dtype=float)
    zones = []
    for (name, prior, _), weight in zip(track.modes, mode_weights(track), strict=True):
        if weight < min_mode_weight:
            continue
        post = posterior(prior, track.displacements)
        mean, _, dof = predictive(post, steps)
        gamma = region_threshold(dof, confidence)
        eigval, eigvec = np.linalg.eigh(post.psi)
        coeff = (steps + steps**2 / post.kappa) / dof  # scale_h = coeff_h * psi
        semi = np.sqrt(gamma * np.maximum(coeff[:, None] * eigval[None, :], 0.0))
        zones.append(
            Zone(
                owner=owner,
                name=f"{track.id}:{name}",
                weight=float(weight),
                times_s=t_last + steps * track.dt_s,
                centres_m=track.positions_m[-1] + mean,
                rot=eigvec.T.copy(),
                axes_m=semi[1:] + safety_m,
            )
        )
    return zones
