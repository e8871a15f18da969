"""The mock fleet over real UDP, with a pymavlink ``udpout`` connection as the GCS."""

import asyncio
import contextlib
import queue
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
from child_process import child, group_alive
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs_planner.core.geo import Origin, enu_to_geodetic, geodetic_to_enu
from gcs_planner.missions.items import plan_to_items
from gcs_planner.model.plan import VehiclePlan
from gcs_planner.wire.enums import ARDUCOPTER_MODES, MissionState, px4_custom_mode
from gcs_planner.wire.types import MissionItem
from gcs_planner.wire.wire import attach_extensions
from sitl_mock import DEFAULT_HOME, Failure, MockFleet
from sitl_mock.probe import Probe

UNGATED = {"arm_ready_s": 0.0, "streams_by_request": False}  # rules these tests are not about
COMPLETES = {**UNGATED, "final_land_disarms": False}  # a final LAND reports COMPLETE (not ArduCopter)

ARM, TAKEOFF, RTL, SET_MODE, MISSION_START, SET_CURRENT, REBOOT = 400, 22, 20, 176, 300, 224, 246
ACCEPTED, DENIED, UNSUPPORTED, FAILED = 0, 2, 3, 4
INTERVAL = 511  # MAV_CMD_SET_MESSAGE_INTERVAL


def _wp(seq: int, e: float, n: float, up: float, command: int = 16, frame: int = 6, **kw) -> MissionItem:
    lat, lon, _ = enu_to_geodetic(e, n, 0.0, DEFAULT_HOME)
    return MissionItem(
        seq=seq, frame=frame, command=command, x=round(lat * 1e7), y=round(lon * 1e7), z=up, **kw
    )


def _mission(home_item: bool) -> tuple[list[MissionItem], np.ndarray]:
    """Takeoff, two waypoints, a speed change, a waypoint with a hold, land there; last target [m ENU]."""
    body = [
        MissionItem(seq=0, frame=6, command=22, z=15.0),
        _wp(0, 0.0, 120.0, 15.0),
        _wp(0, 100.0, 120.0, 25.0),
        MissionItem(seq=0, frame=2, command=178, param2=6.0),
        _wp(0, 100.0, 0.0, 20.0, param1=1.0),
        _wp(0, 100.0, 0.0, 0.0, command=21),
    ]
    items = ([_wp(0, 0.0, 0.0, 0.0, frame=0)] if home_item else []) + body
    return [it.with_seq(k) for k, it in enumerate(items)], np.array([100.0, 0.0, 0.0])


@pytest.fixture
def fleet():
    with MockFleet(flight=UNGATED, count=1, speedup=25.0) as f:
        yield f


@pytest.fixture
def gcs(fleet):
    probe = Probe(fleet.addresses[0])
    assert probe.recv("HEARTBEAT", 3.0) is not None
    yield probe
    probe.close()


LOCKSTEP = {"speedup": 1.0, "tick_s": 0.05, "physics_dt_s": 0.05, "rate_hz": 10}  # in the test's loop


def _listen(fleet_options: dict, window_s: float, rates: dict[int, float] | None = None) -> list:
    """What a GCS hears from one lockstep mock in ``window_s`` of loop time (after 0.5 s), having
    asked for ``rates`` (message id -> Hz), if any."""
    from gcs_planner.core import lockstep
    from gcs_planner.mavlink.link import MavlinkLink
    from gcs_planner.mavlink.preflight import request_streams

    async def listen() -> list:
        async with MockFleet(flight=UNGATED, count=1, **LOCKSTEP, **fleet_options) as fleet:
            ((host, port),) = fleet.addresses
            link = await MavlinkLink.open(f"udpout:{host}:{port}")
            seen: list = []
            link.subscribe(lambda msg, raw, t_s: seen.append(msg))
            await request_streams(link, [1], rates or {33: 10.0})
            await asyncio.sleep(0.5)
            start = len(seen)
            await asyncio.sleep(window_s)
            await link.close()
            return seen[start:]

    return lockstep.run(listen(), True)


