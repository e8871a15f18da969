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
