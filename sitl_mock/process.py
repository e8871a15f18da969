"""A MockFleet in its own process, for GCS code that must not share a core (and the GIL) with it.

In the GCS's process the fleet's thread shares the GIL, so simulation, telemetry parsing, planning
and uploads all run on one core: a benchmark then measures the mock as much as the client, and at
speed-up 20 a coalition HIL run with 26 vehicles saturated that core. ``MockFleetProcess`` takes
MockFleet's keyword arguments, starts the fleet under the ``spawn`` start method and exposes its
addresses and, after exit, its lag count.
"""

from __future__ import annotations

import multiprocessing
import signal

__all__ = ["MockFleetProcess"]

START_TIMEOUT_S = 30.0  # the child must be serving within this [s]


def _serve(conn, kwargs: dict) -> None:
    """Child process: run a MockFleet, send its addresses, apply the fault calls it is sent
    ((method name, args)) until told to stop, send its lag count."""
    from sitl_mock.fleet import MockFleet

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the parent, which stops us
    with MockFleet(**kwargs) as fleet:
        conn.send(fleet.addresses)
        while (message := conn.recv()) != "stop":
            name, args = message
            getattr(fleet, name)(*args)
        lag = fleet.lag_events
    conn.send(lag)


class MockFleetProcess:
    """``with MockFleetProcess(count=3, profile="px4") as fleet: fleet.addresses``."""

    def __init__(self, **kwargs) -> None:
        self.kwargs = kwargs
        self.addresses: list[tuple[str, int]] = []
        self.lag_events = 0

    def __enter__(self) -> MockFleetProcess:
        ctx = multiprocessing.get_context("spawn")
        self._conn, child = ctx.Pipe()
        self._proc = ctx.Process(target=_serve, args=(child, self.kwargs), daemon=True)
        self._proc.start()
        if not self._conn.poll(START_TIMEOUT_S):
            self._proc.terminate()
            raise TimeoutError(f"the mock fleet process did not start within {START_TIMEOUT_S:g} s")
        self.addresses = self._conn.recv()
        return self

    def set_faults(self, sysid: int | None, faults) -> None:
        """MockFleet.set_faults in the child process."""
        self._conn.send(("set_faults", (sysid, faults)))

    def set_drift(self, sysid: int | None, east_mps: float, north_mps: float) -> None:
        """MockFleet.set_drift in the child process."""
        self._conn.send(("set_drift", (sysid, east_mps, north_mps)))

    def __exit__(self, *exc: object) -> None:
        try:
            self._conn.send("stop")
            if self._conn.poll(10.0):
                self.lag_events = int(self._conn.recv())
        except (BrokenPipeError, EOFError):
            pass
        self._proc.join(10.0)
        if self._proc.is_alive():
            self._proc.terminate()
