"""Link fault injection: loss, delay, jitter, duplication and reordering of UDP datagrams.

One `FaultyChannel` per direction of one vehicle's link, each with its own seeded
``np.random.Generator``, so a run is reproducible for a given seed and datagram sequence.

Model (choices where a real radio is open):
- Stages run in the order loss -> duplication -> delay + jitter -> reordering -> delivery.
- Loss and duplication are independent Bernoulli draws per datagram (no burst model).
- Delay is ``delay_s + U(0, jitter_s)`` per copy; jitter alone can already reorder datagrams.
- Reordering holds a datagram back and releases it right after the next datagram on the same
  channel (a swap of neighbours, the common case on a radio), or after ``REORDER_HOLD_S`` if no
  other datagram follows, so a held datagram is late, never lost.
- Delays are wall-clock (the GCS lives in wall time), not simulated time.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable
from dataclasses import dataclass, fields

import numpy as np

__all__ = ["REORDER_HOLD_S", "FaultStats", "FaultyChannel", "LinkFaults"]

REORDER_HOLD_S = 0.1
"""Longest time [s] a reordered datagram waits for a successor before it is released anyway."""

Deliver = Callable[[bytes, tuple], None]


@dataclass(frozen=True)
class LinkFaults:
    """Faults applied to both directions of one vehicle's link (each direction seeded separately).

    loss, duplicate, reorder: probabilities in [0, 1] per datagram.
    delay_s: fixed one-way delay [s]; jitter_s: extra uniform delay in [0, jitter_s] [s].
    seed: seeds both directions' generators (mixed with the vehicle's system id).
    """

    loss: float = 0.0
    delay_s: float = 0.0
    jitter_s: float = 0.0
    duplicate: float = 0.0
    reorder: float = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("loss", "duplicate", "reorder"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and 0.0 <= value <= 1.0):
                raise ValueError(f"LinkFaults.{name} must be a probability in [0, 1], got {value!r}")
        for name in ("delay_s", "jitter_s"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value >= 0.0):
                raise ValueError(f"LinkFaults.{name} must be a finite number >= 0, got {value!r}")
        if not isinstance(self.seed, int) or self.seed < 0:
            raise ValueError(f"LinkFaults.seed must be an integer >= 0, got {self.seed!r}")

    @property
    def clean(self) -> bool:
        """True when no fault is configured (the channel then forwards with no overhead)."""
        return all(getattr(self, f.name) == 0 for f in fields(self) if f.name != "seed")


@dataclass
class FaultStats:
    """Datagram counters of one channel, for tests and the CLI's summary."""

    offered: int = 0
    dropped: int = 0
    duplicated: int = 0
    reordered: int = 0
    delivered: int = 0


class FaultyChannel:
    """One direction of a link: `send(data, addr)` applies the faults, then calls ``deliver``."""

    def __init__(self, deliver: Deliver, faults: LinkFaults, seed_key: tuple[int, ...]) -> None:
        self._deliver = deliver
        self._seed_key = seed_key
        self.stats = FaultStats()
        self._held: tuple[bytes, tuple] | None = None
        self._held_timer: asyncio.TimerHandle | None = None
        self.set_faults(faults)

    def set_faults(self, faults: LinkFaults) -> None:
        """Replace the faults; the generator restarts from the new seed."""
        self.faults = faults
        self._clean = faults.clean
        self._rng = np.random.default_rng([faults.seed, *self._seed_key])

    def send(self, data: bytes, addr: tuple) -> None:
        self.stats.offered += 1
        if self._clean:
            self.stats.delivered += 1
            self._deliver(data, addr)
            return
        f = self.faults
        draws = self._rng.random(5)
        if draws[0] < f.loss:
            self.stats.dropped += 1
            return
        copies = 1
        if draws[1] < f.duplicate:
            copies = 2
            self.stats.duplicated += 1
        for k in range(copies):
            delay_s = f.delay_s + f.jitter_s * draws[2 + k]
            reorder = draws[4] < f.reorder and k == 0
            if delay_s > 0.0:
                asyncio.get_running_loop().call_later(delay_s, self._reorder_stage, data, addr, reorder)
            else:
                self._reorder_stage(data, addr, reorder)

    def _reorder_stage(self, data: bytes, addr: tuple, reorder: bool) -> None:
        if reorder and self._held is None:
            self.stats.reordered += 1
            self._held = (data, addr)
            self._held_timer = asyncio.get_running_loop().call_later(REORDER_HOLD_S, self._release)
            return
        self._emit(data, addr)
        self._release()

    def _release(self) -> None:
        if self._held is None:
            return
        data, addr = self._held
        self._held = None
        if self._held_timer is not None:
            self._held_timer.cancel()
            self._held_timer = None
        self._emit(data, addr)

    def _emit(self, data: bytes, addr: tuple) -> None:
        self.stats.delivered += 1
        self._deliver(data, addr)
