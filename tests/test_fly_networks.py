"""Fleets over several MAVLink networks: system ids repeat, fleet ids do not (mavlink/networks.py)."""

import asyncio
import queue
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from child_process import child, group_alive
from ports import free_port_run
from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs_planner.core import lockstep
from gcs_planner.core.errors import UserError
from gcs_planner.flight import FlyOptions, check_flight, end_summary, fly
from gcs_planner.flight.vehicles import ConnectedVehicles
from gcs_planner.mavlink.networks import open_networks
from gcs_planner.mavlink.preflight import request_streams
from gcs_planner.model.scenario import ScenarioError
from gcs_planner.planning import load_scenario, plan_scenario
from gcs_planner.telemetry import read_flight
from sitl_mock.fleet import MockFleet
from sitl_mock.plan_fleet import MockVehicles

STRAIGHT = Path(__file__).resolve().parents[1] / "missions" / "straight_4uav.toml"


def _two_networks(tmp_path: Path, networks=(0, 0, 1, 1), sysids=(1, 2, 1, 2)) -> Path:
    """straight_4uav with its vehicles on these networks and system ids."""
    text = STRAIGHT.read_text()
    for k, (net, sysid) in enumerate(zip(networks, sysids, strict=True), start=1):
        text = text.replace(
            f'id = "uav{k}"\nsysid = {k}\n', f'id = "uav{k}"\nsysid = {sysid}\nnetwork = {net}\n'
        )
    path = tmp_path / "two_networks.toml"
    path.write_text(text)
    return path


def test_a_vehicle_on_network_1_is_named_by_its_fleet_id(tmp_path):
    scenario = load_scenario(_two_networks(tmp_path))
    assert [v.sysid for v in scenario.vehicles] == [1, 2, 257, 258]
    bad = _two_networks(tmp_path, sysids=(1, 2, 0, 2))
    with pytest.raises(ScenarioError, match=r"vehicles\[2\].network is 1, but the vehicle has no sysid"):
        load_scenario(bad)
    bad.write_text(STRAIGHT.read_text().replace("sysid = 1\n", "sysid = 1\nnetwork = 64\n"))
    with pytest.raises(ScenarioError, match=r"vehicles\[0\].network"):
        load_scenario(bad)


def test_a_plan_with_an_empty_network_or_too_few_connections_is_refused(tmp_path):
    plan = plan_scenario(load_scenario(_two_networks(tmp_path, networks=(0, 0, 2, 2))))
    with pytest.raises(UserError, match="network 1 has no vehicle"):
        check_flight(plan)
    scenario = load_scenario(_two_networks(tmp_path))
    plan = plan_scenario(scenario)
    one_link = ConnectedVehicles(["udpout:127.0.0.1:9"])  # nothing listens: a send would time out
    with pytest.raises(UserError, match=r"on 2 MAVLink network\(s\), but 1 were given"):
        asyncio.run(fly(scenario, plan, FlyOptions(out_dir=tmp_path / "out", rrd=False), one_link))
    assert not (tmp_path / "out" / "flight.mcap").exists()


def test_network_links_route_by_fleet_id():
    """Two fleets whose only vehicle is sysid 1: each is reached, and heard, as itself."""

    async def main():
        with MockFleet(count=1) as a, MockFleet(count=1, vehicle_type="fixed_wing") as b:
            urls = [[f"udpout:{h}:{p}" for h, p in fleet.addresses] for fleet in (a, b)]
            link = await open_networks(urls, heartbeat_period_s=0.2)
            heard: dict[int, set[int]] = {1: set(), 257: set()}
            for vehicle in heard:
                link.subscribe(
                    lambda msg, raw, t, v=vehicle: heard[v].add(msg.get_srcSystem()), sysid=vehicle
                )
            beats = [
                await link.wait_for(
                    lambda m, v=v: m.get_type() == "HEARTBEAT" and m.get_srcSystem() == v, 5.0
                )
                for v in (1, 257)
            ]
            assert [b.type for b in beats] == [mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_TYPE_FIXED_WING]
            request = mavlink.MAVLink_command_long_message(
                257,
                1,
                mavlink.MAV_CMD_REQUEST_MESSAGE,
                0,
                mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION,
                0,
                0,
                0,
                0,
                0,
                0,
            )
            link.send(request)
            assert request.target_system == 257  # the caller's message is left as it was
            ack = await link.wait_for(
                lambda m: m.get_type() == "COMMAND_ACK" and m.get_srcSystem() == 257, 5.0
            )
            assert ack.result == mavlink.MAV_RESULT_ACCEPTED
            assert (
                sorted(link.vehicles) == [1, 257]
                and link.vehicles[257].mav_type == mavlink.MAV_TYPE_FIXED_WING
            )
            with pytest.raises(ValueError, match="network 2; this flight has 2"):
                link.send(mavlink.MAVLink_command_long_message(513, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0))
            await link.close()
            assert heard == {1: {1}, 257: {257}}

    asyncio.run(main())


