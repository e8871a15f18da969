"""Replay to MAVLink (pymavlink listener gets the recorded frames byte for byte) and to Rerun."""

from __future__ import annotations

import contextlib
import os
import socket
import threading
import time

import pytest
from telemetry_frames import ORIGIN, SCENARIO_TEXT, FakeClock, flight_frames, make_plan

from gcs_planner.cli import main
from gcs_planner.core.errors import UserError
from gcs_planner.telemetry import FlightLogger, read_flight, replay_to_mavlink
from gcs_planner.telemetry.replay import MAX_RATE_HZ, paced, parse_udp_url

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402


@pytest.fixture(scope="module")
def flight_path(tmp_path_factory):
    path = tmp_path_factory.mktemp("replay") / "flight.mcap"
    with FlightLogger(path, ORIGIN, plan=make_plan([1, 2, 3]), scenario_text=SCENARIO_TEXT) as logger:
        for msg, raw, t_s in flight_frames([1, 2, 3], samples=20):
            logger.on_frame(msg, raw, t_s)
        logger.log_event({"event": "start", "sysids": [1, 2, 3]}, t_s=t_s)
    return path


def _listen(conn, expected: int, out: list, timeout_s: float = 10.0) -> None:
    deadline = time.monotonic() + timeout_s
    while len(out) < expected and time.monotonic() < deadline:
        msg = conn.recv_match(blocking=True, timeout=0.2)
        if msg is not None and msg.get_type() != "BAD_DATA":
            out.append(bytes(msg.get_msgbuf()))


def test_replay_to_pymavlink_listener_is_byte_identical_and_timed(flight_path):
    flight = read_flight(flight_path)
    conn = mavutil.mavlink_connection("udpin:127.0.0.1:0", dialect="ardupilotmega")
    port = conn.port.getsockname()[1]
    received: list[bytes] = []
    listener = threading.Thread(target=_listen, args=(conn, len(flight.frames), received))
    listener.start()
    speed = 8.0
    start = time.monotonic()
    sent = replay_to_mavlink(flight, f"udpout:127.0.0.1:{port}", speed=speed)
    elapsed = time.monotonic() - start
    listener.join()
    conn.close()
    assert sent == len(flight.frames) == 3 * (20 + 2 * 2) + 3
    assert received == [f.data for f in flight.frames]
    span_s = flight.end_time_s - flight.start_time_s
    assert span_s / speed * 0.9 <= elapsed <= span_s / speed + 2.0


def test_replay_schedule_scales_with_speed(flight_path):
    flight = read_flight(flight_path)
    clock = FakeClock()
    replay_to_mavlink(flight, "udpout:127.0.0.1:9", speed=4.0, sleep=clock.sleep, clock=clock)
    assert sum(clock.sleeps) == pytest.approx((flight.end_time_s - flight.start_time_s) / 4.0, rel=1e-6)


def test_replay_paces_by_flight_time_for_a_log_flown_faster_than_real_time(tmp_path):
    """A log of vehicles at 10x (clock_rate 10: its receive times span a tenth of the flight)
    replays at --speed 1 in flight time: ten times its receive span."""
    path = tmp_path / "fast.mcap"
    with FlightLogger(
        path, ORIGIN, plan=make_plan([1]), scenario_text=SCENARIO_TEXT, clock_rate=10.0
    ) as logger:
        for msg, raw, t_s in flight_frames([1], samples=20):
            logger.on_frame(msg, raw, t_s)
    flight = read_flight(path)
    clock = FakeClock()
    frames = list(paced(flight, 1.0, sleep=clock.sleep, clock=clock))
    span_s = (frames[-1].t_ns - frames[0].t_ns) * 1e-9
    assert span_s > 0 and sum(clock.sleeps) == pytest.approx(10.0 * span_s, rel=1e-6)


def test_bad_udp_url_is_a_user_error():
    with pytest.raises(UserError, match="udpout:HOST:PORT"):
        parse_udp_url("tcp:localhost:14550")


