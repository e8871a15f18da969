"""A fleet as real ones come: three PX4 and three ArduCopter mock autopilots (their own behaviour:
arming delays, position fixes, PX4's unknown CURRENT_MODE messages), two on ports of their own, three
sending to one GCS port, one over TCP, fly a priority-swarm plan and pass in space and in time."""

from __future__ import annotations

from pathlib import Path

import pytest
from ports import free_udp_port

from gcs_planner.cli import main
from gcs_planner.flight.starts import starts
from gcs_planner.planning import load_scenario, plan_scenario
from gcs_planner.telemetry import read_flight

sitl_mock = pytest.importorskip("sitl_mock")
from sitl_mock.plan_fleet import airframe_for  # noqa: E402

MISSIONS = Path(__file__).resolve().parents[1] / "missions"
SPEEDUP = 5.0
UAV6 = """
[[vehicles]]
id = "uav6"
sysid = 6
type = "multirotor"
start = [0.0, 200.0, 35.0]
goal = [500.0, 200.0, 35.0]
speed_mps = 10.0
turn_radius_m = 15.0
min_alt_m = 20.0
max_alt_m = 120.0
separation_m = 8.0
priority = 1.0
"""


def test_three_px4_and_three_arducopters_on_ports_a_shared_port_and_tcp_pass_in_space_and_time(
    tmp_path, capsys
):
    scenario_path = tmp_path / "fleet6.toml"
    scenario_path.write_text((MISSIONS / "swarm_small.toml").read_text() + UAV6)
    plan = plan_scenario(load_scenario(scenario_path))
    plan.save(tmp_path / "plan.json")
    homes = {s.sysid: s.home for s in starts(plan.vehicles, plan.origin)}
    gcs = ("127.0.0.1", free_udp_port())
    transports = {  # sysid: (profile, how it is reached)
        1: ("px4", {}),  # listens on a port of its own
        2: ("ardupilot", {}),
        3: ("px4", {"transport": "udpclient", "gcs": gcs}),  # these three send to one GCS port
        4: ("ardupilot", {"transport": "udpclient", "gcs": gcs}),
        5: ("px4", {"transport": "udpclient", "gcs": gcs}),
        6: ("ardupilot", {"transport": "tcp"}),  # ArduPilot SITL's default: TCP
    }
    specs = [
        {"sysid": vp.sysid, "profile": transports[vp.sysid][0], "home": homes[vp.sysid],
         "airframe": airframe_for(vp), **transports[vp.sysid][1]}
        for vp in plan.vehicles
    ]  # fmt: skip
    with sitl_mock.MockFleet(vehicles=specs, home=plan.origin, speedup=SPEEDUP) as fleet:
        (h1, p1), (h2, p2) = fleet.vehicle(1).address, fleet.vehicle(2).address
        h6, p6 = fleet.vehicle(6).address
        connect = [f"udpout:{h1}:{p1}", f"udpout:{h2}:{p2}", f"udpin:{gcs[0]}:{gcs[1]}", f"tcp:{h6}:{p6}"]
        argv = ["fly", str(scenario_path), "--plan", str(tmp_path / "plan.json"), "--speedup", str(SPEEDUP),
                "-o", str(tmp_path / "out"), *(a for url in connect for a in ("--connect", url))]  # fmt: skip
        rc = main(argv)
    out = capsys.readouterr().out
    assert rc == 0 and "PASS: 6/6 vehicles conform" in out, out
    rows = [line.split() for line in out.splitlines() if line.startswith("uav")]
    late_s = [float(row[10]) for row in rows]
    assert len(rows) == 6 and all(abs(t) <= 3.0 for t in late_s), rows  # the schedule bound
    flight = read_flight(tmp_path / "out" / "flight.mcap")
    assert sorted(flight.positions) == [1, 2, 3, 4, 5, 6]  # PX4's unknown messages made no vehicle 0


def test_a_fleet_flying_30_percent_late_fails_its_schedule_bound(tmp_path, capsys):
    """Vehicles that cannot fly the planned speed (airframes capped at 0.77 of it) fly every route
    on the planned line but 30 % late: for a deconflicted plan time is separation, so they FAIL."""
    from dataclasses import replace

    scenario_path = MISSIONS / "straight_4uav.toml"
    plan = plan_scenario(load_scenario(scenario_path))
    plan.save(tmp_path / "plan.json")
    homes = {s.sysid: s.home for s in starts(plan.vehicles, plan.origin)}
    specs = []
    for vp in plan.vehicles:
        frame = airframe_for(vp)
        slow = 0.77 * float(max(vp.speeds_mps))
        specs.append({"sysid": vp.sysid, "home": homes[vp.sysid],
                      "airframe": replace(frame, cruise_speed_mps=slow, max_speed_mps=slow)})  # fmt: skip
    with sitl_mock.MockFleet(vehicles=specs, home=plan.origin, speedup=SPEEDUP) as fleet:
        connect = [a for h, p in fleet.addresses for a in ("--connect", f"udpout:{h}:{p}")]
        argv = ["fly", str(scenario_path), "--plan", str(tmp_path / "plan.json"), "--speedup", str(SPEEDUP),
                "-o", str(tmp_path / "out"), *connect]  # fmt: skip
        rc = main(argv)
    out = capsys.readouterr().out
    rows = [line for line in out.splitlines() if line.startswith("uav")]
    assert rc == 1 and len(rows) == 4 and all("s late > 3.0 s" in row for row in rows), out
    assert not any("cross-track" in row for row in rows)  # on the line, only late
