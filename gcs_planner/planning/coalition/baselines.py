"""Baselines on the same simulation (section 5.2).

- ``solve_polynomial``: polynomial-time coalition formation after Sujit et al. (ref [23]), which
  optimises completion time only: bidders are added in order of ETA (eq. 23) until the coalition
  can cover every task; tasks are then given greedily, in slot order, to the free member with the
  shortest path to that task. O(n K) per added bidder.
- Global optimisation (no link limits, all idle UAVs, no message delays) is run by the simulation
  with ``method = "global"``: it widens the candidate set and calls ``aco.solve_aco`` with a
  4x larger colony and iteration count (``GLOBAL_SCALE``); not suitable online, as in the paper.
"""

from __future__ import annotations

import numpy as np

from gcs_planner.planning.coalition.aco import CoalitionProblem, Solution, make_solution
from gcs_planner.planning.coalition.model import CoalitionParams

__all__ = ["GLOBAL_SCALE", "solve_polynomial"]

GLOBAL_SCALE = 4


def _greedy(prob: CoalitionProblem, members: np.ndarray) -> np.ndarray:
    cap = prob.capable
    K = len(prob.kind)
    assign = np.full(K, -1)
    free = np.zeros(len(prob.speed_mps), bool)
    free[members] = True
    for k in range(K):
        ok = free & cap[:, k]
        if ok.any():
            i = int(np.argmin(np.where(ok, prob.length_m[:, k], np.inf)))
            assign[k] = i
            free[i] = False
    return assign


def solve_polynomial(prob: CoalitionProblem, params: CoalitionParams, eta_s: np.ndarray) -> Solution:
    """Add candidates by ascending ETA until the greedy assignment covers all tasks."""
    order = np.argsort(eta_s, kind="stable")
    assign = np.full(len(prob.kind), -1)
    for n in range(1, len(order) + 1):
        assign = _greedy(prob, order[:n])
        if (assign >= 0).all():
            break
    return make_solution(assign, prob, params)