def test_stream_rates_and_telemetry_fields():
    """Over 6 s of vehicle time (lockstep: no wall clock in the counts): positions at 10 Hz,
    heartbeats at 1 Hz, the status group, AMSL and relative altitudes, home (every 5 s)."""
    msgs = _listen({"home": Origin(47.0, 8.0, 500.0)}, 6.0)
    by_type: dict[str, list] = {}
    for m in msgs:
        by_type.setdefault(m.get_type(), []).append(m)
    assert 5 <= len(by_type["HEARTBEAT"]) <= 7  # 1 Hz
    gpi = by_type["GLOBAL_POSITION_INT"]
    assert 59 <= len(gpi) <= 61  # 10 Hz
    assert np.abs(np.diff([m.time_boot_ms for m in gpi]) - 100).max() <= 1  # on the vehicle's clock
    for name in ("ATTITUDE", "VFR_HUD", "SYS_STATUS", "BATTERY_STATUS", "MISSION_CURRENT", "HOME_POSITION"):
        assert name in by_type, name
    last = gpi[-1]
    assert abs(last.lat - 470000000) <= 1 and abs(last.lon - 80000000) <= 1
    assert last.alt == 500000 + last.relative_alt and abs(last.relative_alt) < 100  # mm, AMSL = home + rel
    assert {m.get_srcSystem() for m in msgs} == {1} and {m.get_srcComponent() for m in msgs} == {1}
    home_msg = by_type["HOME_POSITION"][-1]
    assert (home_msg.latitude, home_msg.longitude, home_msg.altitude) == (470000000, 80000000, 500000)
    assert by_type["MISSION_CURRENT"][-1].mission_state == MissionState.NO_MISSION


def test_a_requested_message_interval_is_kept():
    """SET_MESSAGE_INTERVAL(ATTITUDE, 200 ms) gives ATTITUDE at 5 Hz beside 10 Hz positions
    (ArduPilot keeps each message's own interval). In lockstep: on vehicle time."""
    msgs = _listen({}, 5.0, {30: 5.0, 33: 10.0})
    boot_ms = {
        k: [m.time_boot_ms for m in msgs if m.get_type() == k] for k in ("ATTITUDE", "GLOBAL_POSITION_INT")
    }
    att, gpi = np.diff(boot_ms["ATTITUDE"]), np.diff(boot_ms["GLOBAL_POSITION_INT"])
    assert len(att) >= 20 and np.abs(att - 200).max() <= 1 and np.abs(gpi - 100).max() <= 1, (att, gpi)


def test_commands_are_acknowledged(fleet, gcs):
    assert gcs.command(1, 183, 1, 1500) == UNSUPPORTED  # DO_SET_SERVO: not emulated
    assert gcs.command(1, SET_MODE, 1, ARDUCOPTER_MODES["AUTO"]) == FAILED  # no mission
    assert gcs.command(1, SET_CURRENT, 3) == FAILED  # out of range
    assert gcs.command(1, TAKEOFF, 0, 0, 0, 0, 0, 0, 12) == FAILED  # not armed
    assert gcs.command(1, ARM, 1) == ACCEPTED
    assert gcs.command(1, TAKEOFF, 0, 0, 0, 0, 0, 0, 12) == ACCEPTED
    hb = gcs.recv("HEARTBEAT", 2.0)
    assert hb.base_mode & 128 and hb.custom_mode == ARDUCOPTER_MODES["GUIDED"]
    up = gcs.recv("GLOBAL_POSITION_INT", 5.0, lambda m: m.relative_alt > 11_500)
    assert up is not None
    assert gcs.command(1, ARM, 0) == FAILED  # disarm in flight refused
    assert gcs.command(1, SET_MODE, 1, ARDUCOPTER_MODES["LOITER"]) == ACCEPTED
    assert gcs.recv("HEARTBEAT", 2.0, lambda m: m.custom_mode == ARDUCOPTER_MODES["LOITER"]) is not None
    assert gcs.command(1, RTL) == ACCEPTED
    landed = gcs.recv("HEARTBEAT", 8.0, lambda m: not m.base_mode & 128)  # lands and disarms itself
    assert landed is not None and landed.custom_mode == ARDUCOPTER_MODES["RTL"]
    assert np.linalg.norm(fleet.vehicles[0].position_enu()) < 0.5


