"""`watch`: vehicles the tool did not start are logged (MCAP, then .rrd) until --count positions."""

from __future__ import annotations

import pytest

from gcs_planner.cli import main
from gcs_planner.core.geo import Origin
from gcs_planner.telemetry import read_flight


def test_watch_logs_a_running_vehicle_until_count(tmp_path, capsys):
    sitl_mock = pytest.importorskip("sitl_mock")
    with sitl_mock.MockFleet(vehicles=[{"profile": "ardupilot"}], home=Origin(47.39, 8.54, 500.0)) as fleet:
        host, port = fleet.vehicle(1).address
        code = main(["watch", "--connect", f"udpout:{host}:{port}", "-o", str(tmp_path), "--count", "5"])
    assert code == 0
    flight = read_flight(tmp_path / "watch.mcap")
    assert flight.sysids == [1] and len(flight.positions[1]) >= 5
    assert flight.origin.lat_deg == pytest.approx(47.39, abs=1e-6)  # the vehicle's home
    assert (tmp_path / "watch.rrd").stat().st_size > 1000
    assert "watched: 5 position reports" in capsys.readouterr().out


def test_watch_without_a_vehicle_is_one_line(tmp_path, capsys):
    import gcs_planner.commands.watch as watch

    watch.FIRST_POSITION_TIMEOUT_S = 0.5
    assert main(["watch", "--connect", "udpout:127.0.0.1:9", "-o", str(tmp_path), "--count", "1"]) == 2
    assert "no vehicle heartbeat or position report" in capsys.readouterr().err


def test_watch_logs_from_the_start_when_the_vehicle_never_acks_stream_requests(tmp_path, capsys):
    """A vehicle (or a `replay --to` stream) that sends but never ACKs SET_MESSAGE_INTERVAL: the
    stream requests, 6 s a message, came before the logging, so `--duration 3` ran 49 s and a
    vehicle gone by then left nothing. They now run beside it."""
    import socket
    import threading

    from ports import free_port_run
    from pymavlink.dialects.v20 import ardupilotmega as mavlink

    port = free_port_run(1)
    stop = threading.Event()

    def vehicle() -> None:  # 10 Hz for at most 8 s, never answering anything
        mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
            for k in range(80):
                if stop.wait(0.1):
                    return
                msgs = [
                    mavlink.MAVLink_global_position_int_message(
                        k * 100, 473977420 + k, 85455940, 520000, 32000, 0, 0, 0, 0
                    )
                ]
                if k % 10 == 0:
                    msgs.append(mavlink.MAVLink_heartbeat_message(2, 3, 0, 0, 4, 3))
                for msg in msgs:
                    sock.sendto(msg.pack(mav), ("127.0.0.1", port))

    thread = threading.Thread(target=vehicle, daemon=True)
    thread.start()
    try:
        code = main(
            [
                "watch",
                "--connect",
                f"udpin:127.0.0.1:{port}",
                "-o",
                str(tmp_path),
                "--duration",
                "2",
            ]
        )
    finally:
        stop.set()
        thread.join()
    assert code == 0
    assert len(read_flight(tmp_path / "watch.mcap").positions[1]) >= 5
