"""Damage inside a flight log (not a cut tail): a chunk whose bytes changed, a message at a time
no flight has. Found by flipping bits in a real `demo` log (2026-12-06): one flip in 40 crashed
`replay` (a log time past 2^63 ns), six replayed altered frames as if intact, and a frame dated
1970 made `--rrd` ask for 13 GiB and `--to` wait for decades.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink
from telemetry_frames import ORIGIN, FakeClock, flight_frames

from gcs_planner.cli import main
from gcs_planner.telemetry import FlightLogger
from gcs_planner.telemetry.reader import read_flight
from gcs_planner.telemetry.replay import MAX_GAP_S, long_gaps, paced

CHUNK = 0x06  # MCAP opcode


def _log(path: Path, frames, flush_every: int = 20) -> None:
    with FlightLogger(path, ORIGIN) as logger:
        for i, (msg, raw, t_s) in enumerate(frames):
            logger.on_frame(msg, raw, t_s)
            if i % flush_every == flush_every - 1:
                logger.flush()  # several chunks


def _records(data: bytes):
    """(offset, opcode, length) of each top-level record after the magic."""
    pos = 8
    while pos + 9 <= len(data) - 8:
        length = int.from_bytes(data[pos + 1 : pos + 9], "little")
        yield pos, data[pos], length
        pos += 9 + length


def test_a_chunk_whose_bytes_changed_is_left_out_and_the_rest_is_read(tmp_path):
    frames = flight_frames([1, 2], samples=40)
    path = tmp_path / "flight.mcap"
    _log(path, frames)
    data = bytearray(path.read_bytes())
    chunks = [(pos, length) for pos, op, length in _records(bytes(data)) if op == CHUNK]
    assert len(chunks) >= 3
    pos, length = chunks[1]
    data[pos + 9 + length - 5] ^= 0x10  # inside the second chunk's compressed records
    path.write_bytes(bytes(data))
    flight = read_flight(path)
    assert flight.damaged_chunks == 1
    originals = {raw for _, raw, _ in frames}
    assert all(f.data in originals for f in flight.frames)  # nothing altered gets through
    assert frames[-1][1] in {f.data for f in flight.frames}  # the chunks after it are read
    out = tmp_path / "out.rrd"
    assert main(["replay", str(path), "--rrd", str(out)]) == 0 and out.stat().st_size > 0


def test_messages_at_an_impossible_time_are_left_out(tmp_path, capsys):
    frames = flight_frames([1, 2], samples=40)
    position = next(f for f in frames if f[0].get_type() == "GLOBAL_POSITION_INT")
    damaged = [*frames[:50], (position[0], position[1], 1.0), *frames[50:], (position[0], position[1], 9.3e9)]
    path = tmp_path / "flight.mcap"
    _log(path, damaged)  # 1970, and past 2^63 ns
    flight = read_flight(path)
    assert flight.misplaced_messages == 4  # each frame's raw and JSON records
    assert [f.data for f in flight.frames] == [raw for _, raw, _ in frames]
    assert set(flight.positions) == {1, 2}
    ends, _ = flight.link_loss(1)
    assert len(ends) < 10  # one bin a second over the 4 s flight, not one for each second since 1970
    out = tmp_path / "out.rrd"
    assert main(["replay", str(path), "--rrd", str(out)]) == 0
    assert "4 messages at an impossible time left out" in capsys.readouterr().out


def test_a_position_past_a_pole_is_no_position(tmp_path):
    """A GLOBAL_POSITION_INT at the int32 extremes (+-214 deg, a valid frame all the same) is not
    on any track: a map or a conformance check would read it as a jump across the globe."""
    frames = flight_frames([1], samples=20)
    position = next(f for f in frames if f[0].get_type() == "GLOBAL_POSITION_INT")
    bogus = mavlink.MAVLink_global_position_int_message(0, 2**31 - 1, -(2**31), 0, 0, 0, 0, 0, 0)
    raw = bytes(bogus.pack(mavlink.MAVLink(None, srcSystem=1, srcComponent=1)))
    path = tmp_path / "flight.mcap"
    _log(
        path,
        [*frames[:5], (mavlink.MAVLink(None).decode(bytearray(raw)), raw, position[2] + 0.05), *frames[5:]],
    )
    track = read_flight(path).positions[1]
    assert len(track.t_s) == 20
    assert abs(track.lat_deg).max() < 90 and abs(track.lon_deg).max() < 180


def test_a_long_silence_is_cut_on_replay_and_said_so(tmp_path, capsys):
    """One frame three hours after the rest (within the log's 30 days, so kept): a paced replay
    waits MAX_GAP_S there, not three hours."""
    frames = flight_frames([1, 2], samples=40)
    text = frames[0]  # a STATUSTEXT: no time_boot_ms to move with it
    late = (text[0], text[1], frames[-1][2] + 3 * 3600.0)
    path = tmp_path / "flight.mcap"
    _log(path, [*frames, late])
    flight = read_flight(path)
    clock = FakeClock()
    sent = list(paced(flight, 1.0, sleep=clock.sleep, clock=clock))
    assert len(sent) == len(flight.vehicle_frames)
    assert sum(clock.sleeps) == pytest.approx(frames[-1][2] - frames[0][2] + MAX_GAP_S, abs=0.01)
    assert long_gaps(flight, 1.0) == [pytest.approx(3 * 3600.0, abs=0.01)]
    assert (
        main(["replay", str(path), "--to", "udpout:127.0.0.1:9", "--speed", "1000", "--max-gap", "0.2"]) == 0
    )
    assert "1 silences over 0.2 s cut to it (longest 11 s; --max-gap S)" in capsys.readouterr().out
