"""Cut received bytes into MAVLink frames without a parser that remembers anything.

UDP: each datagram is framed on its own (``frames(data)``; an incomplete tail is junk), so a
malformed datagram can never swallow the bytes of the next one. A datagram is what UDP delivers or
loses whole, and MAVLink senders put whole frames in one (MAVProxy, QGC, ArduPilot's own UDP
output). This is a choice, stricter than ArduPilot: ArduPilot feeds a UDP port's bytes into the
byte-stream parser of its channel (``GCS_MAVLINK::update_receive`` -> ``mavlink_parse_char``), so
there a cut frame costs the frames after it until the parser resynchronises.
Serial and TCP: a byte stream, so :class:`StreamFramer` keeps the incomplete tail for the next
read, and a candidate frame whose CRC fails (a stray start byte in line noise, whose "length"
swallowed the real frames after it) gives up only its start byte: the scan resumes at the next
byte, as pymavlink's robust parser does, so one noise byte costs no frame.

A frame is returned by its length fields only (MAVLink 2: 10-byte header + payload + CRC + 13 if
signed; MAVLink 1: 6 + payload + 2); the CRC, the message id and the signature are the decoder's
business. Bytes that do not start a frame are skipped up to the next start byte and counted once
per run, as pymavlink's robust parser counts them.
"""

from __future__ import annotations

from collections.abc import Callable

from gcs_planner.wire.codec import crc_fails

__all__ = ["StreamFramer", "frames"]

_V1, _V2 = 0xFE, 0xFD
_SIGNED = 0x01
_SIGNATURE_LEN = 13


def _frame_length(data: bytes | bytearray, i: int) -> int | None:
    """Length of the frame starting at ``data[i]`` (a start byte); None when the header is cut."""
    if data[i] == _V2:
        if i + 3 > len(data):
            return None
        return 12 + data[i + 1] + (_SIGNATURE_LEN if data[i + 2] & _SIGNED else 0)
    if i + 2 > len(data):
        return None
    return 8 + data[i + 1]


def split(
    data: bytes | bytearray, rejects: Callable[[bytes], bool] | None = None
) -> tuple[list[bytes], int, int]:
    """(whole frames, runs of junk skipped, offset where an incomplete frame starts or len(data));
    a frame ``rejects`` refuses gives up only its start byte (junk) and the scan goes on after it."""
    out: list[bytes] = []
    junk = 0
    i, n = 0, len(data)
    while i < n:
        if data[i] not in (_V1, _V2):
            junk += 1
            while i < n and data[i] not in (_V1, _V2):
                i += 1
            continue
        length = _frame_length(data, i)
        if length is None or i + length > n:
            return out, junk, i
        raw = bytes(data[i : i + length])
        if rejects is not None and rejects(raw):
            junk += 1
            i += 1
            continue
        out.append(raw)
        i += length
    return out, junk, n


def frames(datagram: bytes) -> tuple[list[bytes], int]:
    """The whole frames of one datagram and the number of junk pieces (a cut tail counts)."""
    if datagram and datagram[0] == _V2 and _frame_length(datagram, 0) == len(datagram):
        return [datagram], 0  # exactly one MAVLink 2 frame, as PX4 sends every message: no copy
    out, junk, end = split(datagram)
    return out, junk + (end < len(datagram))


class StreamFramer:
    """Frames of a byte stream (serial): the incomplete tail waits for the next read."""

    MAX_PENDING = 280  # longest MAVLink 2 frame (10 + 255 + 2 + 13): more than that is never a frame

    def __init__(self) -> None:
        self._pending = bytearray()

    def feed(self, data: bytes) -> tuple[list[bytes], int]:
        self._pending += data
        out, junk, end = split(self._pending, rejects=crc_fails)
        del self._pending[:end]
        if len(self._pending) > self.MAX_PENDING:  # cannot happen with the length fields above
            self._pending.clear()
            junk += 1
        return out, junk
