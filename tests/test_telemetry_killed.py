"""A logger SIGKILLed mid-flight leaves a file readable up to its last flush, by our reader and by the
stock mcap reader (what Foxglove-side tools use)."""

from __future__ import annotations

import io
import json
import os
import signal
import sys
import time
from pathlib import Path

import pytest
from child_process import child, group_alive
from mcap.reader import NonSeekingReader, make_reader

from gcs_planner.telemetry import read_flight

WRITER = r"""
import os, sys, time
os.environ["MAVLINK20"] = "1"
from pymavlink.dialects.v20 import ardupilotmega as mavlink
from gcs_planner.core.geo import Origin
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


def _killed_log(path: Path, kill_after_bytes: int = 20_000, then_s: float = 0.12) -> None:
    """Run WRITER into ``path`` and SIGKILL it once the file has ``kill_after_bytes``, a flush of
    over 300 messages reads back, and ``then_s`` more have passed (the writer is then somewhere
    inside its next chunk). The size alone is not enough: a flush writes its new end first, so the
    file has its full size before the chunk behind it is whole (and a reader sees no messages)."""
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}

    def ready() -> bool:
        if not path.exists() or path.stat().st_size < kill_after_bytes:
            return False
        return read_flight(path).recovered_messages > 300

    with child([sys.executable, "-c", WRITER, str(path)], env=env) as proc:
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and not ready():
            assert proc.poll() is None, "the writer died by itself"
            time.sleep(0.05)
        time.sleep(then_s)
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    assert proc.returncode == -signal.SIGKILL and not group_alive(proc.pid)


def _stock_messages(path: Path) -> list[tuple[str, int, bytes]]:
    """(topic, log time, data) of every message, read by the stock mcap reader as Foxglove tools do."""
    with open(path, "rb") as f:
        return [(c.topic, m.log_time, m.data) for _, c, m in make_reader(f).iter_messages()]


@pytest.mark.timeout(60)
def test_sigkilled_writer_leaves_readable_prefix(tmp_path: Path):
    path = tmp_path / "killed.mcap"
    _killed_log(path)
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


@pytest.mark.timeout(120)
@pytest.mark.parametrize("kill", range(5))
def test_sigkilled_log_reads_with_the_stock_mcap_reader(tmp_path: Path, kill: int):
    """Killed at five points of its flush cycle, the log opens with ``make_reader(f).iter_messages()``
    (a seekable file: the seeking reader finds the provisional footer, no summary, and reads
    linearly) and with the stream reader on a pipe-like stream, and both give exactly what our
    reader recovered: an intact prefix of the flight."""
    path = tmp_path / "killed.mcap"
    _killed_log(path, kill_after_bytes=20_000 + 7_000 * kill, then_s=0.011 * kill)
    flight = read_flight(path)
    assert flight.truncated and flight.error is None  # ended on a provisional end, not a cut record
    stock = _stock_messages(path)
    assert len(stock) == flight.recovered_messages > 300
    with open(path, "rb") as f:
        assert make_reader(f).get_summary() is None
    unseekable = io.BufferedReader(io.BytesIO(path.read_bytes()))
    unseekable.seekable = lambda: False
    streamed = [(c.topic, m.log_time, m.data) for _, c, m in NonSeekingReader(unseekable).iter_messages()]
    assert sorted(streamed) == sorted(stock)
    # the same frames as our reader, all intact: raw + decoded JSON + LocationFix per frame, k = 0..n-1
    raw = sorted((t, d) for topic, t, d in stock if topic.endswith("/raw"))
    assert raw == sorted((f.t_ns, f.data) for f in flight.frames)
    gpi = [json.loads(d) for topic, _, d in stock if topic.endswith("/GLOBAL_POSITION_INT")]
    assert sorted(m["time_boot_ms"] for m in gpi) == list(range(len(raw)))
    fixes = [topic for topic, _, _ in stock if topic.endswith("/location")]
    assert len(fixes) == len(gpi) == len(raw)


def test_log_is_valid_mcap_after_every_write_the_writer_makes(tmp_path: Path):
    """Deterministic form of the kill test: the file's state after each single write() of the
    writer (a SIGKILL can only land between two of them) is read by the stock reader without error,
    and holds ever more messages, up to all of them at close."""
    from telemetry_frames import ORIGIN, flight_frames

    from gcs_planner.telemetry import FlightLogger

    class Recording(io.BytesIO):
        def __init__(self) -> None:
            super().__init__()
            self.states: list[bytes] = []

        def write(self, data) -> int:
            n = super().write(data)
            self.states.append(self.getvalue())
            return n

    frames = flight_frames([1, 2], samples=30)
    stream = Recording()
    with FlightLogger(stream, ORIGIN, flush_interval_s=3600.0) as logger:  # flushed by the test only
        for i, (msg, raw, t_s) in enumerate(frames):
            logger.on_frame(msg, raw, t_s)
            if i % 20 == 19:
                logger.flush()
    assert len(stream.states) >= 2 * (len(frames) // 20)  # two writes per flush, none in between
    counts, raws = [], []
    for state in stream.states:
        messages = list(make_reader(io.BytesIO(state)).iter_messages())  # must not raise
        counts.append(len(messages))
        raw = [m.data for _, c, m in messages if c.topic.endswith("/raw")]
        assert sorted(raw) == sorted(r for _, r, _ in frames[: len(raw)])
        raws.append(len(raw))
    assert counts == sorted(counts) and raws[-1] == len(frames)
    assert len(set(raws)) >= len(frames) // 20  # each flush added frames the stock reader saw
    final = read_flight_bytes(tmp_path, stream.states[-1])
    assert not final.truncated and final.recovered_messages == counts[-1]
    assert read_flight_bytes(tmp_path, stream.states[-2]).truncated  # a provisional end: not closed


def read_flight_bytes(tmp_path: Path, data: bytes):
    path = tmp_path / "state.mcap"
    path.write_bytes(data)
    return read_flight(path)


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
