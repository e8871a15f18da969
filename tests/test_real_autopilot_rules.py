"""The behaviours of real ArduCopter, ArduPlane and PX4 (docs/real-autopilots.md), as the mock
plays them by default, and the tool's answer to each: fly, upload --verify, clear, lost ACKs."""

from __future__ import annotations

import asyncio
import math
from dataclasses import replace
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink
from test_cli_mission import SCENARIO

import sitl_mock
from gcs_planner.cli import main
from gcs_planner.core import lockstep
from gcs_planner.core.errors import UserError
from gcs_planner.core.geo import Origin
from gcs_planner.flight import FlyOptions, fly
from gcs_planner.flight.limits import FlightLimits, check_limits, read_l1_params, read_limits
from gcs_planner.flight.ops import vehicle_quirks
from gcs_planner.flight.starts import CLIMB_RUN_PER_M
from gcs_planner.mavlink.command import CommandClient
from gcs_planner.mavlink.errors import CommandError
from gcs_planner.mavlink.link import MavlinkLink
from gcs_planner.mavlink.mission import MissionClient
from gcs_planner.mavlink.params import read_param
from gcs_planner.mavlink.preflight import arm_when_ready, request_streams
from gcs_planner.mavlink.vehicle_status import VehicleStatus
from gcs_planner.missions.wpl import loads_wpl
from gcs_planner.planning import load_scenario, plan_scenario
from gcs_planner.telemetry.reader import frame_msgid, read_flight
from gcs_planner.wire import codec
from sitl_mock.flight import AIRFRAMES
from sitl_mock.l1 import SITL_PLANE
from sitl_mock.mission_server import Failure
from sitl_mock.plan_fleet import MockVehicles

MISSIONS = Path(__file__).resolve().parents[1] / "missions"
ORIGIN = Origin(47.397742, 8.545594, 488.0)
# positions, a speed change, yaw (CONDITION_YAW; PX4 has none: a waypoint's yaw), loiter time,
# a camera shot (DIGICAM_CONTROL x = shooting command 1) and RTL; row 0 is the home
MIXED = """QGC WPL 110
0\t1\t0\t16\t0\t0\t0\t0\t47.397742\t8.545594\t488.0\t1
1\t0\t3\t22\t0\t0\t0\t0\t47.397742\t8.545594\t20.0\t1
2\t0\t3\t16\t2.5\t3\t0\t45\t47.398742\t8.545594\t25.34567\t1
3\t0\t3\t178\t1\t8\t-1\t0\t0\t0\t0\t1
{yaw}
5\t0\t3\t19\t5\t0\t40\t0\t47.398742\t8.546594\t25\t1
6\t0\t3\t203\t0\t0\t0\t0\t1\t0\t0\t1
7\t0\t3\t20\t0\t0\t0\t0\t0\t0\t0\t1
"""
YAW = {
    "ardupilot": "4\t0\t3\t115\t90\t20\t1\t0\t0\t0\t0\t1",
    "px4": "4\t0\t3\t16\t0\t0\t0\t-90\t47.399\t8.546\t25\t1",
}
PROFILES = [("ardupilot", "multirotor"), ("ardupilot", "fixed_wing"), ("px4", "multirotor")]


def _fly(scenario_name: str, autopilot: str, out: Path, **kw):
    scenario = load_scenario(MISSIONS / scenario_name)
    plan = plan_scenario(scenario)
    options = FlyOptions(out_dir=out, rrd=False, **kw)
    vehicles = MockVehicles(plan.vehicles, plan.origin, autopilot=autopilot)
    return lockstep.run(fly(scenario, plan, options, vehicles), lockstep=True)


@pytest.mark.parametrize(
    ("scenario", "autopilot"),
    [("straight_4uav.toml", "px4"), ("straight_2fw.toml", "ardupilot"), ("straight_2fw.toml", "px4")],
)
def test_fly_passes_against_each_autopilots_real_behaviour(scenario, autopilot, tmp_path):
    result = _fly(scenario, autopilot, tmp_path)
    assert result.passed, [(r.sysid, r.failures) for r in result.reports]
    assert all(r.completed for r in result.reports)
    assert set(result.end_states.values()) <= {"landed (disarmed)", "holding (mission complete)"}


