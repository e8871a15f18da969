"""MAVLink 2 signing state as the spec and the C library keep it: one clock, one replay table per link.

https://mavlink.io/en/guide/message_signing.html and mavlink's C ``mavlink_helpers.h``
(``mavlink_sign_packet``, ``mavlink_signature_check``), which ArduPilot (``GCS_Signing.cpp``, one
``signing_streams`` table shared by every channel) and PX4 (``mavlink_sign_control.cpp``,
``global_mavlink_signing_streams``) both use:

- :class:`SigningClock`: the timestamp a frame is sent with, in 10 us units since 2015-01-01 UTC.
  It follows the wall clock (ArduPilot: ``update_signing_timestamp`` from GPS time), never goes
  backwards, advances at least 1 per frame (``mavlink_sign_packet``: ``timestamp++``) and is
  raised to any timestamp a verified frame carried (``mavlink_signature_check``: "our next
  timestamp must be at least this timestamp").
- :class:`SignatureVerifier`: the signature is checked first; only a frame whose signature is right
  may touch the state. Then the timestamp must be newer than the last one of its stream
  (link id, system id, component id), whichever address the frame came from; a new stream is
  accepted if its timestamp is at most one minute behind the local clock. A frame failing either
  check changes nothing, so a forged frame with timestamp 2^48-1 locks nobody out.

pymavlink's ``MAVLink.check_signature`` records the timestamp before it checks the signature and
keeps its table per parser object (we had one per source address): both let an attacker in or lock
the operator out, so we verify here and give pymavlink only keyless decoding.
"""

from __future__ import annotations

import hashlib
import time
from collections.abc import Callable

__all__ = ["NEW_STREAM_WINDOW", "SignatureVerifier", "SigningClock", "signature_fields", "signing_timestamp"]

EPOCH_2015_S = 1_420_070_400  # 2015-01-01T00:00:00Z, the signing timestamp's origin
NEW_STREAM_WINDOW = 6_000_000  # 60 s in 10 us units: how far behind a new stream may start
_SIGNED = 0x01
_SIGNATURE_LEN = 13


def signing_timestamp(now_s: float | None = None) -> int:
    """Signing timestamp for Unix time ``now_s`` [10 us units since 2015-01-01]."""
    return max(0, int(((time.time() if now_s is None else now_s) - EPOCH_2015_S) * 100_000))


def signature_fields(frame: bytes) -> tuple[int, int, bytes] | None:
    """(link id, timestamp, 6-byte signature) of a signed MAVLink 2 frame; None if it is not one."""
    if len(frame) < 12 + _SIGNATURE_LEN or frame[0] != 0xFD or not frame[2] & _SIGNED:
        return None
    block = frame[-_SIGNATURE_LEN:]
    return block[0], int.from_bytes(block[1:7], "little"), bytes(block[7:])


class SigningClock:
    """The local signing timestamp (see module docstring); ``now_s`` is injectable for tests."""

    def __init__(self, now_s: Callable[[], float] = time.time) -> None:
        self._now_s = now_s
        self._last = 0

    def current(self) -> int:
        """The local timestamp now, without using one up (new-stream checks)."""
        return max(self._last, signing_timestamp(self._now_s()))

    def next(self) -> int:
        """The timestamp of the next frame sent: > every earlier one, >= the wall clock."""
        self._last = max(self._last + 1, signing_timestamp(self._now_s()))
        return self._last

    def observe(self, timestamp: int) -> None:
        """A verified frame carried ``timestamp``: never send below it."""
        self._last = max(self._last, timestamp)


class SignatureVerifier:
    """Signature and replay check of one link's received frames, shared by all its peers' addresses."""

    def __init__(self, key: bytes, clock: SigningClock) -> None:
        self.key = key
        self.clock = clock
        self.streams: dict[tuple[int, int, int], int] = {}  # (link id, sysid, compid) -> last timestamp
        self.replayed = 0  # right signature, timestamp not newer than the stream's (or too old)
        self.forged = 0  # unsigned or wrong signature

    def accept(self, frame: bytes) -> bool:
        """True when ``frame`` is signed with the key and newer than its stream; only then is the
        stream's timestamp (and the local clock) moved on."""
        fields = signature_fields(frame)
        if fields is None:
            self.forged += 1
            return False
        link_id, timestamp, signature = fields
        if hashlib.sha256(self.key + frame[:-6]).digest()[:6] != signature:
            self.forged += 1
            return False
        stream = (link_id, frame[5], frame[6])
        last = self.streams.get(stream)
        if last is not None and timestamp <= last:
            self.replayed += 1
            return False
        if last is None and timestamp + NEW_STREAM_WINDOW < self.clock.current():
            self.replayed += 1
            return False
        self.streams[stream] = timestamp
        self.clock.observe(timestamp)
        return True
