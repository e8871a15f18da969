"""Division-of-labour ant colony (section 4.4, eqs. 26-32) maximising J = w1 J1 + w2 J2 - w3 J3 (eqs. 7-12).

The leader solves one coalition: candidates = {leader} + potential members (their bids), tasks =
the target's strike and assessment slots. Every candidate has a sub-colony; an *ant cluster* (one
ant per candidate) builds one joint plan. ``m`` clusters are built in parallel as numpy arrays
(m, candidates, tasks); no Python loop over ants.

Per construction step, in every cluster:
1. eq. 26-27: the ant that moves is drawn with probability proportional to its capability
   C = L_frac * max_allowed(tau) * N_allowed / N_task * (N_max - N_cur), N_max = 1 (one task per
   UAV per coalition, see model.py), L_frac its remaining-range fraction.
2. eq. 28 (ACS rule): with q <= q0 it takes argmax tau^alpha eta^beta over its allowed tasks,
   else a roulette draw; eta = 1 / (V + eps), V = w1 Cd + w2 Ct (eq. 29).
   Cd (eq. 30): the Dubins length to the task entry pose, min-max normalised over the matrix.
   Ct (eq. 31) is ill-posed as printed (read as a cost, it rewards arriving late). We use the
   lateness fraction clip((t_v - t_s) / (t_e - t_s), 0, 1): t_s = earliest arrival of any
   candidate at that task, t_e = t_s + time_scale_s.
3. ACS local update on the chosen (candidate, task) pairs: tau <- (1 - rho) tau + rho tau0.
After each iteration the global update (eq. 32, delta tau undefined in the paper): evaporate all
by rho and deposit rho * max(J_best, 0.05) on the best plan's pairs (ACS "deposit by best").

J of a plan (eqs. 7-12), normalised so the weights are comparable:
- strike slots: lambda_0 = max over strikers of (ETA_k - offset_k), lambda_k = lambda_0 + offset_k
  (the latest striker is the reference; the others stretch); assessment start = last strike +
  delay; an assessor that cannot be there starts late.
- J1 = sum_k F_k exp(-beta (t_done_k - t0)) / sum_k F_k (uncovered tasks give 0),
- J2 = mean over members of the range fraction left after the task,
- J3 = sum_k |t_predicted_k - t_required_k| / (n_tasks * time_scale_s), t_predicted = fastest
  arrival (so J3 is the total stretching/waiting plus any lateness).
Defaults (not in the paper): alpha 1, beta 2, q0 0.9, rho 0.1, tau0 1, 30 clusters, 6 iterations.

Colony shape (choice, for compute): 30 clusters x 6 iterations (180 plans) instead of 10 x 15
(150): a construction step costs about the same for 10 or 30 clusters, so the colony's time is
set by iterations x tasks (measurements: docs/coalition.md, Decisions).

Repair (choice, not in the paper): when a member's timed path cannot clear the threats, the leader
re-covers only that task (``repair``: a free candidate or a swap, schedule-keeping moves first,
then the best J) instead of running the colony again; see sim.py.

Compute: a construction step is ~35 numpy calls on (tasks, clusters, candidates) arrays.
Tasks come first, so the eq. 27 reductions are elementwise passes. ``allowed`` is updated in
place. A roulette draw is one argmax of "cumulative sum >= x". The step's three uniform draws come
from one ``rng.random((3, m))`` call, the same stream as three ``rng.random(m)`` calls, so a seed
gives the same plans as a one-draw-at-a-time implementation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from gcs_planner.planning.coalition.model import STRIKE, CoalitionParams

__all__ = ["CoalitionProblem", "Solution", "coverable", "evaluate", "make_solution", "repair", "solve_aco"]

EPS = 1e-3


@dataclass
class CoalitionProblem:
    """One formation: candidates (index 0 = leader if it is capable) and task slots.

    length_m[i, k]: shortest path length of candidate i from its pose at t_start to task k's entry.
    """

    length_m: np.ndarray  # (n, K)
    speed_mps: np.ndarray  # (n,)
    range_left_m: np.ndarray  # (n,) at t_start
    range_max_m: np.ndarray  # (n,)
    can_strike: np.ndarray  # (n,) bool (has munitions)
    can_assess: np.ndarray  # (n,) bool
    kind: np.ndarray  # (K,)
    offset_s: np.ndarray  # (K,) strike slot offsets
    reward: np.ndarray  # (K,) F_k
    decay_per_s: float
    assess_delay_s: float
    assess_duration_s: float
    t0_s: float  # tender time (decay reference)
    t_start_s: float  # t_e^s: when members start flying their tasks

    @property
    def capable(self) -> np.ndarray:
        """(n, K) bool: candidate i may take task k (payload, munitions and range)."""
        cap = np.where(self.kind[None, :] == STRIKE, self.can_strike[:, None], self.can_assess[:, None])
        return cap & (self.length_m < self.range_left_m[:, None])


@dataclass
class Solution:
    assign: np.ndarray  # (K,) candidate index per task, -1 = uncovered
    J: float
    parts: dict[str, float]
    t_required_s: np.ndarray  # (K,) lambda_k for strikes, required start for assessments
    covered: bool


def evaluate(assign: np.ndarray, prob: CoalitionProblem, params: CoalitionParams):
    """J and its parts for plans `assign` (m, K); returns (J (m,), parts dict of (m,), t_required (m, K))."""
    assign = np.atleast_2d(assign)
    m, K = assign.shape
    has = assign >= 0
    a = np.where(has, assign, 0)
    eta = prob.t_start_s + prob.length_m[a, np.arange(K)] / prob.speed_mps[a]
    eta = np.where(has, eta, np.nan)
    strike = prob.kind == STRIKE
    # max over strikes ignoring NaN (what np.nanmax computes, without its wrapper overhead)
    lam0 = np.fmax.reduce(np.where(strike, eta - prob.offset_s, np.nan), axis=1, initial=-np.inf)
    lam0 = np.where(np.isfinite(lam0), lam0, prob.t_start_s)
    t_last_strike = lam0 + (prob.offset_s[strike].max() if strike.any() else 0.0)
    t_req = np.where(strike, lam0[:, None] + prob.offset_s, (t_last_strike + prob.assess_delay_s)[:, None])
    start = np.where(strike, t_req, np.fmax(t_req, eta))
    done = start + np.where(strike, 0.0, prob.assess_duration_s)
    f = prob.reward * np.exp(-prob.decay_per_s * (done - prob.t0_s))
    j1 = np.where(has, f, 0.0).sum(1) / prob.reward.sum()
    used = prob.speed_mps[a] * (done - prob.t_start_s)
    frac = (prob.range_left_m[a] - used) / prob.range_max_m[a]
    j2 = np.where(has, frac, 0.0).sum(1) / np.maximum(has.sum(1), 1)
    j3 = np.where(has, np.abs(start - eta), 0.0).sum(1) / (K * params.time_scale_s)
    J = params.w1 * j1 + params.w2 * j2 - params.w3 * j3
    return J, {"J1": j1, "J2": j2, "J3": j3}, t_req


def coverable(prob: CoalitionProblem) -> bool:
    """Can the candidates cover every task, one task each? (maximum bipartite matching)"""
    cap = prob.capable
    if cap.shape[0] < cap.shape[1]:
        return False
    rows, cols = linear_sum_assignment(np.where(cap, 0.0, 1.0))
    return bool(cap[rows, cols].all())


def _heuristic(prob: CoalitionProblem, params: CoalitionParams) -> np.ndarray:
    """eta (n, K) of eqs. 28-31."""
    fin = np.isfinite(prob.length_m)
    big = prob.length_m[fin].max() if fin.any() else 1.0
    L = np.where(fin, prob.length_m, big)  # excluded pairs are masked by `capable` anyway
    cd = (L - L.min()) / max(L.max() - L.min(), 1e-9)
    t_v = prob.t_start_s + L / prob.speed_mps[:, None]
    t_s = np.where(prob.capable, t_v, np.inf).min(0)
    t_s = np.where(np.isfinite(t_s), t_s, t_v.min(0))
    ct = np.clip((t_v - t_s) / params.time_scale_s, 0.0, 1.0)
    return 1.0 / (params.w1 * cd + params.w2 * ct + EPS)


def solve_aco(
    prob: CoalitionProblem, params: CoalitionParams, rng: np.random.Generator, scale: int = 1
) -> Solution:
    """Best plan found by the colony (scale multiplies clusters and iterations, for the global baseline)."""
    n, K = prob.length_m.shape
    m, iters = params.ants * scale, params.iterations * scale
    cap = prob.capable
    tau = np.full((n, K), params.tau0)
    tau_t = tau.T[:, None, :]  # (K, 1, n) view: tau is only ever updated in place below
    eta_b = _heuristic(prob, params) ** params.beta
    lfrac = np.clip(prob.range_left_m / prob.range_max_m, 0.0, 1.0)
    keep, add = 1 - params.rho, params.rho * params.tau0
    rows = np.arange(m)
    best_assign, best_J = np.full(K, -1), -np.inf
    cap_t = cap.T[:, None, :].astype(float)  # (K, 1, n)
    for _ in range(iters):
        assign = np.full((m, K), -1)
        # (K, m, n) 0/1: capable, ant idle, task open; tasks first, so the reductions over tasks
        # are elementwise passes over (m, n) slices (numpy is slow at reducing short inner axes)
        allowed = np.repeat(cap_t, m, 1)
        for _step in range(K):
            # eq. 27; (N_max - N_cur) = 0 for a candidate with a task: its allowed row is all 0 already
            c = lfrac * (allowed * tau_t).max(0) * allowed.sum(0) / K
            total = c.sum(1)
            live = total > 0
            if not live.any():
                break
            draw = rng.random((3, m))  # the same stream as three rng.random(m) calls
            ant = _roulette(c.cumsum(1), draw[0] * total)  # eq. 26
            score = allowed[:, rows, ant].T * (tau**params.alpha * eta_b)[ant]  # (m, K), 0 if not allowed
            scum = score.cumsum(1)
            roul = _roulette(scum, draw[1] * scum[:, -1])
            task = np.where(draw[2] <= params.q0, score.argmax(1), roul)  # eq. 28
            ok = live & (score[rows, task] > 0)
            r, a, t = (rows, ant, task) if ok.all() else (rows[ok], ant[ok], task[ok])
            assign[r, t] = a
            allowed[:, r, a] = 0.0
            allowed[t, r, :] = 0.0
            tau[a, t] = keep * tau[a, t] + add  # ACS local update
        J, _, _ = evaluate(assign, prob, params)
        i = int(np.argmax(J))
        if J[i] > best_J:
            best_J, best_assign = float(J[i]), assign[i].copy()
        tau *= keep  # eq. 32, global update by the best plan
        has = best_assign >= 0
        tau[best_assign[has], np.flatnonzero(has)] += params.rho * max(best_J, 0.05)
    return make_solution(best_assign, prob, params)


def repair(
    assign: np.ndarray,
    tasks: list[int],
    t_required_s: np.ndarray,
    prob: CoalitionProblem,
    params: CoalitionParams,
) -> np.ndarray | None:
    """The plan `assign` with only `tasks` re-covered (their members were excluded), or None.

    Each task in turn gets the best single move: a free capable candidate takes it, or another
    member takes it and gives its own task to the excluded member (a swap). Moves that keep every
    required time (t_required_s, the schedule of `assign`) come first, so the other members keep
    their planned paths; among them, or else among all moves, the highest J wins (the first on a
    tie). None when no move covers a task. prob.length_m holds inf for excluded pairs.
    """
    out = np.array(assign, copy=True)
    cap = prob.capable
    n = len(cap)
    for k in tasks:
        x, out[k] = out[k], -1
        moves = [(k, c, -1, -1) for c in np.flatnonzero(cap[:, k] & ~np.isin(np.arange(n), out))]
        moves += [(k, j, k2, x) for k2, j in enumerate(out) if j >= 0 and cap[j, k] and cap[x, k2]]
        if not moves:
            return None
        plans = np.repeat(out[None], len(moves), 0)
        for row, (k1, c1, k2, c2) in enumerate(moves):
            plans[row, k1] = c1
            if k2 >= 0:
                plans[row, k2] = c2
        J, _, t_req = evaluate(plans, prob, params)
        same = (t_req == t_required_s).all(1)
        out = plans[int(np.argmax(np.where(same, J, -np.inf)) if same.any() else np.argmax(J))]
    return out


def _roulette(cum: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Per row, the number of entries of the non-decreasing cum (m, n) below x (m,), at most n - 1.

    argmax of the first cum >= x: one fast pass, instead of summing a boolean array."""
    above = cum >= x[:, None]
    return np.where(above[:, -1], above.argmax(1), cum.shape[1] - 1)


def make_solution(assign: np.ndarray, prob: CoalitionProblem, params: CoalitionParams) -> Solution:
    J, parts, t_req = evaluate(assign[None], prob, params)
    return Solution(
        assign=assign,
        J=float(J[0]),
        parts={k: float(v[0]) for k, v in parts.items()},
        t_required_s=t_req[0],
        covered=bool((assign >= 0).all()),
    )
