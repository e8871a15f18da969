"""The autopilot's verdict on a mission it has ACKed: some refuse a stored mission afterwards.

PX4 ACKs a complete upload, then its navigator checks the mission (FeasibilityChecker) and, when it
fails, says so only in a STATUSTEXT ("Mission rejected: takeoff not first waypoint item") and
refuses to start it. ``VerdictWatch`` is subscribed before the upload's first message (the text may
overtake the ACK) and, after the ACK, waits the autopilot's ``verdict_after_ack_s`` for such words.
"""

from __future__ import annotations

import asyncio
import contextlib

from gcs_planner.autopilots import AutopilotQuirks
from gcs_planner.mavlink.link import MavlinkLink
from gcs_planner.mavlink.statustext import TextAssembler

__all__ = ["VerdictWatch"]


class VerdictWatch:
    """Collects one vehicle's refusal texts from now on; ``rejection()`` is the autopilot's words or None."""

    def __init__(
        self, link: MavlinkLink, sysid: int, quirks: AutopilotQuirks, wait_s: float | None = None
    ) -> None:
        self.quirks = quirks
        self.wait_s = quirks.verdict_after_ack_s if wait_s is None else wait_s
        self._texts = TextAssembler()
        self._refused: asyncio.Future[str] = asyncio.get_running_loop().create_future()
        listen = self.wait_s > 0 and quirks.rejection_texts
        self._unsubscribe = link.subscribe(self._on_frame, sysid) if listen else None

    def _on_frame(self, msg, raw: bytes, t_s: float) -> None:
        if msg.get_type() != "STATUSTEXT" or self._refused.done():
            return
        text = self._texts.feed(msg)
        if text is not None and any(words in text.lower() for words in self.quirks.rejection_texts):
            self._refused.set_result(text)

    async def rejection(self) -> str | None:
        """Wait up to ``wait_s`` (default: the autopilot's verdict time) after the ACK; its refusal
        text, or None."""
        if self._unsubscribe is None:
            return None
        with contextlib.suppress(TimeoutError):
            return await asyncio.wait_for(asyncio.shield(self._refused), self.wait_s)
        return None

    def close(self) -> None:
        if self._unsubscribe is not None:
            self._unsubscribe()