def test_a_fleet_over_two_networks_flies_each_vehicle_its_own_mission(tmp_path):
    """Two mock processes, system ids 1 and 2 on each: every vehicle flies its own line (a merged
    or swapped mission would break the cross-track bound) and the log keeps the four apart."""
    scenario = load_scenario(_two_networks(tmp_path))
    plan = plan_scenario(scenario)
    vehicles = MockVehicles(plan.vehicles, plan.origin)
    result = lockstep.run(
        fly(scenario, plan, FlyOptions(out_dir=tmp_path, rrd=False, tlog=True), vehicles), True
    )
    assert result.passed, [r.failures for r in result.reports]
    assert sorted(r.sysid for r in result.reports if r.completed and r.cross_track_max_m < 5.0) == [
        1,
        2,
        257,
        258,
    ]
    flight = read_flight(result.mcap_path)
    assert len(flight.frames) == result.frames_received  # every frame the link delivered is in the log
    assert set(flight.positions) == {1, 2, 257, 258}
    assert all(len(t) > 20 for t in flight.positions.values())
    assert {e["sysid"] for _, e in flight.events if e.get("event") == "route_start"} == {1, 2, 257, 258}
    # a .tlog per network, each read by pymavlink's own reader: system ids 1 and 2, unique within it
    assert result.tlog_paths == [tmp_path / "flight.tlog", tmp_path / "flight.net1.tlog"]
    per_network = []
    for path in result.tlog_paths:
        reader = mavutil.mavlink_connection(str(path))
        positions = {}
        while (msg := reader.recv_match(type="GLOBAL_POSITION_INT")) is not None:
            positions.setdefault(msg.get_srcSystem(), []).append(msg.lat)
        per_network.append(positions)
    assert [sorted(p) for p in per_network] == [[1, 2], [1, 2]]
    for network, positions in enumerate(per_network):
        for sysid, lats in positions.items():
            fixed = [lat for lat in lats if abs(lat) > 100_000]  # the track skips no-fix (0, 0) reports
            track = flight.positions[network * 256 + sysid]
            assert fixed == np.round(track.lat_deg * 1e7).astype(int).tolist()


