"""codec.py must agree with pymavlink on every message of the dialect it covers, byte for byte."""

from __future__ import annotations

import asyncio
import os
import socket
import tracemalloc

import numpy as np
import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

from gcs_planner.mavlink.link import MavlinkLink  # noqa: E402
from gcs_planner.wire import codec  # noqa: E402
from gcs_planner.wire.signing import LinkSigning  # noqa: E402
from gcs_planner.wire.signing_streams import signature_fields  # noqa: E402

_RANGES = {
    "uint8_t": (0, 2**8),
    "int8_t": (-(2**7), 2**7),
    "uint16_t": (0, 2**16),
    "int16_t": (-(2**15), 2**15),
    "uint32_t": (0, 2**32),
    "int32_t": (-(2**31), 2**31),
    "uint64_t": (0, 2**63),
    "int64_t": (-(2**63), 2**63),
}
COVERED = [c for c in mavlink.mavlink_map.values() if codec._covered(c)]


def sample(cls: type[mavlink.MAVLink_message], rng: np.random.Generator, zeros: bool = False):
    """An instance with random values, or with its trailing wire fields zero (truncated payload)."""
    values = []
    for kind in cls.fieldtypes:
        if kind in ("float", "double"):
            values.append(float(np.float32(rng.normal(0, 1e3))))
        else:
            low, high = _RANGES[kind]
            values.append(int(rng.integers(low, high)))
    msg = cls(*values)
    if zeros:
        for name in cls.ordered_fieldnames[len(cls.ordered_fieldnames) // 2 :]:
            setattr(msg, name, 0)
    return msg


def test_most_of_the_dialect_is_covered_and_strings_and_arrays_are_not():
    assert len(COVERED) > 150
    assert mavlink.MAVLink_mission_item_int_message in COVERED
    assert mavlink.MAVLink_mission_request_int_message in COVERED
    assert mavlink.MAVLink_statustext_message not in COVERED  # char[50]
    assert mavlink.MAVLink_param_set_message not in COVERED  # char[16]


@pytest.mark.parametrize("zeros", [False, True])
def test_every_covered_message_encodes_and_decodes_as_pymavlink_does(zeros):
    rng = np.random.default_rng(1)
    ours = mavlink.MAVLink(None, srcSystem=42, srcComponent=7)
    theirs = mavlink.MAVLink(None, srcSystem=42, srcComponent=7)
    for cls in COVERED:
        msg = sample(cls, rng, zeros)
        ours.seq = theirs.seq = int(rng.integers(0, 256))
        frame = codec.encode(msg, ours)
        expected = msg.pack(theirs)
        assert frame == expected, cls.msgname
        got, want = codec.decode(frame), theirs.decode(bytearray(frame))
        assert type(got) is type(want)
        assert got.to_dict() == want.to_dict(), cls.msgname
        assert got.get_header().__dict__ == want.get_header().__dict__
        assert (got.get_crc(), bytes(got.get_msgbuf()), bytes(got.get_payload())) == (
            want.get_crc(),
            bytes(want.get_msgbuf()),
            bytes(want.get_payload()),
        )


@pytest.mark.parametrize("zeros", [False, True])
def test_a_payload_packed_once_frames_as_pymavlink_packs_the_message(zeros):
    """packer + frame (the upload's path without message objects) = pymavlink's pack, byte for byte;
    signed with LinkSigning.sign = pymavlink's signed pack at the same timestamp; intact and
    fields read them back."""
    rng = np.random.default_rng(2)
    theirs = mavlink.MAVLink(None, srcSystem=42, srcComponent=7)
    signed = mavlink.MAVLink(None, srcSystem=42, srcComponent=7)
    signing = LinkSigning(mavlink.MAVLink(None), b"k" * 32, link_id=3)
    LinkSigning(signed, b"k" * 32, link_id=3)
    for cls in COVERED:
        msg = sample(cls, rng, zeros)
        p = codec.packer(cls)
        payload = p.pack(*(getattr(msg, name) for name in cls.fieldnames))
        theirs.seq = signed.seq = seq = int(rng.integers(0, 256))
        frame = codec.frame(p.msgid, p.crc_extra, payload, seq, 42, 7)
        assert frame == msg.pack(theirs), cls.msgname
        assert codec.intact(frame) and codec.fields(frame, cls.unpacker) == cls.unpacker.unpack(
            cls.unpacker.pack(*(getattr(msg, name) for name in cls.ordered_fieldnames))
        )
        ours = signing.sign(
            codec.frame(p.msgid, p.crc_extra, payload, seq, 42, 7, mavlink.MAVLINK_IFLAG_SIGNED)
        )
        signed.signing.timestamp = signature_fields(ours)[1]  # the timestamp ``sign`` used
        assert ours == msg.pack(signed), cls.msgname
        assert codec.intact(ours)
    with pytest.raises(ValueError, match="not covered"):
        codec.packer(mavlink.MAVLink_statustext_message)


def test_intact_refuses_a_bad_crc_length_msgid_or_flag():
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    request = mavlink.MAVLink_mission_request_int_message
    frame = request(255, 190, 7, 2).pack(mav)
    assert codec.intact(frame) and codec.fields(frame, request.unpacker) == (7, 255, 190, 2)
    assert codec.fields(request(255, 190, 7, 0).pack(mav), request.unpacker) == (7, 255, 190, 0)  # cut zeros
    bad_crc = bytearray(frame)
    bad_crc[-3] ^= 0x01
    unknown_flag = bytearray(frame)
    unknown_flag[2] = 0x02
    unknown_id = bytearray(frame)
    unknown_id[9] = 0x7F
    for bad in (bad_crc, frame[:-1], frame + b"\x00", unknown_flag, unknown_id, b"\xfe" + frame[1:]):
        assert not codec.intact(bytes(bad))


def test_frames_it_does_not_cover_are_left_to_pymavlink():
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    text = mavlink.MAVLink_statustext_message(6, b"hello")
    assert codec.encode(text, mav) is None
    assert codec.decode(text.pack(mav)) is None
    mav.WIRE_PROTOCOL_VERSION = "1.0"
    v1 = mavlink.MAVLink_heartbeat_message(2, 3, 0, 0, 4, 3).pack(mav, force_mavlink1=True)
    assert codec.decode(v1) is None
    signed = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    LinkSigning(signed, b"k" * 32)
    beat = mavlink.MAVLink_heartbeat_message(2, 3, 0, 0, 4, 3)
    assert codec.encode(beat, signed) is None
    assert codec.decode(beat.pack(signed)) is None


def test_frames_of_unknown_message_ids_leave_no_memory_behind():
    """Junk frames may carry any of 2^24 message ids: decoding 50,000 unknown ones keeps nothing
    (a cache per id grew by ~4 MB)."""
    junk = [
        bytes([0xFD, 0, 0, 0, 0, 1, 1]) + (1_000_000 + k).to_bytes(3, "little") + b"\0\0"
        for k in range(50_000)
    ]
    codec.decode(junk[0])
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        assert all(codec.decode(f) is None for f in junk)
        assert tracemalloc.get_traced_memory()[0] - before < 100_000
    finally:
        tracemalloc.stop()


def test_bad_crc_and_bad_length_are_errors():
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    frame = bytearray(mavlink.MAVLink_mission_request_int_message(255, 190, 7, 0).pack(mav))
    frame[-3] ^= 0x01  # a payload bit
    with pytest.raises(mavlink.MAVError, match="CRC"):
        codec.decode(bytes(frame))
    with pytest.raises(mavlink.MAVError, match="length"):
        codec.decode(bytes(frame[:-1]))


def test_link_frames_carry_a_sequence_number_that_advances():
    async def main():
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as peer:
            peer.bind(("127.0.0.1", 0))
            peer.settimeout(2)
            link = await MavlinkLink.open(f"udpout:127.0.0.1:{peer.getsockname()[1]}", heartbeat_period_s=0)
            frames = []
            for seq in range(300):  # one at a time: 300 queued datagrams overflow a default buffer
                link.send(mavlink.MAVLink_mission_request_int_message(1, 1, seq, 0))
                frames.append(peer.recv(300))
            await link.close()
        assert [f[4] for f in frames] == [s % 256 for s in range(300)]
        parser = mavlink.MAVLink(None)
        assert [parser.decode(bytearray(f)).seq for f in frames] == list(range(300))

    asyncio.run(main())
