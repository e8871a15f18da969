"""SIGINT, SIGTERM and SIGHUP end a flight safely: the vehicles are sent home, the log keeps
running until they land, then the report is written.

A service manager or a CI runner stops a process with SIGTERM, a closed terminal sends SIGHUP:
each must bring the fleet home as Ctrl-C does. The first signal cancels the flight's task (its
failure path sends every airborne vehicle home); a second one stops the wait for the landings
(the report is still written); a third ends the process at once.
"""

from __future__ import annotations

import asyncio
import contextlib
import signal
import threading

__all__ = ["SAFE_END_SIGNALS", "SafeEndSignals"]

SAFE_END_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


class SafeEndSignals:
    """Installed around a flight in the running loop (main thread only; elsewhere it does nothing)."""

    def __init__(self) -> None:
        self.received: signal.Signals | None = None
        self.hurry = asyncio.Event()  # set by a second signal: stop waiting for the vehicles
        self._installed: list[signal.Signals] = []

    def __enter__(self) -> SafeEndSignals:
        if threading.current_thread() is not threading.main_thread():
            return self
        loop, task = asyncio.get_running_loop(), asyncio.current_task()
        for sig in SAFE_END_SIGNALS:
            with contextlib.suppress(ValueError, RuntimeError, NotImplementedError):
                loop.add_signal_handler(sig, self._on_signal, sig, task)
                self._installed.append(sig)
        return self

    def _on_signal(self, sig: signal.Signals, task: asyncio.Task | None) -> None:
        if self.received is None:
            self.received = sig
            if task is not None:
                task.cancel()
        elif not self.hurry.is_set():
            self.hurry.set()
        else:
            raise KeyboardInterrupt

    def __exit__(self, *exc: object) -> None:
        loop = asyncio.get_running_loop()
        for sig in self._installed:
            loop.remove_signal_handler(sig)
        self._installed.clear()