def test_a_flight_ending_in_landings_is_logged_until_they_have_disarmed(tmp_path):
    """PX4 completes its mission at touchdown and disarms 2 s later (COM_DISARM_LAND): the flight
    waits for the disarm, so the end line says landed and the log holds each disarmed HEARTBEAT."""
    result = _fly("straight_4uav.toml", "px4", tmp_path)
    assert result.end_states == {s: "landed (disarmed)" for s in (1, 2, 3, 4)}, result.end_states
    flight = read_flight(tmp_path / "flight.mcap")
    for sysid in (1, 2, 3, 4):
        beats = [codec.decode(f.data) for f in flight.frames_of(sysid) if frame_msgid(f.data) == 0]
        assert not beats[-1].base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED


def test_a_failing_fly_leaves_every_vehicle_landed_or_returning_and_says_so(tmp_path):
    drift = {2: (0.0, 3.0)}
    result = _fly(
        "straight_4uav.toml",
        "ardupilot",
        tmp_path,
        drift_mps=drift,
        max_cross_track_m=5.0,
        timeout_factor=0.6,
    )
    assert not result.passed
    assert set(result.end_states) == {1, 2, 3, 4}
    assert all(s in ("landed (disarmed)", "returning (RTL)") for s in result.end_states.values()), (
        result.end_states
    )


def _fleet(profile: str, vehicle_type: str = "multirotor", speedup: float = 20.0, **kw):
    return sitl_mock.MockFleet(
        count=1, profile=profile, vehicle_type=vehicle_type, home=ORIGIN, speedup=speedup, **kw
    )


def test_arducopter_refuses_to_arm_until_ready_and_the_tool_waits_with_its_reason():
    async def run():
        async with _fleet("ardupilot") as fleet:
            link = await MavlinkLink.open(*(f"udpout:{h}:{p}" for h, p in fleet.addresses))
            try:
                await link.wait_for(lambda m: m.get_type() == "HEARTBEAT", 5.0)
                with pytest.raises(CommandError, match="FAILED"):
                    await CommandClient(link, 1, retries=0).arm()
                status = VehicleStatus(link, [1])
                reasons = []
                await arm_when_ready(link, status, 1, 120.0, 20.0, lambda s, r: reasons.append(r))
                assert "Need Position Estimate" in reasons[0] and fleet.vehicles[0].armed
                with pytest.raises(CommandError, match="DENIED"):  # ArduPilot: MISSION_START(0, 0) only
                    await CommandClient(link, 1).mission_start(1, 3)
            finally:
                await link.close()

    asyncio.run(run())


@pytest.mark.parametrize(("profile", "vehicle_type"), PROFILES)
def test_upload_verify_passes_on_a_mixed_mission_and_clear_all_clears_all_three(
    profile, vehicle_type, tmp_path, capsys
):
    path = tmp_path / "mixed.waypoints"
    path.write_text(MIXED.format(yaw=YAW[profile]))
    scenario = tmp_path / "s.toml"
    scenario.write_text(SCENARIO)  # bounds and a cylinder: fence and rally lists
    with _fleet(profile, vehicle_type) as fleet:
        host, port = fleet.addresses[0]
        argv = ["--connect", f"udpout:{host}:{port}", "--sysid", "1"]
        assert main(["upload", *argv, str(path), "--scenario", str(scenario), "--verify"]) == 0
        out = capsys.readouterr().out
        assert out.count(" yes") == 3, out
        server = fleet.vehicle(1).mission_server
        camera = [it for it in server.items() if it.command == 203]
        assert [it.x for it in camera] == [1]  # params 5/6 of a positionless command go unscaled
        assert main(["clear", *argv, "--type", "all"]) == 0
        assert server.count(1) == 0 and server.count(2) == 0 and server.count(0) <= 1  # ArduPilot keeps home


@pytest.mark.parametrize("profile", ["ardupilot", "px4"])
def test_a_lost_final_ack_ends_in_success_after_a_read_back(profile):
    items = loads_wpl(MIXED.format(yaw=YAW[profile])).items("ardupilot" if profile == "ardupilot" else "px4")

    async def run():
        async with _fleet(profile) as fleet:
            fleet.set_mission_failure(1, Failure.WRITE_FINAL_ACK_NO_RESPONSE)
            link = await MavlinkLink.open(*(f"udpout:{h}:{p}" for h, p in fleet.addresses))
            try:
                await link.wait_for(lambda m: m.get_type() == "HEARTBEAT", 5.0)
                result = await MissionClient(link, 1).upload(items)
                assert result.ack_lost and result.verified
            finally:
                await link.close()

    asyncio.run(run())