def test_sitl_mock_runs_one_process_per_network_reached_by_its_connect_range(tmp_path):
    """`sitl-mock --vehicles 4 --per-network 2`: two processes, sysids 1-2 on each, and the two
    --connect ranges it prints reach them as fleet ids 1, 2, 257, 258 on one shared clock; fly with
    one --connect for the two-network plan is refused before anything is sent."""
    base = free_port_run(4)
    cli = [sys.executable, "-m", "sitl_mock.cli", "--vehicles", "4", "--per-network", "2"]
    with child([*cli, "--base-port", str(base)], stderr=subprocess.PIPE, text=True) as mock:
        lines: queue.Queue[str] = queue.Queue()
        threading.Thread(target=lambda: [lines.put(line) for line in mock.stderr], daemon=True).start()
        urls = []
        while len(urls) < 2:
            line = lines.get(timeout=60)
            if "--connect" in line:
                urls.append(line.split("--connect ")[1].rstrip(")\n"))
        assert urls == [f"udpout:127.0.0.1:{base}-{base + 1}", f"udpout:127.0.0.1:{base + 2}-{base + 3}"]

        async def boot_times() -> dict[int, float]:
            link = await open_networks([[url] for url in urls], heartbeat_period_s=0.2)
            await request_streams(link, [1, 2, 257, 258])
            times: dict[int, float] = {}

            def on_frame(msg, raw, t_s) -> None:
                if msg.get_type() == "GLOBAL_POSITION_INT":
                    times[msg.get_srcSystem()] = msg.time_boot_ms / 1000.0 - time.monotonic()

            link.subscribe(on_frame)
            while len(times) < 4:
                await asyncio.sleep(0.2)
            await link.close()
            return times

        offsets = asyncio.run(asyncio.wait_for(boot_times(), 30.0))
        assert sorted(offsets) == [1, 2, 257, 258]
        assert max(offsets.values()) - min(offsets.values()) < 0.5  # one simulated clock (10 Hz reports)
        argv = ["fly", str(_two_networks(tmp_path)), "-o", str(tmp_path / "out"), "--connect", urls[0]]
        refused = subprocess.run(
            [sys.executable, "-m", "gcs_planner.cli", *argv], capture_output=True, text=True
        )
        assert refused.returncode == 2 and "one --connect per network" in refused.stderr, refused.stderr
        assert not (tmp_path / "out").exists()  # refused before anything was written
        mock.send_signal(signal.SIGINT)
        assert mock.wait(timeout=30) == 0
    assert not group_alive(mock.pid)


def test_the_end_states_of_a_large_fleet_fit_one_line():
    states = {s: "landed (disarmed)" for s in [*range(1, 251), *range(257, 507)]} | {
        7: "holding (mission complete)"
    }
    assert end_summary(states) == (
        "sysid 1-6, 8-250, 257-506 landed (disarmed); sysid 7 holding (mission complete)"
    )


def _held(fleet: MockFleet, sysid: int) -> list:
    return fleet.call(lambda: fleet.vehicle(sysid).mission_server.items(0))


def test_upload_names_vehicles_by_fleet_id_with_one_connect_per_network(tmp_path, capsys):
    """`upload plan.json --sysid all` of a two-network plan: system id 1 on each network gets its
    own vehicle's mission (not the other's, not both merged); with one --connect it is refused in
    one line before anything is sent."""
    from gcs_planner.autopilots import readback
    from gcs_planner.cli import main
    from gcs_planner.mavlink.mission import compare_items
    from gcs_planner.missions.items import plan_to_items

    scenario = load_scenario(_two_networks(tmp_path))
    plan = plan_scenario(scenario)
    plan_path = tmp_path / "plan.json"
    plan.save(plan_path)
    base = free_port_run(4)
    with (
        MockFleet(count=2, home=plan.origin, base_port=base) as a,
        MockFleet(count=2, home=plan.origin, base_port=base + 2) as b,
    ):
        connects = [f"udpout:{f.addresses[0][0]}:{f.addresses[0][1]}-{f.addresses[1][1]}" for f in (a, b)]
        one = ["upload", str(plan_path), "--sysid", "1,257", "--connect", connects[0]]
        assert main(one) == 2
        err = capsys.readouterr().err
        assert "fleet id 257 is on MAVLink network 1" in err and err.count("\n") == 1
        assert [_held(f, s) for f in (a, b) for s in (1, 2)] == [[]] * 4  # nothing was sent
        argv = ["upload", str(plan_path), "--sysid", "all", *(x for c in connects for x in ("--connect", c))]
        assert main(argv) == 0
        rows = [line.split() for line in capsys.readouterr().out.splitlines() if "ACCEPTED" in line]
        assert sorted(int(r[0]) for r in rows) == [1, 2, 257, 258]
        for fleet, network in ((a, 0), (b, 1)):
            for sysid in (1, 2):
                vehicle = next(v for v in plan.vehicles if v.sysid == network * 256 + sysid)
                sent = plan_to_items(vehicle, plan.origin, "ardupilot")
                assert compare_items(sent, _held(fleet, sysid), readback.ARDUCOPTER, skip_home=True) is None
