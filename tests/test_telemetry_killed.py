"""A logger SIGKILLed mid-flight leaves a file readable up to its last complete chunk."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from gcs_planner.telemetry import read_flight

WRITER = r"""
import os, sys, time
os.environ["MAVLINK20"] = "1"
from pymavlink.dialects.v20 import ardupilotmega as mavlink
from gcs_planner.geo import Origin
from gcs_planner.telemetry import FlightLogger

mav = {s: mavlink.MAVLink(None, srcSystem=s, srcComponent=1) for s in (1, 2)}
logger = FlightLogger(sys.argv[1], Origin(47.0, 8.0, 400.0), flush_interval_s=0.05)
k = 0
while True:  # until SIGKILL: frame k of vehicle 1 + (k % 2) carries time_boot_ms = k
    s = 1 + k % 2
    msg = mavlink.MAVLink_global_position_int_message(k, 470000000 + k, 80000000, 430000, 30000, 0, 0, 0, 0)
    logger.on_frame(msg, bytes(msg.pack(mav[s])), time.time())
    k += 1
    if k % 200 == 0:
        time.sleep(0.01)
"""


@pytest.mark.timeout(60)
def test_sigkilled_writer_leaves_readable_prefix(tmp_path: Path):
    path = tmp_path / "killed.mcap"
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    proc = subprocess.Popen([sys.executable, "-c", WRITER, str(path)], env=env)
    try:
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and (not path.exists() or path.stat().st_size < 20_000):
            time.sleep(0.05)
        time.sleep(0.12)  # let the writer be somewhere inside its next chunk
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    assert proc.returncode == -signal.SIGKILL
    flight = read_flight(path)  # must not raise
    assert flight.truncated
    assert flight.recovered_messages > 0
    frames = len(flight.frames)
    assert frames > 100
    # every recovered frame is intact and the recovered frames are exactly a prefix 0..n-1
    boot_ms = sorted(int(fields["time_boot_ms"]) for _, _, fields in flight.messages("GLOBAL_POSITION_INT"))
    assert boot_ms == list(range(frames))
    assert sorted(flight.positions) == [1, 2]
    assert len(flight.positions[1]) + len(flight.positions[2]) == frames
    # raw frame + JSON + LocationFix per frame, nothing else after the header
    assert flight.recovered_messages == 3 * frames


def test_file_cut_at_any_byte_reads_without_error(tmp_path: Path):
    from telemetry_frames import ORIGIN, flight_frames

    from gcs_planner.telemetry import FlightLogger

    path = tmp_path / "full.mcap"
    frames = flight_frames([1, 2], samples=30)
    with FlightLogger(path, ORIGIN) as logger:
        for i, (msg, raw, t_s) in enumerate(frames):
            logger.on_frame(msg, raw, t_s)
            if i % 20 == 19:
                logger.flush()  # several chunks
    data = path.read_bytes()
    previous = -1
    cuts = [*range(0, len(data), max(1, len(data) // 97)), *(len(data) - k for k in (9, 8, 4, 1))]
    for cut in cuts:  # including cuts inside the footer and the closing magic
        (tmp_path / "cut.mcap").write_bytes(data[:cut])
        flight = read_flight(tmp_path / "cut.mcap")
        assert flight.truncated
        assert flight.recovered_messages >= previous  # more bytes never lose messages
        previous = flight.recovered_messages
        assert [f.data for f in flight.frames] == [raw for _, raw, _ in frames[: len(flight.frames)]]