def test_arduplane_refuses_an_airspeed_outside_its_range_and_keeps_its_speed():
    """Plane::do_change_speed: an airspeed outside [AIRSPEED_MIN, AIRSPEED_MAX] is refused; the
    flight reads the range first (read_param) so that it never asks for one."""

    async def run():
        async with _fleet("ardupilot", "fixed_wing") as fleet:
            link = await MavlinkLink.open(*(f"udpout:{h}:{p}" for h, p in fleet.addresses))
            try:
                await link.wait_for(lambda m: m.get_type() == "HEARTBEAT", 5.0)
                quirks = vehicle_quirks(link, [1])
                (lim,) = (await read_limits(link, [1], quirks)).values()
                assert (lim.min_mps, lim.max_mps) == (12.0, 30.0)  # the mock airframe's range
                assert await read_param(link, 1, "NO_SUCH_PARAM", retry_s=0.2) is None
                kin, command = fleet.vehicles[0]._world.kin, CommandClient(link, 1, retries=0)
                before = float(kin.speed_cmd[0])
                with pytest.raises(CommandError, match="FAILED"):
                    await command.command_long(mavlink.MAV_CMD_DO_CHANGE_SPEED, 0, 40.0, -1)
                assert float(kin.speed_cmd[0]) == before
                await command.command_long(mavlink.MAV_CMD_DO_CHANGE_SPEED, 0, 25.0, -1)
                assert float(kin.speed_cmd[0]) == 25.0
            finally:
                await link.close()

    asyncio.run(run())


def test_a_plane_on_l1_guidance_gives_its_period_and_roll_lag_and_a_pursuit_plane_none():
    """ArduPlane's NAVL1_PERIOD and RLL2SRV_TCONST (plane.parm: 15 s, 0.25 s) say how a plane
    follows waypoints; the flight reads them to shape its missions (l1_guidance). The mock's
    pursuit plane, which has no L1 guidance, answers 0 and is left alone."""
    planes = [
        dict(sysid=s, home=ORIGIN, vehicle_type="fixed_wing", profile="ardupilot",
             airframe=replace(AIRFRAMES["fixed_wing"], l1=l1))
        for s, l1 in ((1, SITL_PLANE), (2, None))
    ]  # fmt: skip

    async def run():
        async with sitl_mock.MockFleet(vehicles=planes, home=ORIGIN, speedup=20.0) as fleet:
            link = await MavlinkLink.open(*(f"udpout:{h}:{p}" for h, p in fleet.addresses))
            try:
                for sysid in (1, 2):
                    heard = lambda m, s=sysid: m.get_type() == "HEARTBEAT" and m.get_srcSystem() == s  # noqa: E731
                    await link.wait_for(heard, 5.0)
                quirks = vehicle_quirks(link, [1, 2])
                assert await read_l1_params(link, [1, 2], quirks) == {1: (15.0, 0.25)}
            finally:
                await link.close()

    asyncio.run(run())


def test_a_plan_beyond_a_planes_limits_is_refused_naming_the_parameter():
    plane = plan_scenario(load_scenario(MISSIONS / "straight_2fw.toml")).vehicles[0]
    names = ("AIRSPEED_MIN", "AIRSPEED_MAX", "ROLL_LIMIT_DEG")
    top = float(max(plane.speeds_mps))
    roomy = FlightLimits(names, 1.0, 2 * top, 89.0)
    check_limits([plane], {plane.sysid: roomy}, 1.5)
    cases = [
        (FlightLimits(names, 1.0, top * 1.2, 89.0), f"AIRSPEED_MAX is {top * 1.2:g} m/s, but the flight"),
        (FlightLimits(names, top + 1.0, 2 * top, 89.0), "AIRSPEED_MIN is"),
        (FlightLimits(names, 1.0, 2 * top, 1.0), "ROLL_LIMIT_DEG is 1 deg, but turns of"),
    ]
    for limits, message in cases:
        with pytest.raises(UserError, match=message):
            check_limits([plane], {plane.sysid: limits}, 1.5)


