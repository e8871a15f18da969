"""Is each vehicle's clock running at the rate the flight assumes? A mock started at another
``--speedup`` (or a SITL run faster than real time) flies every schedule at the wrong rate.

``ClockRate`` watches the ``time_boot_ms`` of each vehicle's GLOBAL_POSITION_INT against the receive
time; ``check`` refuses a vehicle whose clock runs more than ``RATE_TOLERANCE`` off the expected rate.
"""

from __future__ import annotations

from gcs_planner.core.errors import UserError

__all__ = ["MIN_SPAN_S", "RATE_TOLERANCE", "ClockRate"]

MIN_SPAN_S = 1.0  # receive time to measure a rate over [s]
RATE_TOLERANCE = 0.2  # relative: link jitter over MIN_SPAN_S stays well inside it


class ClockRate:
    """First and newest (receive time, vehicle time) per vehicle, from ``on_frame``."""

    def __init__(self, sysids) -> None:
        self.first: dict[int, tuple[float, float]] = {}
        self.last: dict[int, tuple[float, float]] = {}
        self.sysids = set(sysids)

    def on_frame(self, msg, raw: bytes, t_s: float) -> None:
        sysid = msg.get_srcSystem()
        if sysid in self.sysids and msg.get_type() == "GLOBAL_POSITION_INT":
            sample = (t_s, msg.time_boot_ms / 1000.0)
            self.first.setdefault(sysid, sample)
            self.last[sysid] = sample

    def span_s(self, sysid: int) -> float:
        return self.last[sysid][0] - self.first[sysid][0] if sysid in self.last else 0.0

    def rate(self, sysid: int) -> float | None:
        """Vehicle seconds per received second, None before MIN_SPAN_S of reports."""
        if self.span_s(sysid) < MIN_SPAN_S:
            return None
        (t0, b0), (t1, b1) = self.first[sysid], self.last[sysid]
        return (b1 - b0) / (t1 - t0)

    def check(self, expected: float) -> None:
        """UserError naming every vehicle whose clock runs off ``expected`` (x real time)."""
        off = []
        for sysid in sorted(self.sysids):
            rate = self.rate(sysid)
            if rate is not None and not abs(rate / expected - 1.0) <= RATE_TOLERANCE:
                off.append(f"sysid {sysid} runs at {rate:.2f}x")
        if off:
            raise UserError(
                f"vehicle clocks do not run at the flight's {expected:g}x real time: {', '.join(off)}"
                " (a mock or SITL started with another --speedup? restart it at 1x)"
            )