def test_replay_command_writes_a_non_empty_rrd_with_all_views(flight_path, tmp_path, capsys):
    rrd = tmp_path / "out.rrd"
    assert main(["replay", str(flight_path), "--rrd", str(rrd)]) == 0
    assert rrd.stat().st_size > 1000
    from rerun.chunk import RrdReader

    entities = {chunk.entity_path for chunk in RrdReader(rrd).stream()}
    for s in (1, 2, 3):
        assert {
            f"/map/plan/{s}",
            f"/map/track/{s}",
            f"/map/vehicle/{s}",
            f"/world/plan/{s}",
            f"/world/track/{s}",
            f"/world/vehicle/{s}",
            f"/series/altitude_m/{s}",
            f"/series/ground_speed_mps/{s}",
            f"/series/mission_item/{s}",
            f"/series/link_loss/{s}",
        } <= entities
    assert {
        "/world/obstacles/cylinders",
        "/world/obstacles/radars/0",
        "/map/obstacles",
        "/events",
    } <= entities
    rows = sum(c.num_rows for c in RrdReader(rrd).stream() if c.entity_path == "/world/vehicle/2")
    assert rows == 20
    assert "wrote" in capsys.readouterr().out


def test_replay_command_needs_a_target(flight_path, capsys):
    assert main(["replay", str(flight_path)]) == 2
    assert "nothing to do" in capsys.readouterr().err


def test_replay_to_live_rerun_uses_the_live_views(flight_path, tmp_path):
    import rerun as rr
    from rerun.chunk import RrdReader

    from gcs_planner.telemetry.replay import replay_to_rerun_live

    flight = read_flight(flight_path)
    rrd = tmp_path / "live.rrd"
    rec = rr.RecordingStream("gcs-planner", recording_id="live-replay-test")
    rec.save(str(rrd))
    assert replay_to_rerun_live(flight, rec, speed=0) == len(flight.frames)
    rec.flush()
    rec.disconnect()
    entities = {c.entity_path for c in RrdReader(rrd).stream()}
    assert {
        "/map/plan/1",
        "/map/vehicle/3",
        "/series/mission_item/2",
        "/world/obstacles/cylinders",
    } <= entities
    rows = sum(c.num_rows for c in RrdReader(rrd).stream() if c.entity_path == "/world/vehicle/2")
    assert rows == 20


def test_log_flight_to_rerun_file_is_complete_and_reopenable(flight_path, tmp_path):
    from rerun.chunk import RrdReader

    from gcs_planner.telemetry import log_flight_to_rerun

    rrd = tmp_path / "f.rrd"
    log_flight_to_rerun(read_flight(flight_path), rrd)
    reader = RrdReader(rrd)
    assert len(reader.recordings()) == 1 and len(reader.blueprints()) == 1  # default blueprint saved
    store = reader.store()  # needs the footer/manifest: the file was finished
    assert "/map/track/1" in store.summary()


def _with_ground_station(tmp_path, n_vehicle_samples: int = 20):
    """A log holding three vehicles and a ground station (sysid 255, HEARTBEAT type GCS)."""
    gcs = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
    path = tmp_path / "gcs.mcap"
    with FlightLogger(path, ORIGIN) as logger:
        for k, (msg, raw, t_s) in enumerate(flight_frames([1, 2, 3], samples=n_vehicle_samples)):
            logger.on_frame(msg, raw, t_s)
            if k % 5 == 0:
                hb = gcs.heartbeat_encode(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
                logger.on_frame(hb, bytes(hb.pack(gcs)), t_s)
    return read_flight(path)


def test_ground_station_frames_are_kept_but_never_replayed(tmp_path):
    flight = _with_ground_station(tmp_path)
    assert flight.sysids == [1, 2, 3] and flight.gcs_sysids == [255]
    assert any(f.sysid == 255 for f in flight.frames)  # kept in the log
    clock = FakeClock()
    sent = list(paced(flight, 0.0, sleep=clock.sleep, clock=clock))
    assert sent == [f for f in flight.frames if f.sysid != 255] and sent


def test_unpaced_replay_is_capped_and_loses_nothing_on_loopback(tmp_path):
    flight = _with_ground_station(tmp_path, n_vehicle_samples=50)  # fits a default socket buffer
    clock = FakeClock()
    replay_to_mavlink(flight, "udpout:127.0.0.1:9", speed=0.0, sleep=clock.sleep, clock=clock)
    n = len(flight.vehicle_frames)
    assert clock.now == pytest.approx((n - 1) / MAX_RATE_HZ)  # speed 0: as fast as the cap allows
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(5.0)
    got: list[bytes] = []

    def receive() -> None:
        with contextlib.suppress(TimeoutError):
            while len(got) < n:
                got.append(sock.recv(4096))

    listener = threading.Thread(target=receive)
    listener.start()
    assert replay_to_mavlink(flight, f"udpout:127.0.0.1:{sock.getsockname()[1]}", speed=0.0) == n
    listener.join()
    sock.close()
    assert got == [f.data for f in flight.vehicle_frames]