def test_arduplane_reports_no_position_until_its_gps_is_found_and_the_tool_keeps_none_of_it():
    """ArduPilot sends GLOBAL_POSITION_INT at (0, 0) before it has a position (the first 10 s on
    SITL) and no HOME_POSITION: the mock plays it; the flight's tracks, the live legs' telemetry and
    the home altitude skip those reports."""
    from gcs_planner.flight.coalition.live_legs import Telemetry
    from gcs_planner.flight.ops import TrackRecorder, boot_clock

    async def run():
        async with _fleet("ardupilot", "fixed_wing", speedup=2.0) as fleet:  # 5 s wall before the fix
            link = await MavlinkLink.open(*(f"udpout:{h}:{p}" for h, p in fleet.addresses))
            recorder, telemetry = TrackRecorder(ORIGIN, boot_clock, [1]), Telemetry({1})
            status = VehicleStatus(link, [1])
            seen = []

            def on_frame(msg, raw: bytes, t_s: float) -> None:
                kind = msg.get_type()
                if kind in ("GLOBAL_POSITION_INT", "HOME_POSITION"):
                    home = status.tracks[1].home_amsl_m
                    seen.append((kind, getattr(msg, "time_boot_ms", None), home, getattr(msg, "lat", None)))

            for subscriber in (recorder.on_frame, telemetry.on_frame, on_frame):
                link.subscribe(subscriber)
            try:
                await link.wait_for(lambda m: m.get_type() == "HEARTBEAT", 5.0)
                await request_streams(link, [1])
                await link.wait_for(lambda m: getattr(m, "time_boot_ms", 0) > 11_000 and m.lat != 0, 30.0)
            finally:
                await link.close()
        return seen, recorder.samples[1], list(telemetry.rows[1])

    seen, samples, rows = asyncio.run(run())
    positions = [s for s in seen if s[0] == "GLOBAL_POSITION_INT"]
    before = [s for s in positions if s[1] < 10_000]
    assert before and all(s[3] == 0 for s in before)  # (0, 0) before the fix
    first_home = next(i for i, s in enumerate(seen) if s[0] == "HOME_POSITION")
    assert first_home > 0 and seen[first_home - 1][1] >= 10_000  # no HOME_POSITION before the fix
    assert all(s[2] is None or abs(s[2] - ORIGIN.alt_m) < 1.0 for s in seen)  # never a home at 0 m
    assert len(samples) == len(positions) - len(before) > 0 and len(rows) > 0
    assert all(abs(lat - ORIGIN.lat_deg) < 0.01 for _, lat, _, _ in samples)
    assert all(abs(lat - ORIGIN.lat_deg) < 0.01 for _, lat, _, _, _ in rows)


def test_a_vehicle_not_ready_to_arm_is_said_to_wait_for_its_pre_arm_text_not_its_last_words():
    """ArduPlane in TAKEOFF mode says "Mode TAKEOFF" after the GCS's mode change; while its pre-arm
    checks fail, the wait line gives its last pre-arm text (PreArm / Arm / Preflight), not that."""

    async def run():
        async with _fleet("ardupilot", "fixed_wing", speedup=5.0) as fleet:
            link = await MavlinkLink.open(*(f"udpout:{h}:{p}" for h, p in fleet.addresses))
            status, reasons = VehicleStatus(link, [1]), []
            try:
                await link.wait_for(lambda m: m.get_type() == "HEARTBEAT", 5.0)
                await request_streams(link, [1])
                await link.wait_for(lambda m: m.get_type() == "SYS_STATUS", 5.0)
                fleet.vehicles[0].statustext("PreArm: Need Position Estimate")
                fleet.vehicles[0].statustext("Mode TAKEOFF")
                await link.wait_for(lambda m: m.get_type() == "STATUSTEXT" and m.text.startswith("Mode"), 5.0)
                await arm_when_ready(link, status, 1, 120.0, 5.0, lambda s, r: reasons.append(r))
            finally:
                await link.close()
        return reasons

    reasons = asyncio.run(run())
    assert reasons and set(reasons) == {"PreArm: Need Position Estimate"}, reasons


