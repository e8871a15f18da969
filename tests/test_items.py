"""Plan -> mission items and validation: structure, rounding, profiles and every bad-input case."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs_planner.core.errors import UserError
from gcs_planner.core.geo import Origin, geodetic_to_enu
from gcs_planner.missions.items import (
    deg_to_e7,
    e7,
    half_away,
    plan_to_items,
    rally_items,
    round_half_away,
    scenario_fence_items,
    scenario_rally_items,
)
from gcs_planner.missions.validate import MissionValidationError, validate_items
from gcs_planner.model.plan import VehiclePlan
from gcs_planner.planning import parse_scenario, plan_scenario
from gcs_planner.wire.types import MissionItem, MissionType

ORIGIN = Origin(47.397742, 8.545594, 488.0)
REL = mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT


def vehicle_plan(**kw) -> VehiclePlan:
    wps = np.array([[0.0, 0.0, 0.0], [100.0, 0.0, 20.0], [200.0, 50.0, 30.0], [300.0, 50.0, 30.0]])
    speeds = np.array([0.0, 10.0, 10.0, 6.0])
    seg = np.linalg.norm(np.diff(wps, axis=0), axis=1)
    times = np.concatenate([[0.0], np.cumsum(seg / speeds[1:])])
    args = dict(
        vehicle_id="uav1",
        sysid=1,
        waypoints=wps,
        times_s=times,
        speeds_mps=speeds,
        path=wps,
        path_times_s=times,
    )
    args.update(kw)
    return VehiclePlan(**args)


def commands(items):
    return [it.command for it in items]


def test_round_half_away_from_zero_not_truncation_or_bankers():
    halves = np.array([0.5, 1.5, 2.5, -0.5, -1.5, -2.5, 2.4999, -2.4999])
    assert round_half_away(halves).tolist() == [1, 2, 3, -1, -2, -3, 2, -2]
    assert round(2.5) == 2  # Python's own rounding would be wrong here
    # truncation (int()) would give 473977418 here, one unit (1.1 cm) short
    assert int(47.39774189 * 1e7) == 473977418
    assert deg_to_e7(47.39774189) == 473977419
    assert deg_to_e7(-47.39774189) == -473977419
    assert deg_to_e7(-122.08404009) == -1220840401
    values = np.random.default_rng(3).uniform(-180, 180, 2000).round(8)
    assert [e7(v) for v in values] == deg_to_e7(values).tolist()  # scalar fast path agrees
    assert [half_away(v) for v in halves] == round_half_away(halves).tolist()


def test_ardupilot_mission_structure_and_coordinates():
    vp = vehicle_plan()
    items = plan_to_items(vp, ORIGIN, "ardupilot")
    C = mavlink
    assert commands(items) == [
        C.MAV_CMD_NAV_WAYPOINT,  # home
        C.MAV_CMD_NAV_TAKEOFF,
        C.MAV_CMD_DO_CHANGE_SPEED,
        C.MAV_CMD_NAV_WAYPOINT,
        C.MAV_CMD_NAV_WAYPOINT,
        C.MAV_CMD_DO_CHANGE_SPEED,  # 10 -> 6 m/s on the last leg only
        C.MAV_CMD_NAV_WAYPOINT,
        C.MAV_CMD_NAV_LAND,
    ]
    assert [it.seq for it in items] == list(range(len(items)))
    assert [it.current for it in items] == [1] + [0] * (len(items) - 1)
    home = items[0]
    assert (home.frame, home.x, home.y, home.z) == (mavlink.MAV_FRAME_GLOBAL, 473977420, 85455940, 488.0)
    takeoff = items[1]
    assert takeoff.frame == REL and takeoff.z == 20.0  # start on the ground: climb to waypoint 1's altitude
    speeds = [it for it in items if it.command == C.MAV_CMD_DO_CHANGE_SPEED]
    assert [(s.param1, s.param2) for s in speeds] == [(1.0, 10.0), (1.0, 6.0)]  # ground speed, m/s
    wps = [it for it in items if it.command == C.MAV_CMD_NAV_WAYPOINT][1:]
    assert all(w.frame == REL and w.param2 == vp.acceptance_radius_m and w.param3 == 0 for w in wps)
    # positions round-trip through geodesy to the plan's ENU to well within 1 cm (degE7 ~ 1.1 cm)
    e, n, _ = geodetic_to_enu(
        np.array([w.x for w in wps]) / 1e7, np.array([w.y for w in wps]) / 1e7, 0.0, ORIGIN
    )
    np.testing.assert_allclose(np.c_[e, n], vp.waypoints[1:, :2], atol=0.01)
    assert [w.z for w in wps] == vp.waypoints[1:, 2].tolist()
    land = items[-1]
    assert (land.x, land.y, land.z) == (wps[-1].x, wps[-1].y, 0.0)


def test_px4_profile_has_no_home_and_first_item_current():
    ap = plan_to_items(vehicle_plan(), ORIGIN, "ardupilot")
    px4 = plan_to_items(vehicle_plan(), ORIGIN, "px4")
    assert px4[0].command == mavlink.MAV_CMD_NAV_TAKEOFF and px4[0].current == 1
    assert [replace(it, seq=0, current=0) for it in px4] == [replace(it, seq=0, current=0) for it in ap[1:]]


def test_delayed_takeoff_final_actions_and_fixed_wing():
    items = plan_to_items(vehicle_plan(takeoff_delay_s=42.0, final_action="rtl"), ORIGIN, "px4")
    assert items[0].command == mavlink.MAV_CMD_NAV_DELAY and items[0].param1 == 42.0 and items[0].current == 1
    assert items[1].command == mavlink.MAV_CMD_NAV_TAKEOFF
    assert items[-1].command == mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH
    fw = plan_to_items(
        vehicle_plan(final_action="loiter", vehicle_type="fixed_wing", turn_radius_m=60.0),
        ORIGIN,
        "ardupilot",
    )
    assert fw[1].param1 == 15.0  # minimum take-off pitch
    assert [it.param1 for it in fw if it.command == mavlink.MAV_CMD_DO_CHANGE_SPEED] == [0.0, 0.0]  # airspeed
    assert fw[-1].command == mavlink.MAV_CMD_NAV_LOITER_UNLIM and fw[-1].param3 == 60.0 and fw[-1].z == 30.0


def test_zero_length_leg_becomes_hold_time():
    wps = np.array([[0, 0, 10.0], [50, 0, 10.0], [50, 0, 10.0], [100, 0, 10.0]])
    times = np.array([0.0, 5.0, 17.0, 22.0])
    vp = vehicle_plan(waypoints=wps, times_s=times, speeds_mps=[0, 10, 0, 10], path=wps, path_times_s=times)
    items = plan_to_items(vp, ORIGIN, "px4")
    assert items[0].z == 10.0  # airborne start: take off to the start's altitude
    wp = [it for it in items if it.command == mavlink.MAV_CMD_NAV_WAYPOINT]
    assert len(wp) == 2 and wp[0].param1 == pytest.approx(12.0) and wp[1].param1 == 0.0


@pytest.mark.parametrize(
    ("kw", "field"),
    [
        ({"final_action": "crash"}, "final_action"),
        ({"takeoff_delay_s": -1.0}, "takeoff_delay_s"),
        ({"speeds_mps": [0.0, 10.0, 0.0, 6.0]}, "speeds_mps"),
    ],
)
def test_plan_errors_name_the_field(kw, field):
    with pytest.raises(MissionValidationError) as err:
        plan_to_items(vehicle_plan(**kw), ORIGIN)
    assert err.value.field == field and field in str(err.value)
    assert isinstance(err.value, UserError)


def test_nan_waypoint_is_rejected():
    vp = vehicle_plan()
    vp.waypoints[2, 2] = math.nan
    with pytest.raises(MissionValidationError, match="waypoints"):
        plan_to_items(vp, ORIGIN)


# ----------------------------------------------------------------- validate_items


def good() -> list[MissionItem]:
    return plan_to_items(vehicle_plan(), ORIGIN, "ardupilot")


def test_valid_lists_pass():
    validate_items(good())
    validate_items([])  # count 0 clears a mission
    validate_items(scenario_rally_items(parse_scenario(SCENARIO)))


@pytest.mark.parametrize(
    ("seq", "change", "field"),
    [
        (3, {"x": 910_000_000}, "x"),  # lat 91
        (3, {"x": -900_000_001}, "x"),
        (3, {"y": 1_800_000_001}, "y"),
        (3, {"z": math.nan}, "z"),
        (3, {"z": math.inf}, "z"),
        (3, {"param2": math.inf}, "param2"),
        (3, {"command": 70000}, "command"),  # not a uint16 (an unknown id is passed through)
        (3, {"frame": 99}, "frame"),
        (3, {"seq": 7}, "seq"),
        (3, {"current": 1}, "current"),  # second current item
        (3, {"autocontinue": 2}, "autocontinue"),
        (3, {"mission_type": MissionType.FENCE}, "mission_type"),
        (3, {"x": 47.5}, "x"),  # float where degE7 int is required
        (0, {"current": 0}, "current"),  # no current item at all
    ],
)
def test_validation_names_item_and_field(seq, change, field):
    items = good()
    items[seq] = replace(items[seq], **change)
    with pytest.raises(MissionValidationError) as err:
        validate_items(items)
    assert err.value.field == field
    assert field in str(err.value)
    if field != "current" or seq:
        assert err.value.seq == seq and f"item {seq}" in str(err.value)


def test_nan_param_means_default_and_is_allowed():
    items = good()
    items[3] = replace(items[3], param4=math.nan)  # QGC's "keep yaw"
    validate_items(items)


def test_positionless_commands_skip_the_latitude_check():
    items = good()
    assert items[2].command == mavlink.MAV_CMD_DO_CHANGE_SPEED and items[2].x == 0
    validate_items(items)


def test_count_limits():
    base = MissionItem(0, REL, mavlink.MAV_CMD_NAV_WAYPOINT, 0, 1, x=473977420, y=85455940, z=20.0)
    many = [replace(base, seq=i, current=int(i == 0)) for i in range(70000)]
    with pytest.raises(MissionValidationError, match="65535") as err:
        validate_items(many)
    assert err.value.field == "count"
    with pytest.raises(MissionValidationError, match="capacity 50"):
        validate_items(many[:51], capacity=50)
    validate_items(many[:50], capacity=50)


# ----------------------------------------------------------------- fence and rally

SCENARIO = {
    "origin": {"lat_deg": 47.397742, "lon_deg": 8.545594, "alt_m": 488.0},
    "planner": {"name": "straight"},
    "vehicles": [
        {"id": "a", "sysid": 1, "start": [0.0, 0.0, 0.0], "goal": [100.0, 0.0, 20.0], "min_alt_m": 15.0},
        {"id": "b", "sysid": 2, "start": [0.0, 30.0, 0.0], "goal": [100.0, 30.0, 20.0]},
    ],
    "obstacles": {
        "cylinders": [{"x": 50.0, "y": 10.0, "radius_m": 8.0, "buffer_m": 2.0, "z_max_m": 40.0}],
        "hemispheres": [{"x": 200.0, "y": -50.0, "radius_m": 30.0}],
    },
    "bounds": {"x": [-100.0, 400.0], "y": [-200.0, 300.0], "z": [0.0, 120.0]},
}


def test_fence_from_scenario():
    sc = parse_scenario(SCENARIO)
    fence = scenario_fence_items(sc)
    C = mavlink
    assert (
        commands(fence)
        == [C.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION] * 4 + [C.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION] * 2
    )
    assert all(it.mission_type == MissionType.FENCE for it in fence) and [it.seq for it in fence] == list(
        range(6)
    )
    assert [it.param1 for it in fence] == [4.0] * 4 + [10.0, 30.0]  # radius + buffer; dome footprint
    e, n, _ = geodetic_to_enu(
        np.array([it.x for it in fence]) / 1e7, np.array([it.y for it in fence]) / 1e7, 0, ORIGIN
    )
    np.testing.assert_allclose(
        np.c_[e, n], [[-100, -200], [400, -200], [400, 300], [-100, 300], [50, 10], [200, -50]], atol=0.01
    )


def test_rally_points():
    sc = parse_scenario(SCENARIO)
    rally = scenario_rally_items(sc)
    assert commands(rally) == [mavlink.MAV_CMD_NAV_RALLY_POINT] * 2
    assert [it.z for it in rally] == [15.0, 10.0] and all(
        it.mission_type == MissionType.RALLY for it in rally
    )
    assert rally_items([], ORIGIN) == []
    plan = plan_scenario(sc)
    own = scenario_rally_items(sc, plan.vehicles[1])  # one vehicle's upload: its own start only
    assert len(own) == 1 and (own[0].x, own[0].y, own[0].z) == (rally[1].x, rally[1].y, rally[1].z)


def _shallow_arc_plan(turn_deg: float, vehicle_type: str = "multirotor", r: float = 15.0) -> VehiclePlan:
    """Two 100 m legs joined by a Dubins arc of radius ``r`` kept as its start, middle and end."""
    half = math.radians(turn_deg) / 2
    a0 = np.array([0.0, 0.0])
    arc_start = a0 + [100.0, 0.0]
    centre = arc_start + [0.0, r]
    angles = np.array([-math.pi / 2, -math.pi / 2 + half, -math.pi / 2 + 2 * half])
    arc = centre + r * np.c_[np.cos(angles), np.sin(angles)]
    end = arc[-1] + 100.0 * np.array([math.cos(2 * half), math.sin(2 * half)])
    xy = np.vstack([a0, arc, end])
    wps = np.c_[xy, np.full(len(xy), 30.0)]
    seg = np.linalg.norm(np.diff(wps, axis=0), axis=1)
    times = np.concatenate([[0.0], np.cumsum(seg / 10.0)])
    speeds = np.r_[0.0, np.full(len(seg), 10.0)]
    return vehicle_plan(waypoints=wps, times_s=times, speeds_mps=speeds, path=wps, path_times_s=times,
                        vehicle_type=vehicle_type, turn_radius_m=r)  # fmt: skip


def _route(items) -> np.ndarray:
    """ENU of the waypoints after the take-off."""
    nav = [it for it in items if it.command == mavlink.MAV_CMD_NAV_WAYPOINT]
    return np.array([geodetic_to_enu(it.x * 1e-7, it.y * 1e-7, it.z, ORIGIN)[:2] for it in nav])


def test_a_shallow_arc_is_one_corner_where_its_straight_legs_meet():
    """A 5-degree arc (two 0.65 m legs): ArduCopter SITL slowed to ~1 m/s at each such waypoint
    to be able to stop at the next; the mission turns once, at the legs' meeting point."""
    vp = _shallow_arc_plan(5.0)
    route = _route(plan_to_items(vp, ORIGIN, "px4"))
    assert len(route) == 2  # the corner and the end; the arc's three points are one
    corner = route[0]
    assert corner[1] == pytest.approx(0.0, abs=0.01)  # on the first leg's line (y = 0) ...
    assert corner[0] == pytest.approx(
        100.0 + 15.0 * math.tan(math.radians(2.5)), abs=0.01
    )  # ... where it meets
    assert np.linalg.norm(route[-1] - vp.waypoints[-1, :2]) < 0.01
    assert len(_route(plan_to_items(_shallow_arc_plan(48.0), ORIGIN, "px4"))) == 2  # 2 m off: one corner
    wide = _route(plan_to_items(_shallow_arc_plan(90.0, r=10.0), ORIGIN, "px4"))
    assert len(wide) == 4  # a 90-degree arc of 10 m (7.7 m legs): its corner is 4.1 m off, the arc stays
    plane = _route(plan_to_items(_shallow_arc_plan(5.0, "fixed_wing"), ORIGIN, "px4"))
    assert len(plane) == 4  # a fixed wing flies its own turns (L1)


def test_a_shallow_arc_with_a_speed_change_keeps_its_waypoints():
    """A 4-D plan slows on an arc: merging it would drop the DO_CHANGE_SPEED of its legs."""
    vp = _shallow_arc_plan(5.0)
    vp = replace(vp, speeds_mps=np.r_[0.0, 10.0, 6.0, 6.0, 10.0])
    assert len(_route(plan_to_items(vp, ORIGIN, "px4"))) == 4