def test_set_mode_message_and_px4_mode_numbers():
    with MockFleet(flight=UNGATED, count=1, profile="px4", speedup=10.0) as fleet:
        gcs = Probe(fleet.addresses[0])
        loiter = px4_custom_mode(4, 3)
        assert gcs.command(1, SET_MODE, 1, 4, 3) == ACCEPTED  # PX4: main mode 4 (AUTO), sub 3 (LOITER)
        assert gcs.recv("HEARTBEAT", 2.0, lambda m: m.custom_mode == loiter and m.autopilot == 12) is not None
        gcs.mav.set_mode_send(1, 1, px4_custom_mode(3))  # POSCTL through the SET_MODE message
        ack = gcs.recv("COMMAND_ACK", 2.0, lambda m: m.command == 11)
        assert ack is not None and ack.result == ACCEPTED
        assert fleet.vehicles[0].state.mode == "POSCTL"
        gcs.close()


@pytest.mark.parametrize(
    ("profile", "vehicle_type"), [("ardupilot", "multirotor"), ("px4", "fixed_wing"), ("px4", "multirotor")]
)
def test_mission_flown_end_to_end(profile, vehicle_type):
    items, last_target = _mission(home_item=profile == "ardupilot")
    first = 1 if profile == "ardupilot" else 0
    with MockFleet(
        flight=UNGATED, count=1, speedup=40.0, profile=profile, vehicle_type=vehicle_type
    ) as fleet:
        gcs = Probe(fleet.addresses[0])
        assert gcs.upload(1, items) == 0
        ack_id = fleet.vehicles[0].mission_server.opaque_id(0)
        assert gcs.command(1, ARM, 1) == ACCEPTED
        assert gcs.command(1, MISSION_START, 0, 0) == ACCEPTED
        # ArduCopter's final NAV_LAND ends in a disarm that resets the mission: no ITEM_REACHED of
        # the LAND, no COMPLETE (AP_Arming_Copter::disarm); the others report both
        resets = profile == "ardupilot" and vehicle_type == "multirotor"
        expected = list(range(first, len(items) - int(resets)))
        reached = []
        deadline = time.monotonic() + 20.0
        while time.monotonic() < deadline and len(reached) < len(expected):
            msg = gcs.recv(["MISSION_ITEM_REACHED", "MISSION_CURRENT"], 1.0)
            if msg is not None and msg.get_type() == "MISSION_ITEM_REACHED":
                reached.append(msg.seq)
        assert reached == expected
        state = MissionState.NOT_STARTED if resets else MissionState.COMPLETE
        current = gcs.recv("MISSION_CURRENT", 5.0, lambda m: m.mission_state == state)
        assert current is not None
        attach_extensions(current, current.get_msgbuf())
        assert current.mission_id == ack_id != 0
        assert current.total == len(items) - first and current.seq == (first if resets else len(items) - 1)
        gpi = gcs.recv("GLOBAL_POSITION_INT", 2.0)
        e, n, u = geodetic_to_enu(gpi.lat / 1e7, gpi.lon / 1e7, gpi.alt / 1000, DEFAULT_HOME)
        tolerance = 3.0 if vehicle_type == "multirotor" else 2 * fleet.vehicles[0].airframe.loiter_radius_m
        assert np.hypot(e - last_target[0], n - last_target[1]) < tolerance
        assert abs(gpi.relative_alt) < 200  # on the ground
        disarmed = gcs.recv("HEARTBEAT", 10.0, lambda m: not m.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
        assert disarmed is not None  # after landing (PX4: 2 s after, COM_DISARM_LAND)
        gcs.close()


def _cross_track_m(points: np.ndarray, polyline: np.ndarray) -> np.ndarray:
    """Horizontal distance of each point to the nearest segment of ``polyline`` [m]."""
    out = np.full(len(points), np.inf)
    for a, b in zip(polyline[:-1, :2], polyline[1:, :2], strict=True):
        ab = b - a
        t = np.clip((points - a) @ ab / (ab @ ab), 0.0, 1.0)
        out = np.minimum(out, np.linalg.norm(points - (a + t[:, None] * ab), axis=1))
    return out


def test_planner_items_with_delay_fly_close_to_the_plan():
    """plan_to_items output (home, NAV_DELAY, takeoff, speed changes, corners, land) flown by the mock."""
    wps = np.array([[0, 0, 20], [100, 0, 20], [100, 100, 25], [0, 100, 20], [0, 0, 20]], dtype=float)
    times = np.array([0.0, 13.0, 26.0, 39.0, 56.0])
    vp = VehiclePlan("a", 1, wps, times, np.array([0, 8, 8, 8, 6.0]), wps, times, takeoff_delay_s=5.0)
    items = plan_to_items(vp, DEFAULT_HOME, "ardupilot")
    with MockFleet(flight=COMPLETES, count=1, speedup=30.0) as fleet:
        gcs = Probe(fleet.addresses[0])
        assert gcs.upload(1, items) == 0 and gcs.command(1, ARM, 1) == ACCEPTED
        t_before = fleet.sim_time_s
        assert gcs.command(1, MISSION_START) == ACCEPTED
        t_after = fleet.sim_time_s  # the start happened between t_before and t_after
        track = []
        deadline = time.monotonic() + 15.0
        while fleet.vehicles[0].state.mission_state != MissionState.COMPLETE and time.monotonic() < deadline:
            time.sleep(0.01)
            track.append(fleet.positions_enu()[0])
        gcs.close()
        reached = fleet.vehicles[0].nav.reached
    assert [seq for seq, _ in reached] == list(range(1, len(items)))
    assert t_before + 5.0 <= reached[0][1] <= t_after + 5.0 + 0.1  # NAV_DELAY held the take-off 5 s
    track = np.array(track)
    airborne = track[track[:, 2] > 19.0]  # at cruise altitude, after the take-off climb
    assert len(airborne) > 30 and _cross_track_m(airborne[:, :2], wps).max() < 3.0  # corners slowed for
    assert np.linalg.norm(track[-1, :2]) < 1.0  # landed at the last waypoint


def test_mission_start_range_and_set_current(fleet, gcs):
    items, _ = _mission(home_item=True)
    assert gcs.upload(1, items) == 0
    assert gcs.command(1, MISSION_START, 9, 0) == DENIED  # first item past the end
    assert gcs.command(1, SET_CURRENT, len(items)) == FAILED
    assert gcs.command(1, SET_CURRENT, 2) == ACCEPTED
    assert gcs.recv("MISSION_CURRENT", 2.0, lambda m: m.seq == 2) is not None
    gcs.mav.mission_set_current_send(1, 1, 3)  # the legacy message
    assert gcs.recv("MISSION_CURRENT", 2.0, lambda m: m.seq == 3) is not None
    assert gcs.command(1, ARM, 1) == ACCEPTED
    assert gcs.command(1, MISSION_START, 2, 3) == DENIED  # ArduPilot: only (0, 0) (GCS_MAVLink_Copter.cpp)
    assert gcs.command(1, MISSION_START, 0, 0) == ACCEPTED  # resumes at the current item, 3
    got = [gcs.recv("MISSION_ITEM_REACHED", 10.0) for _ in range(2)]
    assert [m.seq for m in got] == [3, 4]


def test_reboot_forgets_the_mission_unless_persisted():
    items, _ = _mission(home_item=True)
    with MockFleet(
        flight=UNGATED, vehicles=[{"persist_mission": False}, {"persist_mission": True}], speedup=5.0
    ) as fleet:
        for sysid, address in ((1, fleet.addresses[0]), (2, fleet.addresses[1])):
            gcs = Probe(address)
            assert gcs.upload(sysid, items) == 0
            assert gcs.recv("MISSION_CURRENT", 2.0, lambda m: m.total == len(items) - 1) is not None
            assert gcs.command(sysid, REBOOT, 1) == ACCEPTED
            time.sleep(0.1)
            gcs.heartbeat()  # the rebooted vehicle forgot its peers: reconnect
            state = gcs.recv("MISSION_CURRENT", 3.0)
            if sysid == 1:
                assert state.mission_state == MissionState.NO_MISSION and state.total == 65535
                assert fleet.vehicles[0].mission_server.count() == 0
            else:
                assert state.mission_state == MissionState.NOT_STARTED and state.total == len(items) - 1
            gcs.close()


def test_sysid_routing_between_vehicles():
    with MockFleet(flight=UNGATED, count=3, speedup=5.0) as fleet:
        assert len(set(fleet.addresses)) == 3
        gcs = Probe(fleet.addresses[1])
        msgs = gcs.collect(1.2)
        assert msgs and {m.get_srcSystem() for m in msgs} == {2}
        assert gcs.command(3, ARM, 1, timeout_s=0.7) is None  # vehicle 2 ignores commands for 3
        assert not fleet.vehicle(3).state.armed and not fleet.vehicle(2).state.armed
        assert gcs.command(2, ARM, 1) == ACCEPTED
        assert fleet.vehicle(2).state.armed and not fleet.vehicle(1).state.armed
        gcs.close()


CLI = [sys.executable, "-m", "sitl_mock.cli", "--vehicles", "3", "--base-port", "0", "--speedup", "5"]


def _ignore_interrupts() -> None:
    """In the child before exec: SIGINT and SIGTERM ignored, as a background job of a
    non-interactive shell (or nohup) inherits them."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)


def _cli_session(check, stop_signal: int = signal.SIGINT) -> subprocess.Popen:
    """Start the sitl-mock CLI (interrupts inherited as ignored), wait for its 3 start lines, call
    ``check(port, proc)``, then send ``stop_signal`` and expect exit status 0. The CLI runs in its
    own process group, killed on the way out whatever happens (a failed check, a timeout); its
    stderr is drained by a thread, so that a chatty child never blocks on a full pipe instead of
    handling the signal."""
    with child(CLI, stderr=subprocess.PIPE, text=True, preexec_fn=_ignore_interrupts) as proc:
        lines: queue.Queue[str] = queue.Queue()
        threading.Thread(target=lambda: [lines.put(line) for line in proc.stderr], daemon=True).start()
        first = [lines.get(timeout=60) for _ in range(3)]
        assert [f"sysid {k}: udp 127.0.0.1:" in line for k, line in enumerate(first, 1)] == [True] * 3, first
        check(int(first[0].split("127.0.0.1:")[1].split()[0]), proc)
        proc.send_signal(stop_signal)
        assert proc.wait(timeout=30) == 0  # generous: a loaded 2-core CI machine
        assert any("stopped" in line for line in _drained(lines)), "no clean stop logged"
    return proc


def _drained(lines: queue.Queue) -> list[str]:
    out = []
    with contextlib.suppress(queue.Empty):
        while True:
            out.append(lines.get(timeout=1.0))
    return out


@pytest.mark.parametrize("stop_signal", [signal.SIGINT, signal.SIGTERM])
def test_cli_starts_vehicles_and_stops_on_interrupt(stop_signal):
    def heartbeat(port: int, proc: subprocess.Popen) -> None:
        gcs = Probe(("127.0.0.1", port))
        try:
            assert gcs.recv("HEARTBEAT", 3.0) is not None
        finally:
            gcs.close()

    proc = _cli_session(heartbeat, stop_signal)
    assert not group_alive(proc.pid)


def test_cli_child_is_killed_when_the_interrupt_test_fails():
    """A failing check never reaches the Ctrl-C: the CLI and its process group are killed anyway."""
    started = []

    def fail(port: int, proc: subprocess.Popen) -> None:
        started.append(proc)
        raise AssertionError("check failed")

    with pytest.raises(AssertionError, match="check failed"):
        _cli_session(fail)
    (proc,) = started
    assert proc.returncode == -signal.SIGKILL and not group_alive(proc.pid)


def test_fleet_in_the_callers_loop_with_the_gcs_stack():
    """`async with MockFleet` beside MavlinkLink: upload_fleet + start_fleet fly three vehicles to the end."""
    import asyncio

    from gcs_planner.mavlink.fleet import start_fleet, upload_fleet
    from gcs_planner.mavlink.link import MavlinkLink

    async def main() -> list:
        specs = [
            {"profile": "ardupilot"},
            {"profile": "px4"},
            {"profile": "px4", "vehicle_type": "fixed_wing"},
        ]
        async with MockFleet(flight=COMPLETES, vehicles=specs, speedup=60.0) as fleet:
            link = await MavlinkLink.open(*(f"udpout:{h}:{p}" for h, p in fleet.addresses))
            try:
                await link.wait_for(lambda m: m.get_type() == "HEARTBEAT" and m.get_srcSystem() == 3, 3.0)
                missions = {v.sysid: _mission(home_item=v.profile.home_at_seq0)[0] for v in fleet.vehicles}
                uploaded = await upload_fleet(link, missions)
                assert all(r.ok for r in uploaded.values()), uploaded
                started = await start_fleet(link, list(missions))
                assert all(r.ok for r in started.values()), started
                done: set[int] = set()
                deadline = asyncio.get_running_loop().time() + 20.0
                while len(done) < 3 and asyncio.get_running_loop().time() < deadline:
                    msg = await link.wait_for(lambda m: m.get_type() == "MISSION_CURRENT", 5.0)
                    if msg.mission_state == MissionState.COMPLETE:
                        done.add(msg.get_srcSystem())
            finally:
                await link.close()
            return [v.state for v in fleet.vehicles]

    states = asyncio.run(main())
    assert [s.mission_state for s in states] == [MissionState.COMPLETE] * 3
    assert [s.reached[-1] for s in states] == [6, 5, 5]  # the land item of each list


def test_scripted_mission_failure_and_duplicate_sysids():
    items, _ = _mission(home_item=True)
    with MockFleet(flight=UNGATED, vehicles=[{"sysid": 7}, {"sysid": 7}], speedup=5.0) as fleet:
        a, b = Probe(fleet.addresses[0]), Probe(fleet.addresses[1])
        assert {a.recv("HEARTBEAT").get_srcSystem(), b.recv("HEARTBEAT").get_srcSystem()} == {7}
        uids = []
        for probe in (a, b):
            assert probe.command(7, 512, 148) == ACCEPTED  # REQUEST_MESSAGE(AUTOPILOT_VERSION)
            uids.append(probe.recv("AUTOPILOT_VERSION").uid)
        assert uids[0] != uids[1]  # a GCS can tell the two apart
        fleet.set_mission_failure(7, "write_count_no_response")  # both vehicles with sysid 7
        assert a.upload(7, items, timeout_s=1.0) is None  # MISSION_COUNT ignored
        fleet.call(lambda: setattr(fleet.vehicles[0].mission_server, "failure", Failure.NONE))
        assert a.upload(7, items) == 0
        assert fleet.vehicles[0].mission_server.count() == len(items)
        assert fleet.vehicles[1].mission_server.count() == 0  # same sysid, separate vehicle
        assert b.upload(7, items, timeout_s=1.0) is None  # the failure was set on both
        a.close()
        b.close()


@pytest.mark.parametrize(("profile", "requests_per_datagram"), [("px4", [1] * 8), ("ardupilot", [8])])
def test_a_datagram_of_items_is_answered_as_the_autopilot_sends(profile, requests_per_datagram):
    """Eight items in one datagram: PX4 answers each with a MISSION_REQUEST_INT in a datagram of its
    own (measured on PX4 SITL v1.15.4, AutopilotProfile.frame_per_datagram), ArduPilot sends what
    its buffer holds: the eight requests in one datagram."""
    import socket

    with (
        MockFleet(count=1, profile=profile, speedup=1.0) as fleet,
        socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as gcs,
    ):
        gcs.bind(("127.0.0.1", 0))
        gcs.settimeout(5.0)
        mav, parser = mavlink.MAVLink(None, srcSystem=255, srcComponent=190), mavlink.MAVLink(None)
        to = fleet.vehicle(1).address
        items = [
            MissionItem(seq=k, frame=3, command=16, x=473_977_000 + k, y=85_455_000, z=20.0)
            for k in range(20)
        ]

        def send(*msgs) -> None:
            gcs.sendto(b"".join(m.pack(mav) for m in msgs), to)

        def requests() -> list[int]:
            got = parser.parse_buffer(gcs.recv(65535)) or []
            return [m.seq for m in got if m.get_type() in ("MISSION_REQUEST", "MISSION_REQUEST_INT")]

        send(
            mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3),
            mavlink.MAVLink_mission_count_message(1, 1, 20, 0),
        )
        while requests() != [0]:
            pass
        send(*(mavlink.MAVLink_mission_item_int_message(1, 1, *items[k].fields()) for k in range(8)))
        counts, asked = [], []
        while len(asked) < 8:
            got = requests()
            if got:
                counts.append(len(got))
                asked += got
    assert asked == list(range(1, 9)) and counts == requests_per_datagram
