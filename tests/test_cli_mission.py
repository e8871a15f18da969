"""The mission commands end to end: export, and upload / download / clear / start against a real mock
vehicle over UDP on 127.0.0.1; user mistakes are one line on stderr with exit code 2."""

from __future__ import annotations

import socket
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from ports import frames_from_a_gcs

from gcs_planner.autopilots import readback
from gcs_planner.cli import main
from gcs_planner.core.geo import Origin
from gcs_planner.mavlink.mission import compare_items
from gcs_planner.missions.files import in_file_frames, load_mission_file
from gcs_planner.missions.items import deg_to_e7, plan_to_items
from gcs_planner.missions.wpl import dumps_wpl
from gcs_planner.model.plan import Plan, VehiclePlan
from gcs_planner.wire.types import MissionItem

ORIGIN = Origin(47.397742, 8.545594, 488.0)
SCENARIO = """
name = "cli"
[origin]
lat_deg = 47.397742
lon_deg = 8.545594
alt_m = 488.0
[planner]
name = "straight"
[[vehicles]]
id = "a"
sysid = 1
start = [0.0, 0.0, 0.0]
goal = [200.0, 0.0, 20.0]
[[obstacles.cylinders]]
x = 100.0
y = 40.0
radius_m = 10.0
z_max_m = 50.0
[bounds]
x = [-50.0, 300.0]
y = [-100.0, 100.0]
"""


def make_plan(tmp_path: Path, sysids=(1, 2)) -> Path:
    vehicles = []
    for sysid in sysids:
        wps = np.array([[0.0, 10.0 * sysid, 0.0], [80.0, 10.0 * sysid, 20.0], [160.0, 10.0 * sysid, 25.0]])
        times = np.array([0.0, 8.0, 16.0])
        speeds = np.array([0.0, 10.0, 10.0])
        vehicles.append(VehiclePlan(f"uav{sysid}", sysid, wps, times, speeds, wps, times))
    path = tmp_path / "plan.json"
    Plan(ORIGIN, "test", vehicles).save(path)
    return path


