"""Message bus of the ad-hoc network (section 3.1): range-limited one-hop links with one-way delay.

Adjacency is time-varying: a_ij(t) = 1 when |p_i(t) - p_j(t)| <= r_n (symmetric, eq. before 19).
A message from i to j sent at t is delivered at t + dt_d (+ optional uniform jitter, + a per-UAV
extra delay used by tests) only if the link holds both when it is sent and when it arrives
(choice: the paper does not say what happens to a message in flight when the link breaks; we
drop it). No relaying: tenders reach one-hop neighbours only.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

__all__ = ["MessageBus"]


class MessageBus:
    """positions(t) -> (n, 2) every UAV's position [m] at time t [s]; position(i, t) -> (2,) one UAV's."""

    def __init__(
        self,
        positions: Callable[[float], np.ndarray],
        position: Callable[[int, float], np.ndarray],
        range_m: float,
        delay_s: float,
        rng: np.random.Generator,
        jitter_s: float = 0.0,
        extra_delay_s: np.ndarray | None = None,
    ) -> None:
        self.positions = positions
        self.position = position
        self.range_m = range_m
        self.delay_s = delay_s
        self.jitter_s = jitter_s
        self.rng = rng
        self.extra_delay_s = extra_delay_s

    def adjacency(self, t_s: float) -> np.ndarray:
        """(n, n) bool a_ij(t): in communication range, no self-links."""
        p = self.positions(t_s)
        d = np.hypot(p[:, None, 0] - p[None, :, 0], p[:, None, 1] - p[None, :, 1])
        adj = d <= self.range_m
        np.fill_diagonal(adj, False)
        return adj

    def neighbours(self, i: int, t_s: float) -> np.ndarray:
        """Indices of i's one-hop neighbours at t_s."""
        p = self.positions(t_s)
        d = np.hypot(*(p - p[i]).T)
        d[i] = np.inf
        return np.flatnonzero(d <= self.range_m)

    def arrival_s(self, src: int, dst: int, t_send_s: float) -> float | None:
        """When a message sent src -> dst at t_send_s arrives, or None if the link is down."""
        delay = self.delay_s
        if self.jitter_s > 0:
            delay += float(self.rng.uniform(0.0, self.jitter_s))
        if self.extra_delay_s is not None:
            delay += float(self.extra_delay_s[src] + self.extra_delay_s[dst])
        t_arr = t_send_s + delay
        for t in (t_send_s, t_arr):
            if np.hypot(*(self.position(src, t) - self.position(dst, t))) > self.range_m:
                return None
        return t_arr
