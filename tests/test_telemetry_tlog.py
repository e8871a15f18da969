"""import-tlog round trip with a .tlog written by pymavlink's own logger (mavutil setup_logfile)."""

from __future__ import annotations

import os
import socket
import struct
import time

from telemetry_frames import ORIGIN, flight_frames

from gcs_planner.cli import main
from gcs_planner.telemetry import read_flight, write_tlog

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402


def _pymavlink_tlog(path, frames) -> list[tuple[int, bytes]]:
    """Receive frames on a mavutil link that logs them (mavfile.setup_logfile); return (t_us, frame) rows.

    mavutil writes the tlog in the generic mavfile.recv_msg (serial, TCP); its UDP class does not
    log, so the frames come over a TCP connection from a local server socket.
    """
    with socket.create_server(("127.0.0.1", 0)) as server:
        conn = mavutil.mavlink_connection(f"tcp:127.0.0.1:{server.getsockname()[1]}", dialect="ardupilotmega")
        peer, _ = server.accept()
    conn.setup_logfile(str(path))
    with peer:
        for _, raw, _ in frames:
            peer.sendall(raw)
        deadline = time.monotonic() + 10
        received = 0
        while received < len(frames) and time.monotonic() < deadline:
            if conn.recv_match(blocking=True, timeout=0.5) is not None:
                received += 1
    conn.close()
    conn.logfile.close()
    data = path.read_bytes()
    rows, i = [], 0
    for _, raw, _ in frames:
        rows.append((struct.unpack(">Q", data[i : i + 8])[0], data[i + 8 : i + 8 + len(raw)]))
        i += 8 + len(raw)
    assert i == len(data)
    return rows


def test_import_tlog_round_trip(tmp_path):
    frames = flight_frames([1, 2], samples=12)
    tlog = tmp_path / "mavproxy.tlog"
    rows = _pymavlink_tlog(tlog, frames)
    assert [raw for _, raw in rows] == [raw for _, raw, _ in frames]

    mcap = tmp_path / "imported.mcap"
    assert main(["import-tlog", str(tlog), "-o", str(mcap)]) == 0
    flight = read_flight(mcap)
    assert not flight.truncated
    assert [f.data for f in flight.frames] == [raw for _, raw in rows]
    assert [(f.t_ns + 500) // 1000 for f in flight.frames] == [t_us for t_us, _ in rows]
    assert sorted(flight.positions) == [1, 2] and len(flight.positions[2]) == 12
    assert "STATUSTEXT" in flight.message_types()
    origin = flight.origin  # from the first GLOBAL_POSITION_INT: home = alt - relative_alt
    assert abs(origin.alt_m - (flight.positions[1].alt_m[0] - 30.0)) < 1e-6

    back = tmp_path / "back.tlog"
    assert write_tlog(flight.frames, back) == len(frames)
    assert back.read_bytes() == tlog.read_bytes()
    reader = mavutil.mavlink_connection(str(back), dialect="ardupilotmega")  # mavlogdump's reader
    again = [reader.recv_match() for _ in range(3)]
    assert [m.get_type() for m in again] == [m.get_type() for m, _, _ in frames[:3]]
    assert again[2]._timestamp == rows[2][0] * 1e-6


def test_import_missing_tlog_is_a_user_error(tmp_path, capsys):
    assert main(["import-tlog", str(tmp_path / "none.tlog")]) == 2
    assert "no such file" in capsys.readouterr().err


def test_a_tlog_from_boot_keeps_the_reports_before_the_fix_but_no_position_from_them(tmp_path):
    """ArduPilot's first position reports are at (0, 0) (GCS_MAVLINK::send_global_position_int):
    the imported log keeps every frame, and neither the origin nor the tracks come from those."""
    frames = flight_frames([1], samples=12, no_fix_first=3)
    tlog, mcap = tmp_path / "boot.tlog", tmp_path / "boot.mcap"
    _pymavlink_tlog(tlog, frames)
    assert main(["import-tlog", str(tlog), "-o", str(mcap)]) == 0
    flight = read_flight(mcap)
    assert [f.data for f in flight.frames] == [raw for _, raw, _ in frames]
    assert len(flight.positions[1]) == 9 and abs(flight.positions[1].lat_deg - ORIGIN.lat_deg).max() < 0.01
    first = next(m for m, _, _ in frames if m.get_type() == "GLOBAL_POSITION_INT" and m.lat)
    origin = flight.origin
    assert (origin.lat_deg, origin.lon_deg) == (first.lat * 1e-7, first.lon * 1e-7)
    assert abs(origin.alt_m - ORIGIN.alt_m) < 0.01
