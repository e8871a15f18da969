"""One clock for a flight against mock vehicles run in this process: an event loop on virtual time.

ArduPilot SITL and PX4 lockstep with their simulators: the simulator steps only when the
controller has consumed the last step, so a run is the same however busy the machine is. Here the
GCS and the mock fleet (sitl_mock) share one asyncio loop whose clock is virtual: when every task
waits on a timer and no socket has anything to read or write, the clock jumps to the next timer
instead of sleeping. Time never passes while there is work: a datagram on loopback is in the
receiver's socket before ``sendto`` returns, and work handed to a thread (``asyncio.to_thread``:
the coalition planner) is done at once in the loop's own thread, so the clock stands still while
it works, as a simulator waits for its controller. The cost: nothing outside this process can
take part (real vehicles and a mock in another process run on the wall clock,
``run(..., lockstep=False)``), planning does not overlap the fleet on a second core, and a run
is as fast as the CPU allows, not paced: a live viewer sees it at that rate.

Code on a flight's path reads time from its loop (``now_s``), never ``time.monotonic()``; the
Unix time it logs is ``unix_s``: the loop's start plus its virtual time.
"""

from __future__ import annotations

import asyncio
import gc
import os
import selectors
import time
from collections.abc import Callable, Coroutine
from typing import Any, TypeVar

__all__ = ["LockstepLoop", "check_loop", "now_s", "run", "unix_s"]

T = TypeVar("T")

GC_THRESHOLD = 10_000  # allocations between first-generation collections during a run (CPython: 700)
LOOP_START_S = 1000.0  # the virtual clock's first reading (not 0: nothing may read it as "unset")


class _IdleJumps:
    """The loop's selector: it reports ready sockets at once, and when nothing is ready it moves
    the virtual clock to the timer the loop would have slept until, instead of sleeping."""

    def __init__(self, selector: selectors.BaseSelector, loop: LockstepLoop) -> None:
        self._selector, self._loop = selector, loop

    def select(self, timeout: float | None = None) -> list:
        events = self._selector.select(0)
        if events or timeout == 0:
            return events
        os.sched_yield()  # a busy kernel may leave loopback delivery to ksoftirqd: let it run first
        events = self._selector.select(0)
        if events:
            return events
        if timeout is None:  # no timer at all: only outside I/O (a signal) can wake the loop
            return self._selector.select(None)
        self._loop.advance(timeout)
        return []

    def __getattr__(self, name: str) -> Any:  # register, unregister, modify, get_map, close, ...
        return getattr(self._selector, name)


class LockstepLoop(asyncio.SelectorEventLoop):
    """A selector event loop whose ``time()`` is virtual and advances only while it is idle."""

    def __init__(self) -> None:
        super().__init__(_IdleJumps(selectors.DefaultSelector(), self))
        self._virtual_s = LOOP_START_S
        self._unix_start_s = time.time()
        self._clock_resolution = 1e-6  # a jump lands on its timer: rounding must not leave it due later

    def time(self) -> float:
        return self._virtual_s

    def unix_time(self) -> float:
        """Unix time of this run: the loop's start plus the virtual time since."""
        return self._unix_start_s + (self._virtual_s - LOOP_START_S)

    def advance(self, seconds: float) -> None:
        self._virtual_s += max(0.0, seconds)

    def run_in_executor(self, executor: Any, func: Callable[..., T], *args: Any) -> asyncio.Future[T]:
        """Runs ``func`` at once in this thread (``asyncio.to_thread`` too): the clock stands still
        while it works, as a simulator waits for its controller, and results come back in the
        order they were asked for, not in the order a pool's threads happen to finish."""
        future = self.create_future()
        try:
            future.set_result(func(*args))
        except Exception as exc:  # noqa: BLE001 - handed to the awaiting task, as a pool would
            future.set_exception(exc)
        return future


def run(main: Coroutine[Any, Any, T], lockstep: bool) -> T:
    """``asyncio.run(main)``, on a LockstepLoop when ``lockstep`` (every vehicle in this process).

    A flight makes ~10^4 short-lived message objects per second of wall time beside tracks that
    only grow; CPython's collector at its default first threshold (700) then walks those tracks
    over and over, so the run raises it (docs/results/lockstep.md: 18.4x -> 20.6x real time)."""
    thresholds = gc.get_threshold()
    gc.set_threshold(GC_THRESHOLD, *thresholds[1:])
    try:
        with asyncio.Runner(loop_factory=LockstepLoop if lockstep else None) as runner:
            return runner.run(main)
    finally:
        gc.set_threshold(*thresholds)


def check_loop(lockstep: bool) -> None:
    """Vehicles in lockstep need a LockstepLoop, and only they may have one (on it, the clock
    would run ahead of vehicles outside this process)."""
    on_lockstep = isinstance(asyncio.get_running_loop(), LockstepLoop)
    if lockstep != on_lockstep:
        need = (
            "on a LockstepLoop: gcs_planner.core.lockstep.run(..., lockstep=True)"
            if lockstep
            else ("on the wall clock: gcs_planner.core.lockstep.run(..., lockstep=False)")
        )
        raise RuntimeError(f"these vehicles fly {need}")


def now_s() -> float:
    """The running loop's clock [s]: virtual under lockstep, else (and outside a loop)
    time.monotonic()."""
    try:
        return asyncio.get_running_loop().time()
    except RuntimeError:
        return time.monotonic()


def unix_s() -> float:
    """Unix time [s] as this run sees it: the LockstepLoop's under lockstep, else time.time()."""
    try:
        loop = asyncio.get_running_loop()
    except RuntimeError:
        return time.time()
    return loop.unix_time() if isinstance(loop, LockstepLoop) else time.time()
