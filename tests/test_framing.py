"""Datagrams and byte streams cut into MAVLink frames (wire/framing.py), frames packed by pymavlink."""

from __future__ import annotations

import pytest
from pymavlink.dialects.v10 import ardupilotmega as mavlink1
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs_planner.wire.framing import StreamFramer, frames


def _v2(seq: int = 0, key: bytes | None = None) -> bytes:
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    mav.seq = seq
    if key is not None:
        mav.signing.secret_key, mav.signing.sign_outgoing = key, True
    return mavlink.MAVLink_mission_request_int_message(255, 190, seq, 0).pack(mav)


V2, V2_NEXT, SIGNED = _v2(0), _v2(1), _v2(2, key=bytes(32))
V1 = mavlink1.MAVLink_heartbeat_message(2, 3, 0, 0, 4, 3).pack(mavlink1.MAVLink(None, 1, 1))


@pytest.mark.parametrize(
    ("datagram", "whole", "junk"),
    [
        (V2, [V2], 0),  # one frame, as PX4 sends every message
        (SIGNED, [SIGNED], 0),
        (V1, [V1], 0),
        (V2 + V2_NEXT, [V2, V2_NEXT], 0),  # several, as ArduPilot and our corked replies send them
        (V2 + b"\x00", [V2], 1),  # one byte more than the frame's length says
        (V2[:-1], [], 1),  # one byte short: a cut frame is junk, never half delivered
        (V2 + V2_NEXT[:5], [V2], 1),  # a cut tail
        (b"\x00\x01" + V2, [V2], 1),  # junk before a frame: one run
        (SIGNED[:-13], [], 1),  # the signed flag without its signature
        (b"", [], 0),
    ],
)
def test_a_datagram_is_cut_into_its_whole_frames_and_counted_junk(datagram, whole, junk):
    assert frames(datagram) == (whole, junk)


def test_a_stream_keeps_a_frame_cut_between_reads_for_the_next():
    framer = StreamFramer()
    assert framer.feed(V2 + V2_NEXT[:7]) == ([V2], 0)
    assert framer.feed(V2_NEXT[7:] + SIGNED) == ([V2_NEXT, SIGNED], 0)


def _unknown_id() -> bytes:
    """A MAVLink 2 frame of a message id no dialect has: its CRC cannot be checked, so it passes."""
    frame = bytearray(_v2(3))
    frame[7:10] = (0xFFFFF0).to_bytes(3, "little")
    return bytes(frame)


@pytest.mark.parametrize("chunk", [1, 7, 4096])
def test_a_stray_start_byte_in_a_stream_costs_no_frame(chunk):
    """Line noise of one 0xFD before each frame: its 'length' swallowed the real frame behind it,
    so no frame ever came through (a TCP peer, 2026-12-06). A start byte whose frame fails its CRC
    now gives up only itself and the scan resumes at the next byte, as pymavlink's parser does."""
    sent = [V2, V1, SIGNED, _unknown_id(), V2_NEXT]
    stream = b"".join(b"\xfd" + raw for raw in sent) + b"\xfe" + V2 + bytes(300)
    framer = StreamFramer()
    got, junk = [], 0
    for i in range(0, len(stream), chunk):
        out, skipped = framer.feed(stream[i : i + chunk])
        got += out
        junk += skipped
    assert got == [*sent, V2] and junk >= len(sent) + 1
