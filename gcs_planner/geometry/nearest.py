"""The k nearest of a stream of candidates, kept in place: the compiled planners' neighbour lists."""

from __future__ import annotations

import numpy as np

from gcs_planner.core.compiled import compiled

__all__ = ["keep_nearest"]


@compiled
def keep_nearest(js: np.ndarray, d2s: np.ndarray, n: int, j: int, d2: float) -> int:
    """Offer candidate ``j`` at squared distance ``d2`` to the ``n`` kept so far in ``js`` / ``d2s``
    (nearest first, ties by index; at most ``len(js)``); returns how many are kept now."""
    at = n
    while at > 0 and (d2s[at - 1] > d2 or (d2s[at - 1] == d2 and js[at - 1] > j)):
        at -= 1
    if at == len(js):
        return n
    n = min(n + 1, len(js))
    for m in range(n - 1, at, -1):  # the farther ones move down, the last one out
        js[m], d2s[m] = js[m - 1], d2s[m - 1]
    js[at], d2s[at] = j, d2
    return n