def test_export_qgc_and_wpl(tmp_path, capsys):
    plan_path = make_plan(tmp_path)
    scenario = tmp_path / "s.toml"
    scenario.write_text(SCENARIO)
    out = tmp_path / "out"
    assert main(["export", str(plan_path), "--scenario", str(scenario), "-o", str(out)]) == 0
    table = capsys.readouterr().out
    assert "uav1" in table and "uav2" in table and "uav1.plan" in table
    plan = Plan.load(plan_path)
    mf = load_mission_file(out / "uav2.plan")
    assert mf.items("ardupilot") == in_file_frames(plan_to_items(plan.vehicles[1], ORIGIN, "ardupilot"))
    assert len(mf.fence) == 5 and len(mf.rally) == 1  # 4 bound vertices + 1 cylinder; 1 vehicle start
    assert main(["export", str(plan_path), "--format", "wpl", "--autopilot", "px4", "--vehicle", "uav1",
                 "-o", str(out)]) == 0  # fmt: skip
    assert load_mission_file(out / "uav1.waypoints", autopilot="px4").items("px4") == in_file_frames(
        plan_to_items(plan.vehicles[0], ORIGIN, "px4")
    )
    assert not (out / "uav2.waypoints").exists()


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["export", "{tmp}/missing.json"], "no such file"),
        (["export", "{plan}", "--vehicle", "ghost"], "'ghost' is not in the plan"),
        (["export", "{plan}", "--format", "wpl", "--scenario", "{tmp}/s.toml"], "needs --format qgc"),
    ],
)
def test_export_errors_are_one_line(tmp_path, capsys, argv, message):
    plan_path = make_plan(tmp_path)
    argv = [a.format(tmp=tmp_path, plan=plan_path) for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1 and "Traceback" not in err


# ----------------------------------------------------------------- against a mock vehicle over UDP


@pytest.fixture(scope="module")
def fleet():
    sitl_mock = pytest.importorskip("sitl_mock")
    vehicles = [{"profile": "ardupilot"}, {"profile": "px4"}, {"profile": "ardupilot", "capacity": 4}]
    with sitl_mock.MockFleet(vehicles=vehicles, home=ORIGIN, speedup=20.0) as f:
        yield f


def url(fleet, sysid: int) -> str:
    host, port = fleet.vehicle(sysid).address
    return f"udpout:{host}:{port}"


def held(fleet, sysid: int, mission_type: int = 0):
    return fleet.call(lambda: fleet.vehicle(sysid).mission_server.items(mission_type))


@pytest.mark.parametrize("sysids", [["--sysid", "1"], ["--sysid", "all"]])
def test_in_flight_sets_the_items_an_upload_sends_ahead(fleet, tmp_path, monkeypatch, sysids):
    """`upload --in-flight 2` (one vehicle and a fleet): every list goes with Timing.window 2."""
    from gcs_planner.mavlink.mission import MissionClient

    windows = []
    real = MissionClient.upload

    async def upload(self, *args, **kw):
        windows.append(self.timing.window)
        return await real(self, *args, **kw)

    monkeypatch.setattr(MissionClient, "upload", upload)
    plan_path = make_plan(tmp_path, sysids=(1,))
    argv = ["upload", "--connect", url(fleet, 1), *sysids, str(plan_path), "--in-flight", "2"]
    assert main(argv) == 0
    assert windows and set(windows) == {2}


def test_upload_download_start_clear_ardupilot(fleet, tmp_path, capsys):
    plan_path = make_plan(tmp_path, sysids=(1,))
    scenario = tmp_path / "s.toml"
    scenario.write_text(SCENARIO)
    argv = ["--connect", url(fleet, 1), "--sysid", "1"]
    assert main(["upload", *argv, str(plan_path), "--scenario", str(scenario), "--verify"]) == 0
    out = capsys.readouterr().out
    assert "(ardupilot)" in out and out.count("ACCEPTED") == 3 and out.count(" yes") == 3
    sent = plan_to_items(Plan.load(plan_path).vehicles[0], ORIGIN, "ardupilot")
    assert compare_items(sent, held(fleet, 1), readback.ARDUCOPTER, skip_home=True) is None
    assert len(held(fleet, 1, 1)) == 5 and len(held(fleet, 1, 2)) == 1

    assert main(["download", *argv, str(tmp_path / "back.plan")]) == 0
    out = capsys.readouterr().out
    assert "NAV_TAKEOFF" in out and "fence: 5 items" in out and "rally: 1 items" in out
    back = load_mission_file(tmp_path / "back.plan")
    assert compare_items(sent, back.items("ardupilot"), readback.ARDUCOPTER, skip_home=True) is None
    assert len(back.fence) == 5

    assert main(["start", *argv]) == 0
    assert "mission start" in capsys.readouterr().out
    state = fleet.call(lambda: fleet.vehicle(1).state)
    assert state.armed and state.mode == "AUTO"

    # armed and flying the mission in AUTO (issue 14): upload and clear ask for --force
    flying = held(fleet, 1)
    for command in (["upload", *argv, str(plan_path)], ["clear", *argv, "--type", "all"]):
        assert main(command) == 2
        err = capsys.readouterr().err
        assert "armed and flying its mission in AUTO" in err and "--force" in err and err.count("\n") == 1
    assert held(fleet, 1) == flying and len(held(fleet, 1, 1)) == 5
    assert main(["clear", *argv, "--type", "all", "--force"]) == 0
    out = capsys.readouterr().out
    assert "CLEARED" in out  # ArduPilot refused MISSION_CLEAR_ALL in AUTO; --force uploaded an empty list
    assert "note: mission: MISSION_CLEAR_ALL refused (ERROR); cleared by uploading an empty list" in out
    assert held(fleet, 1, 1) == [] and held(fleet, 1, 2) == [] and len(held(fleet, 1)) <= 1  # home may stay


def test_wpl_row_0_is_the_home_and_px4_gets_the_rows_after_it(fleet, tmp_path, capsys):
    """QGroundControl reads row 0 of every WPL 110 file as the planned home: PX4 gets rows 1.., so
    its feasibility check finds the take-off first (a home waypoint before it is rejected)."""
    plan = Plan.load(make_plan(tmp_path, sysids=(2,)))
    items = plan_to_items(plan.vehicles[0], ORIGIN, "px4")
    lat, lon = deg_to_e7([ORIGIN.lat_deg, ORIGIN.lon_deg]).tolist()
    home = MissionItem(0, 0, 16, x=lat, y=lon, z=488.0)
    (tmp_path / "m.waypoints").write_text(dumps_wpl([home, *items]))
    argv = ["--connect", url(fleet, 2), "--sysid", "2"]
    assert main(["upload", *argv, str(tmp_path / "m.waypoints")]) == 0
    assert "(px4)" in capsys.readouterr().out
    assert held(fleet, 2) == [readback.PX4(it) for it in items]
    assert not fleet.call(lambda: fleet.vehicle(2).mission_rejected)
    assert main(["download", *argv, str(tmp_path / "back.txt")]) == 0
    back = load_mission_file(tmp_path / "back.txt")
    assert back.items("px4") == in_file_frames([readback.PX4(it) for it in items])  # 6 is written as 3
    assert back.home == pytest.approx((ORIGIN.lat_deg, ORIGIN.lon_deg, ORIGIN.alt_m), abs=1e-3)


def test_vehicle_refusal_is_one_line_and_keeps_the_old_mission(fleet, tmp_path, capsys):
    before = held(fleet, 3)
    plan_path = make_plan(tmp_path, sysids=(3,))
    assert main(["upload", "--connect", url(fleet, 3), "--sysid", "3", str(plan_path)]) == 2
    captured = capsys.readouterr()
    assert "FAILED" in captured.out and "Traceback" not in captured.err
    assert captured.err.count("\n") == 1 and "space" in captured.err.lower()
    assert held(fleet, 3) == before


def bad_file(tmp_path: Path) -> Path:
    items = plan_to_items(Plan.load(make_plan(tmp_path, sysids=(2,))).vehicles[0], ORIGIN, "px4")
    bad = tmp_path / "bad.waypoints"
    home = MissionItem(0, 0, 16)  # row 0: the planned home
    bad.write_text(dumps_wpl([home, *items[:2], replace(items[2], x=910_000_000), *items[3:]]))  # latitude 91
    return bad


@pytest.mark.parametrize("in_process", [True, False])
def test_bad_input_sends_nothing(tmp_path, capsys, in_process):
    """One line on stderr, exit 2, and not a single datagram (not even a heartbeat) reaches the vehicle."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as vehicle:
        vehicle.bind(("127.0.0.1", 0))
        argv = ["upload", "--connect", f"udpout:127.0.0.1:{vehicle.getsockname()[1]}", "--sysid", "2"]
        argv.append(str(bad_file(tmp_path)))
        if in_process:
            code, err = main(argv), capsys.readouterr().err
        else:  # a real process: no traceback on stderr
            proc = subprocess.run(
                [sys.executable, "-m", "gcs_planner.cli", *argv], capture_output=True, text=True, timeout=60
            )
            code, err = proc.returncode, proc.stderr
        assert frames_from_a_gcs(vehicle) == []
    assert code == 2 and "Traceback" not in err and err.count("\n") == 1
    assert "item 2: field x" in err and "latitude 91" in err


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (
            ["--connect", "udpout:127.0.0.1:{port}", "--sysid", "9", "--heartbeat-timeout", "0.5"],
            "no HEARTBEAT",
        ),
        (["--connect", "tcp:nowhere", "--sysid", "1"], "cannot open --connect"),
    ],
)
def test_connection_errors_are_one_line(fleet, capsys, argv, message):
    port = fleet.vehicle(1).address[1]
    assert main(["download", *[a.format(port=port) for a in argv]]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


def test_fleet_upload_from_plan_json(fleet, tmp_path, capsys):
    plan_path = make_plan(tmp_path, sysids=(1, 2, 3))
    plan = Plan.load(plan_path)
    connects = [a for s in (1, 2, 3) for a in ("--connect", url(fleet, s))]
    before = held(fleet, 3)
    assert (
        main(["upload", *connects, "--sysid", "all", "--force", str(plan_path)]) == 2
    )  # vehicle 3 has room for 4 items; --force: vehicle 1 may still be armed in AUTO (test above)
    captured = capsys.readouterr()
    notes = [line for line in captured.out.splitlines() if line.startswith("note:")]
    assert notes == [f"note: {t}: not in the file; the vehicle's list is kept (--clear-absent clears it)"
                     for t in ("fence", "rally")]  # fmt: skip
    rows = [line.split() for line in captured.out.splitlines()[3:]]
    assert [(r[0], r[1], r[3]) for r in rows] == [
        ("1", "mission", "ACCEPTED"),
        ("2", "mission", "ACCEPTED"),
        ("3", "mission", "FAILED"),
    ]
    assert "1 of 3 uploads failed; vehicle 3 mission" in captured.err and captured.err.count("\n") == 1
    sent = plan_to_items(plan.vehicles[0], ORIGIN, "ardupilot")
    assert compare_items(sent, held(fleet, 1), readback.ARDUCOPTER, skip_home=True) is None
    assert held(fleet, 2) == [readback.PX4(it) for it in plan_to_items(plan.vehicles[1], ORIGIN, "px4")]
    assert held(fleet, 3) == before
    assert main(["upload", *connects[:4], "--sysid", "1,2", "--force", str(plan_path)]) == 0
    assert capsys.readouterr().out.count("ACCEPTED") == 2


def test_an_upload_with_a_scenario_sets_the_fence_ceiling_as_each_autopilot_keeps_it(fleet, tmp_path, capsys):
    plan_path = make_plan(tmp_path, sysids=(1, 2))
    scenario = tmp_path / "s.toml"
    scenario.write_text(SCENARIO + "z = [0.0, 60.0]\n")  # [bounds] z: the ceiling above home
    connects = [a for s in (1, 2) for a in ("--connect", url(fleet, s))]
    argv = ["upload", *connects, "--sysid", "1,2", "--force", str(plan_path), "--scenario", str(scenario)]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "vehicle 1: fence ceiling FENCE_ALT_MAX = 60 m above home" in out  # ArduCopter (AC_Fence)
    assert "vehicle 2: fence ceiling GF_MAX_VER_DIST = 60 m above home" in out  # PX4's geofence
    ceilings = fleet.call(
        lambda: (fleet.vehicle(1).params["FENCE_ALT_MAX"], fleet.vehicle(2).params["GF_MAX_VER_DIST"])
    )
    assert ceilings == (60.0, 60.0)
    low = tmp_path / "low.toml"
    low.write_text(SCENARIO + "z = [0.0, 22.0]\n")  # the plan climbs to 25 m
    assert main([*argv[:-1], str(low)]) == 2
    assert "climbs to 25.0 m above home, over the fence ceiling 22.0 m" in capsys.readouterr().err


def test_fleet_arguments_are_checked(tmp_path, capsys):
    plan_path = make_plan(tmp_path)
    wpl = tmp_path / "m.waypoints"
    wpl.write_text(dumps_wpl(plan_to_items(Plan.load(plan_path).vehicles[0], ORIGIN, "px4")))
    for argv, message in [
        (["--sysid", "all", str(wpl)], "needs a plan.json"),
        (["--sysid", "1,2", "--vehicle", "uav1", str(plan_path)], "single --sysid"),
        (["--sysid", "1,9", str(plan_path)], "no vehicle with sysid 9"),
    ]:
        assert main(["upload", "--connect", "udpout:127.0.0.1:9", *argv]) == 2
        assert message in capsys.readouterr().err


def test_signed_vehicle_takes_an_upload_signed_from_the_environment(tmp_path, capsys, monkeypatch):
    sitl_mock = pytest.importorskip("sitl_mock")
    from gcs_planner.wire.signing import key_from_passphrase

    key = key_from_passphrase("field-day")
    with sitl_mock.MockFleet(count=1, profile="px4", home=ORIGIN, speedup=20.0, signing_key=key) as signed:
        plan = Plan.load(make_plan(tmp_path, sysids=(1,)))
        items = plan_to_items(plan.vehicles[0], ORIGIN, "px4")
        (tmp_path / "m.waypoints").write_text(dumps_wpl([MissionItem(0, 0, 16), *items]))  # row 0: home
        monkeypatch.setenv("GCS_PLANNER_SIGNING_PASSPHRASE", "field-day")
        assert (
            main(["upload", "--connect", url(signed, 1), "--sysid", "1", str(tmp_path / "m.waypoints")]) == 0
        )
        assert "ACCEPTED" in capsys.readouterr().out
        assert held(signed, 1) == [readback.PX4(it) for it in items]


# ----------------------------------------------------------------- issue 14: who uploads, what is left


class RawGcs:
    """A second GCS as bare pymavlink over its own UDP socket: it opens an upload and goes silent."""

    def __init__(self, address, sysid: int, compid: int) -> None:
        from pymavlink.dialects.v20 import ardupilotmega as mavlink

        self.mavlink = mavlink
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(2.0)
        self.address = address
        self.mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)
        self.parser = mavlink.MAVLink(None)

    def send(self, msg) -> None:
        self.sock.sendto(msg.pack(self.mav), self.address)

    def wait(self, name: str):
        while True:
            for msg in self.parser.parse_buffer(self.sock.recv(4096)) or []:
                if msg.get_type() == name:
                    return msg


def test_a_second_gcs_with_its_own_sysid_is_denied_and_told_what_the_vehicle_holds(tmp_path, capsys):
    """Failure 1: the first GCS opened an upload (ArduPilot keeps it 8 s); ours, with --gcs-sysid
    254, is DENIED (MissionItemProtocol::handle_mission_count) and changes nothing."""
    sitl_mock = pytest.importorskip("sitl_mock")
    with sitl_mock.MockFleet(count=1, profile="ardupilot", home=ORIGIN, speedup=20.0) as one:
        other = RawGcs(one.vehicle(1).address, 255, 190)
        try:
            other.send(other.mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3))
            other.send(other.mavlink.MAVLink_mission_count_message(1, 1, 6, 0))
            assert other.wait("MISSION_REQUEST").seq == 0  # the vehicle is inside the other upload
            plan_path = make_plan(tmp_path, sysids=(1,))
            argv = ["upload", "--connect", url(one, 1), "--sysid", "1", "--gcs-sysid", "254", str(plan_path)]
            assert main(argv) == 2
            captured = capsys.readouterr()
            assert "FAILED" in captured.out and captured.err.count("\n") == 1
            assert "refused the mission upload: DENIED" in captured.err
            assert "the vehicle's list is unchanged" in captured.err
            assert one.call(lambda: one.vehicle(1).mission_server.busy())  # still the other GCS's upload
        finally:
            other.sock.close()


def test_a_rejected_upload_says_what_an_ardupilot_vehicle_now_holds(tmp_path, capsys):
    """Failure 7: ArduPilot truncates at MISSION_COUNT and stores items as they arrive, so a refusal
    mid-upload leaves a mix; the one error line says so after reading the list back."""
    sitl_mock = pytest.importorskip("sitl_mock")
    from sitl_mock.mission_server import Failure

    with sitl_mock.MockFleet(count=1, profile="ardupilot", home=ORIGIN, speedup=20.0) as one:
        plan = Plan.load(make_plan(tmp_path, sysids=(1,)))
        items = plan_to_items(plan.vehicles[0], ORIGIN, "ardupilot")
        first, second = tmp_path / "first.waypoints", tmp_path / "second.waypoints"
        first.write_text(dumps_wpl(items))
        second.write_text(dumps_wpl([replace(it, z=it.z + 7.0) for it in items]))
        argv = ["upload", "--connect", url(one, 1), "--sysid", "1"]
        assert main([*argv, str(first)]) == 0
        capsys.readouterr()
        one.set_mission_failure(1, Failure.WRITE_REQUEST1_ERROR_ACK)  # refuses item 1 with ERROR
        assert main([*argv, str(second)]) == 2
        err = capsys.readouterr().err
        assert "refused the mission upload: ERROR" in err and "; the vehicle now holds a mixed list" in err
        assert err.count("\n") == 1 and "Traceback" not in err
        back = one.call(lambda: one.vehicle(1).mission_server.items())
        assert len(back) == len(items) and back[1].z == pytest.approx(items[1].z, abs=0.01)  # the old item 1


def test_a_fleet_upload_with_verify_says_each_list_was_verified(fleet, tmp_path, capsys):
    plan_path = make_plan(tmp_path, sysids=(1, 2))
    argv = [
        "upload",
        "--connect",
        url(fleet, 1),
        "--connect",
        url(fleet, 2),
        "--sysid",
        "all",
        str(plan_path),
    ]
    assert main([*argv, "--verify", "--force"]) == 0
    lines = capsys.readouterr().out.splitlines()
    header = next(i for i, line in enumerate(lines) if line.split()[:2] == ["sysid", "list"])
    rows = [line.split() for line in lines[header:]]
    assert rows[0][-1] == "verified" and [r[-1] for r in rows[1:] if r[0] in ("1", "2")] == ["yes", "yes"]
    assert main([*argv, "--force"]) == 0
    assert "verified" not in capsys.readouterr().out


def test_clear_takes_a_list_of_vehicles_and_refuses_all(fleet, tmp_path, capsys):
    plan_path = make_plan(tmp_path, sysids=(1, 2))
    connects = ["--connect", url(fleet, 1), "--connect", url(fleet, 2)]
    assert main(["upload", *connects, "--sysid", "1,2", str(plan_path), "--force"]) == 0
    assert held(fleet, 1) and held(fleet, 2)
    capsys.readouterr()
    assert main(["clear", *connects, "--sysid", "1,2", "--type", "all", "--force"]) == 0
    rows = [line.split() for line in capsys.readouterr().out.splitlines()]
    assert [r[0] for r in rows if r[-2:-1] == ["CLEARED"]] == ["1", "2"], rows
    assert len(held(fleet, 1)) <= 1 and not held(fleet, 2)  # ArduPilot keeps its home at seq 0
    assert main(["clear", *connects, "--sysid", "all"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "give them as a list" in err


def rows_by_sysid(out: str) -> dict[str, list[str]]:
    return {r[0]: r for r in (line.split() for line in out.splitlines()) if r and r[0].isdigit()}


def test_download_and_start_take_a_fleet(fleet, tmp_path, capsys):
    """download --sysid 1,2 writes one file a vehicle ({sysid} in FILE), each what that vehicle
    holds; start --sysid 1,2 arms both and starts both."""
    plan_path = make_plan(tmp_path, sysids=(1, 2))
    connects = ["--connect", url(fleet, 1), "--connect", url(fleet, 2)]
    assert main(["upload", *connects, "--sysid", "1,2", str(plan_path), "--force"]) == 0
    capsys.readouterr()
    assert main(["download", *connects, "--sysid", "1,2", str(tmp_path / "back_{sysid}.plan")]) == 0
    rows = rows_by_sysid(capsys.readouterr().out)
    assert rows["1"][1] == "ardupilot" and rows["2"][1] == "px4", rows
    assert rows["1"][-2:] == ["OK", str(tmp_path / "back_1.plan")] and rows["2"][-2] == "OK"
    plan = Plan.load(plan_path)
    ardupilot = load_mission_file(tmp_path / "back_1.plan").items("ardupilot")
    sent = plan_to_items(plan.vehicles[0], ORIGIN, "ardupilot")
    assert compare_items(sent, ardupilot, readback.ARDUCOPTER, skip_home=True) is None
    px4 = load_mission_file(tmp_path / "back_2.plan", autopilot="px4").items("px4")
    assert px4 == in_file_frames([readback.PX4(it) for it in plan_to_items(plan.vehicles[1], ORIGIN, "px4")])

    assert main(["start", *connects, "--sysid", "1,2"]) == 0
    rows = rows_by_sysid(capsys.readouterr().out)
    assert [rows[s][1:3] for s in ("1", "2")] == [["OK", "OK"], ["OK", "OK"]], rows
    for sysid in (1, 2):
        state = fleet.call(lambda s=sysid: fleet.vehicle(s).state)
        assert state.armed and state.mode in ("AUTO", "MISSION"), (sysid, state.mode)


def test_a_fleet_download_needs_a_file_a_vehicle_and_start_all_needs_a_plan(tmp_path, capsys):
    """Refused in one line before any vehicle is asked (no vehicle listens on the URL)."""
    argv = ["--connect", "udpout:127.0.0.1:9", "--heartbeat-timeout", "0.1"]
    assert main(["download", *argv, "--sysid", "1,2", str(tmp_path / "fleet.plan")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "{sysid}" in err and not (tmp_path / "fleet.plan").exists()
    assert main(["start", *argv, "--sysid", "all"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "plan.json" in err


def test_a_fleet_start_with_a_vehicle_that_will_not_arm_starts_none(tmp_path, capsys):
    """One vehicle's pre-arm checks never pass: no vehicle starts, and the one that armed is
    disarmed again; the last line names the vehicle and its reason."""
    sitl_mock = pytest.importorskip("sitl_mock")
    vehicles = [{"flight": {"arm_ready_s": 1e9}}, {"flight": {"arm_ready_s": 0.0}}]
    with sitl_mock.MockFleet(vehicles=vehicles, home=ORIGIN, speedup=20.0) as f:
        connects = ["--connect", url(f, 1), "--connect", url(f, 2)]
        assert main(["start", *connects, "--sysid", "1,2", "--arm-timeout", "3"]) == 2
        captured = capsys.readouterr()
        states = [f.call(lambda s=s: f.vehicle(s).state) for s in (1, 2)]
    rows = rows_by_sysid(captured.out)
    assert rows["1"][1:3] == ["FAILED", "-"] and rows["2"][2] == "-", rows
    last = captured.err.strip().splitlines()[-1]
    assert "1 of 2 vehicles did not arm, none started" in last and "vehicle 1 could not arm" in last, last
    assert not any(s.armed for s in states) and not any(s.mode == "AUTO" for s in states)