@pytest.mark.parametrize(
    ("scenario", "run_per_m"), [("straight_2fw.toml", CLIMB_RUN_PER_M), ("straight_4uav.toml", 0.0)]
)
def test_fly_homes_puts_a_plane_one_climb_run_behind_its_first_waypoint_and_a_copter_under_it(
    scenario, run_per_m, capsys, tmp_path
):
    """A SITL plane's take-off climbs on its launch course (TAKEOFF mode): started at its first
    waypoint, one flew 70 m off its route turning back to it; a multirotor climbs straight up."""
    from gcs_planner.core.geo import geodetic_to_enu

    out = tmp_path / "out"
    assert main(["fly", str(MISSIONS / scenario), "--homes", "-o", str(out)]) == 0
    plan = plan_scenario(load_scenario(MISSIONS / scenario))
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == len(plan.vehicles) and not out.exists()
    for line, vp in zip(lines, plan.vehicles):
        lat, lon, alt, heading = (float(v) for v in line.split("--home ")[1].split()[0].split(","))
        x, y, _ = geodetic_to_enu(lat, lon, alt, plan.origin)
        (x0, y0, z0), (x1, y1, _) = vp.waypoints[0], vp.waypoints[1]
        assert abs(alt - plan.origin.alt_m) < 0.5 and f"MAV_SYSID {vp.sysid}" in line
        assert f"PX4_HOME_LAT={lat:.7f} PX4_HOME_LON={lon:.7f}" in line and f"MAV_SYS_ID {vp.sysid}" in line
        sih = line.split("PX4 SIH: ")[1]  # SIH_LOC_LAT0 / LON0 are integers of 1e-7 degrees
        assert f"PX4_HOME_LAT={round(lat * 1e7)} PX4_HOME_LON={round(lon * 1e7)}" in sih
        assert math.hypot(x0 - x, y0 - y) == pytest.approx(z0 * run_per_m, abs=0.5)
        assert abs(math.remainder(heading - math.degrees(math.atan2(x1 - x0, y1 - y0)), 360.0)) < 1.0


@pytest.mark.parametrize("run_m", [150.0, 0.0])
def test_arduplane_takeoff_mode_ends_its_straight_climb_at_tkoff_dist_and_climbs_on_circling(run_m):
    """The mock's TAKEOFF mode as ArduPlane's ModeTakeoff::update: the straight climb ends 2 m below
    TKOFF_ALT or at TKOFF_DIST from its start, whichever first (0: at once), and the plane climbs
    on circling the point TKOFF_DIST along its climb-out (SITL 4.8.0-dev left its climb-out after
    the default 200 m, docs/real-autopilots.md)."""

    async def climb() -> tuple:
        ready = {"arm_ready_s": 0.0, "position_fix_s": 0.0}
        async with sitl_mock.MockFleet(
            count=1, profile="ardupilot", vehicle_type="fixed_wing", home=ORIGIN, flight=ready
        ) as fleet:
            plane = fleet.vehicle(1)
            plane.params.update(TKOFF_ALT=100.0, TKOFF_DIST=run_m)
            assert plane._set_mode_name("TAKEOFF", start=False)
            assert plane._cmd_arm(1.0, 0.0) == 0  # ACCEPTED
            start = fleet.positions_enu()[0].copy()
            await asyncio.sleep(1.0)
            heading = fleet.positions_enu()[0] - start
            await asyncio.sleep(120.0)  # flight time: lockstep
            return start, heading, fleet.positions_enu()[0]

    start, heading, end = lockstep.run(climb(), True)
    loiter_r = AIRFRAMES["fixed_wing"].loiter_radius_m
    centre = start[:2] + run_m * heading[:2] / max(math.hypot(*heading[:2]), 1e-9)
    assert end[2] - start[2] == pytest.approx(98.0, abs=1.0)  # up, in the end
    assert math.hypot(*(end[:2] - centre)) < 1.5 * loiter_r  # circling TKOFF_DIST along the climb-out


def test_a_relative_plan_is_judged_on_the_height_above_home_whatever_the_homes_amsl_altitude():
    """PX4 SIH v1.15 starts at 32 m AMSL unless SIH_LOC_H0 is set (PX4_HOME_ALT is not applied), a
    real GPS's AMSL altitude is off by metres: a vehicle flying a "relative" plan is told heights
    above its home, so its track is its relative_alt over the origin's altitude (it was recorded at
    -436 m, "never airborne", before); a plan over a site ("amsl") keeps the AMSL altitude."""
    from gcs_planner.flight.ops import TrackRecorder, boot_clock

    recorder = TrackRecorder(ORIGIN, boot_clock, [1, 2], relative=[1])  # origin 488 m AMSL
    for sysid in (1, 2):
        for k in range(3):
            msg = mavlink.MAVLink_global_position_int_message(
                1000 * k, int(ORIGIN.lat_deg * 1e7), int(ORIGIN.lon_deg * 1e7), 52_000, 20_000, 0, 0, 0, 0
            )
            msg._header = mavlink.MAVLink_header(msg.id, srcSystem=sysid, srcComponent=1)
            recorder.on_frame(msg, b"", 0.0)
    tracks = recorder.tracks()
    assert tracks[1].positions[:, 2] == pytest.approx(20.0, abs=0.01)
    assert tracks[2].positions[:, 2] == pytest.approx(52.0 - 488.0, abs=0.01)
