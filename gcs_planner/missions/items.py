"""Plan -> MAVLink mission items (MISSION_ITEM_INT), fence and rally items from a scenario.

One vehicle's plan becomes, in order:

    [home]  [NAV_DELAY]  NAV_TAKEOFF  (DO_CHANGE_SPEED?  NAV_WAYPOINT)*  LAND | RTL | LOITER_UNLIM

Choices where MAVLink or the autopilots leave room (all documented here, nowhere else):
- Frames: items with a position use GLOBAL_RELATIVE_ALT_INT (z = metres above home = ENU up about
  the plan origin), or MAV_FRAME_GLOBAL (z = ENU up + the origin's altitude AMSL) for a vehicle
  plan whose ``altitude_frame`` is "amsl" (plans on a site: each vehicle's home is on its own
  ground, so altitudes above home would shift by its height above the origin; NAV_LAND stays a
  relative 0); commands without a position (DO_CHANGE_SPEED, NAV_DELAY, RTL) use
  MAV_FRAME_MISSION with x = y = 0, as QGroundControl and MAVSDK send them (PX4 rejects some
  of them in a global frame).
- Home (ArduPilot profile only): seq 0 is a NAV_WAYPOINT at the plan origin in MAV_FRAME_GLOBAL
  with z = the origin's altitude AMSL, as Mission Planner writes it and ArduPilot returns it.
  ArduPilot replaces it with its own home on upload. PX4 missions carry no home item.
- current = 1 on seq 0 (the home item on ArduPilot, the first real item on PX4).
- lat/lon: degE7 rounded half away from zero (:func:`deg_to_e7`); truncation (``int()``, as
  pymavlink's mavwp does) biases every coordinate towards 0 by up to 1.1 cm.
- Take-off: at the first waypoint's horizontal position, to its altitude if it is airborne
  (>= ``MIN_TAKEOFF_ALT_M``), otherwise to the second waypoint's altitude. Fixed wings get a
  minimum take-off pitch of ``FIXED_WING_TAKEOFF_PITCH_DEG`` in param1.
- Delayed take-off: ``takeoff_delay_s > 0`` becomes MAV_CMD_NAV_DELAY (param1 = delay [s],
  param2..4 = -1: no UTC time) before the take-off, so the vehicle waits on the ground after the
  fleet-wide MISSION_START. Both ArduCopter and PX4 execute NAV_DELAY; it is the documented way to
  delay a take-off in ArduCopter.
- Speed: DO_CHANGE_SPEED before the first leg and before every leg whose planned speed differs from
  the last one commanded by more than ``SPEED_TOLERANCE_MPS``. Speed type (param1): ground speed
  (1) for multirotors, airspeed (0) for fixed wings (ArduPlane reads a ground-speed change as a
  minimum ground speed); param3 = -1 keeps the throttle.
- Waypoints: param2 = the plan's acceptance radius [m], param3 = 0 (pass through, no orbit),
  param4 (yaw) = 0; ArduCopter ignores it and PX4's default MIS_YAWMODE points the nose at the
  next waypoint. NaN is never emitted, so a downloaded list compares equal to the uploaded one.
- Corners (multirotors): a run of legs shorter than ``CORNER_LEG_M`` between two longer ones, all
  at one speed (a Dubins arc of a few degrees, kept by the planner as its start, middle and end,
  0.6-2.4 m apart) becomes one waypoint where the longer legs' lines meet, when that point is within
  ``CORNER_DEV_M`` of the run's middle point: ArduCopter slows at every waypoint to be able to
  stop at the next one, and on SITL such 1 m legs took a 10 m/s copter down to 0.3-1.3 m/s at each
  corner; at the meeting point the autopilot turns once, rounding it as it rounds any corner.
- Dwell: a zero-length leg in the plan (the same point twice, later in time) is a wait; it becomes
  the hold time (param1) of the previous waypoint, or NAV_LOITER_TIME for a fixed wing, which
  cannot hover.
- Final action: "land" lands at ``plan.land_point`` (z = 0): under the last waypoint for a
  multirotor; for a fixed wing a land point one glide-slope run ahead on the last leg (the
  approach is outside the planned path, checked only by the fence; no DO_LAND_START: ArduPlane
  refuses to arm with one while RTL_AUTOLAND is 0, docs/real-autopilots.md); "rtl" is NAV_RETURN_TO_LAUNCH,
  "loiter" is NAV_LOITER_UNLIM over the last waypoint (radius = turn radius for fixed wings).
- Fence (mission_type 1): the scenario's x/y bounds (a site's area) as an inclusion polygon, each
  cylinder (radius + buffer) and each radar dome (its footprint) as an exclusion circle, a site's
  no-fly zones as exclusion polygons, in
  MAV_FRAME_GLOBAL as QGroundControl sends fences; for one vehicle's plan only the obstacles its
  path keeps out of (gcs_planner/safety/geofence.py: a 2-D fence cannot let a vehicle over a tower).
- Rally (mission_type 2): one point over each vehicle's start at its min_alt_m.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import replace

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs_planner.autopilots import Conventions
from gcs_planner.core.geo import Origin, enu_to_geodetic
from gcs_planner.missions.validate import MissionValidationError, validate_items
from gcs_planner.model.plan import VehiclePlan, land_point
from gcs_planner.model.scenario import Scenario
from gcs_planner.safety.geofence import vehicle_geofence
from gcs_planner.wire.types import MissionItem, MissionType
from gcs_planner.wire.units import SPEED_AIRSPEED, SPEED_GROUNDSPEED, e7, half_away

__all__ = [
    "AUTOPILOTS",
    "MissionValidationError",
    "deg_to_e7",
    "e7",
    "half_away",
    "mission_waypoints",
    "plan_to_items",
    "rally_items",
    "round_half_away",
    "scenario_fence_items",
    "scenario_rally_items",
    "validate_items",
]

AUTOPILOTS = tuple(Conventions)
FINAL_ACTIONS = ("land", "rtl", "loiter")
MIN_TAKEOFF_ALT_M = 1.0
FIXED_WING_TAKEOFF_PITCH_DEG = 15.0
SPEED_TOLERANCE_MPS = 0.05
DWELL_LEG_M = 0.01  # a leg shorter than this is a wait, not a move
CORNER_LEG_M = 10.0  # a multirotor's legs shorter than this between longer ones are one corner
CORNER_DEV_M = 3.0  # ... where the corner point is this near the planned path

REL = mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
NO_FRAME = mavlink.MAV_FRAME_MISSION


def round_half_away(values) -> np.ndarray:
    """Round to the nearest integer, halves away from zero (2.5 -> 3, -2.5 -> -3); int64 array."""
    a = np.asarray(values, dtype=float)
    return (np.sign(a) * np.floor(np.abs(a) + 0.5)).astype(np.int64)


def deg_to_e7(deg) -> np.ndarray:
    """Degrees -> MAVLink int degE7, correctly rounded (half away from zero); int64 array."""
    return round_half_away(np.asarray(deg, dtype=float) * 1e7)


def plan_to_items(
    vehicle_plan: VehiclePlan, origin: Origin, autopilot: str = Conventions.ARDUPILOT
) -> list[MissionItem]:
    """One vehicle's plan -> validated mission items (mission_type 0) for ``autopilot``."""
    vp = vehicle_plan
    if autopilot not in AUTOPILOTS:
        raise MissionValidationError(
            f"autopilot must be one of {AUTOPILOTS}, got {autopilot!r}", field="autopilot"
        )
    if vp.final_action not in FINAL_ACTIONS:
        raise MissionValidationError(
            f"vehicle {vp.vehicle_id}: final_action must be one of {FINAL_ACTIONS}, got {vp.final_action!r}",
            field="final_action",
        )
    wps = vp.waypoints
    if len(wps) == 0 or not np.all(np.isfinite(wps)):
        raise MissionValidationError(
            f"vehicle {vp.vehicle_id}: waypoints must be a non-empty (N, 3) array of finite metres",
            field="waypoints",
        )
    fixed_wing = vp.vehicle_type == "fixed_wing"
    vp = replace(vp, **mission_waypoints(vp))
    wps = vp.waypoints
    lat, lon, _ = enu_to_geodetic(wps[:, 0], wps[:, 1], wps[:, 2], origin)
    lat_e7, lon_e7 = deg_to_e7(lat).tolist(), deg_to_e7(lon).tolist()  # python ints

    amsl = vp.altitude_frame == "amsl"  # altitudes above sea level, not above each vehicle's home
    frame, z0 = (mavlink.MAV_FRAME_GLOBAL, origin.alt_m) if amsl else (REL, 0.0)

    def at(i: int, command: int, z: float, p1=0.0, p2=0.0, p3=0.0, p4=0.0) -> MissionItem:
        return MissionItem(0, frame, command, 0, 1, p1, p2, p3, p4, lat_e7[i], lon_e7[i], float(z) + z0)

    items: list[MissionItem] = [_home_item(origin)] if autopilot == Conventions.ARDUPILOT else []
    if vp.takeoff_delay_s > 0:
        items.append(
            MissionItem(
                0,
                NO_FRAME,
                mavlink.MAV_CMD_NAV_DELAY,
                param1=float(vp.takeoff_delay_s),
                param2=-1.0,
                param3=-1.0,
                param4=-1.0,
            )
        )
    elif vp.takeoff_delay_s < 0 or not math.isfinite(vp.takeoff_delay_s):
        raise MissionValidationError(
            f"vehicle {vp.vehicle_id}: takeoff_delay_s must be >= 0, got {vp.takeoff_delay_s!r}",
            field="takeoff_delay_s",
        )
    takeoff_alt = wps[0, 2] if wps[0, 2] >= MIN_TAKEOFF_ALT_M or len(wps) == 1 else wps[1, 2]
    if takeoff_alt < MIN_TAKEOFF_ALT_M:
        raise MissionValidationError(
            f"vehicle {vp.vehicle_id}: take-off altitude {takeoff_alt:.2f} m is below {MIN_TAKEOFF_ALT_M} m",
            field="waypoints",
        )
    pitch = FIXED_WING_TAKEOFF_PITCH_DEG if fixed_wing else 0.0
    items.append(at(0, mavlink.MAV_CMD_NAV_TAKEOFF, takeoff_alt, p1=pitch))
    items.extend(_legs(vp, at, fixed_wing))
    last = len(wps) - 1
    if vp.final_action == "land":
        if fixed_wing:  # no DO_LAND_START: ArduPlane refuses to arm with one unless RTL_AUTOLAND is set
            items.append(_fixed_wing_land(vp, origin))
        else:  # land where the ground is: a relative-frame 0 (autopilots ignore the altitude)
            items.append(
                MissionItem(0, REL, mavlink.MAV_CMD_NAV_LAND, 0, 1, x=lat_e7[last], y=lon_e7[last], z=0.0)
            )
    elif vp.final_action == "rtl":
        items.append(MissionItem(0, NO_FRAME, mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH))
    else:
        radius = vp.turn_radius_m if fixed_wing else 0.0
        items.append(at(last, mavlink.MAV_CMD_NAV_LOITER_UNLIM, wps[last, 2], p3=radius))
    items = [_renumbered(item, i, current=int(i == 0)) for i, item in enumerate(items)]
    validate_items(items)
    return items


def mission_waypoints(vp: VehiclePlan) -> dict[str, np.ndarray]:
    """The waypoints, times and speeds ``vp``'s mission holds: a multirotor's runs of short legs
    made corners (module docstring, Corners), a fixed wing's as planned."""
    if vp.vehicle_type == "fixed_wing":
        return {"waypoints": vp.waypoints, "times_s": vp.times_s, "speeds_mps": vp.speeds_mps}
    return _corners(vp)


def _corners(vp: VehiclePlan) -> dict[str, np.ndarray]:
    """The waypoints, times and speeds with each run of short legs between two longer ones made
    one corner (module docstring, Corners); the first and last waypoints stay."""
    wps, times = vp.waypoints, vp.times_s
    leg_m = np.linalg.norm(np.diff(wps, axis=0), axis=1)
    short = (leg_m >= DWELL_LEG_M) & (leg_m < CORNER_LEG_M)
    long = leg_m >= CORNER_LEG_M
    points, at_s = wps.copy(), times.astype(float).copy()
    dropped: set[int] = set()
    k = 1
    while k < len(leg_m):
        if not (short[k] and long[k - 1]):
            k += 1
            continue
        j = k
        while j < len(leg_m) and short[j]:
            j += 1
        one_speed = np.ptp(vp.speeds_mps[k : j + 2]) <= SPEED_TOLERANCE_MPS  # no speed change lost
        if j < len(leg_m) and long[j] and one_speed:  # points k..j: short legs, long legs either side
            corner = _corner_point(wps[k - 1 : j + 2])
            if corner is not None:
                points[k], at_s[k] = corner, 0.5 * (times[k] + times[j])
                dropped.update(range(k + 1, j + 1))
        k = j + 1
    keep = [i for i in range(len(wps)) if i not in dropped]
    return {"waypoints": points[keep], "times_s": at_s[keep], "speeds_mps": vp.speeds_mps[keep]}


def _corner_point(run: np.ndarray) -> np.ndarray | None:
    """The one waypoint for ``run`` (the long leg's start, the short legs' points, the next long
    leg's end): where the long legs' horizontal lines meet, at the height of the run's middle,
    if that is within CORNER_DEV_M of the middle; else None (keep the run)."""
    a, b, c, d = run[0, :2], run[1, :2], run[-2, :2], run[-1, :2]
    inner = run[1:-1]
    middle = (
        inner[len(inner) // 2]
        if len(inner) % 2
        else 0.5 * (inner[len(inner) // 2 - 1] + inner[len(inner) // 2])
    )
    u, v = b - a, d - c
    cross = u[0] * v[1] - u[1] * v[0]
    if abs(cross) <= 1e-9 * np.linalg.norm(u) * np.linalg.norm(v):  # no turn: a straight run
        at = middle[:2]
    else:
        w = c - a
        at = a + (w[0] * v[1] - w[1] * v[0]) / cross * u
    if np.linalg.norm(at - middle[:2]) > CORNER_DEV_M:
        return None
    return np.array([at[0], at[1], middle[2]])


def _home_item(origin: Origin) -> MissionItem:
    """ArduPilot's seq 0: a NAV_WAYPOINT at the origin, AMSL (the module docstring)."""
    home_lat, home_lon = deg_to_e7([origin.lat_deg, origin.lon_deg])
    return MissionItem(
        0,
        mavlink.MAV_FRAME_GLOBAL,
        mavlink.MAV_CMD_NAV_WAYPOINT,
        x=int(home_lat),
        y=int(home_lon),
        z=float(origin.alt_m),
    )


def _fixed_wing_land(vp: VehiclePlan, origin: Origin) -> MissionItem:
    """NAV_LAND at the plan's land point: one glide-slope run ahead of the last waypoint."""
    x, y, _ = land_point(vp)
    lat, lon, _ = enu_to_geodetic(x, y, 0.0, origin)
    lat_e7, lon_e7 = deg_to_e7([float(lat), float(lon)]).tolist()
    return MissionItem(0, REL, mavlink.MAV_CMD_NAV_LAND, 0, 1, x=lat_e7, y=lon_e7, z=0.0)


def _legs(vp: VehiclePlan, at, fixed_wing: bool) -> list[MissionItem]:
    """Waypoints 1..N-1 with speed changes before their legs and dwells as hold times."""
    wps, times, speeds = vp.waypoints, vp.times_s, vp.speeds_mps
    speed_type = SPEED_AIRSPEED if fixed_wing else SPEED_GROUNDSPEED
    out: list[MissionItem] = []
    commanded = None
    last_nav = None  # index in ``out`` of the waypoint a dwell extends
    leg_m = np.linalg.norm(np.diff(wps, axis=0), axis=1)
    for i in range(1, len(wps)):
        if leg_m[i - 1] < DWELL_LEG_M:
            hold_s = float(times[i] - times[i - 1])
            if hold_s <= 0:
                continue
            if fixed_wing:
                out.append(at(i, mavlink.MAV_CMD_NAV_LOITER_TIME, wps[i, 2], p1=hold_s, p3=vp.turn_radius_m))
            elif last_nav is None:
                out.append(
                    at(i, mavlink.MAV_CMD_NAV_WAYPOINT, wps[i, 2], p1=hold_s, p2=vp.acceptance_radius_m)
                )
                last_nav = len(out) - 1
            else:
                prev = out[last_nav]
                out[last_nav] = replace(prev, param1=prev.param1 + hold_s)
            continue
        speed = float(speeds[i])
        if not (math.isfinite(speed) and speed > 0):
            raise MissionValidationError(
                f"vehicle {vp.vehicle_id}: speeds_mps[{i}] = {speed!r} must be > 0 on a leg of length > 0",
                field="speeds_mps",
            )
        if commanded is None or abs(speed - commanded) > SPEED_TOLERANCE_MPS:
            out.append(
                MissionItem(
                    0, NO_FRAME, mavlink.MAV_CMD_DO_CHANGE_SPEED, param1=speed_type, param2=speed, param3=-1.0
                )
            )
            commanded = speed
        out.append(at(i, mavlink.MAV_CMD_NAV_WAYPOINT, wps[i, 2], p2=vp.acceptance_radius_m))
        last_nav = len(out) - 1
    return out


def _renumbered(it: MissionItem, seq: int, current: int) -> MissionItem:
    """``it`` with a new seq and current flag (built directly: faster than dataclasses.replace)."""
    return MissionItem(seq, it.frame, it.command, current, it.autocontinue, it.param1, it.param2, it.param3,
                       it.param4, it.x, it.y, it.z, it.mission_type)  # fmt: skip


def _numbered(items: list[MissionItem]) -> list[MissionItem]:
    return [item.with_seq(i) for i, item in enumerate(items)]


def scenario_fence_items(scenario: Scenario, vp: VehiclePlan | None = None) -> list[MissionItem]:
    """The fence items (type 1) of the scenario, or of one vehicle's plan (gcs_planner.safety.geofence:
    the bounds or site area as an inclusion polygon, the obstacles its path keeps out of as exclusion
    circles, the site's no-fly zones it keeps out of as exclusion polygons)."""
    fence = vehicle_geofence(scenario, vp)
    origin = scenario.origin
    items: list[MissionItem] = []

    def geo(east, north):
        lat, lon, _ = enu_to_geodetic(np.asarray(east, float), np.asarray(north, float), 0.0, origin)
        return deg_to_e7(lat), deg_to_e7(lon)

    fence_type, fence_frame = MissionType.FENCE, mavlink.MAV_FRAME_GLOBAL
    polygons = (
        []
        if fence.inclusion is None
        else [(mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION, fence.inclusion)]
    )
    polygons += [
        (mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION, z.vertices) for z in fence.exclusion_polygons
    ]
    for cmd, vertices in polygons:  # counter-clockwise seen from above; param1 = the vertex count
        lats, lons = geo(vertices[:, 0], vertices[:, 1])
        items += [
            MissionItem(
                0, fence_frame, cmd, 0, 1, float(len(vertices)), x=int(a), y=int(b), mission_type=fence_type
            )
            for a, b in zip(lats, lons, strict=True)
        ]
    if fence.exclusions:
        cx, cy, radii = np.array([(c.x, c.y, c.radius_m) for c in fence.exclusions], dtype=float).T
        lats, lons = geo(cx, cy)
        cmd = mavlink.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION
        items += [
            MissionItem(0, fence_frame, cmd, 0, 1, float(r), x=int(a), y=int(b), mission_type=fence_type)
            for a, b, r in zip(lats, lons, radii, strict=True)
        ]
    items = _numbered(items)
    validate_items(items, mission_type=fence_type)
    return items


def rally_items(points_enu: Iterable, origin: Origin) -> list[MissionItem]:
    """Rally points (K, 3) ENU [m] -> rally items (type 2), altitude relative to home."""
    pts = np.asarray(list(points_enu), dtype=float).reshape(-1, 3)
    lat, lon, _ = enu_to_geodetic(pts[:, 0], pts[:, 1], pts[:, 2], origin)
    items = [
        MissionItem(
            i,
            REL,
            mavlink.MAV_CMD_NAV_RALLY_POINT,
            0,
            1,
            x=int(a),
            y=int(b),
            z=float(z),
            mission_type=MissionType.RALLY,
        )
        for i, (a, b, z) in enumerate(zip(deg_to_e7(lat), deg_to_e7(lon), pts[:, 2], strict=True))
    ]
    validate_items(items, mission_type=MissionType.RALLY)
    return items


def scenario_rally_items(scenario: Scenario, vp: VehiclePlan | None = None) -> list[MissionItem]:
    """A rally point over a vehicle's start at its minimum altitude: for one vehicle's plan its own
    only (an RTL goes to the nearest rally point: a neighbour's would send it into the neighbour's
    return), else (or when the scenario does not name the plan's vehicle) one per scenario vehicle."""
    own = [v for v in scenario.vehicles if vp is not None and v.id == vp.vehicle_id]
    vehicles = own or scenario.vehicles
    return rally_items([(v.start[0], v.start[1], v.min_alt_m) for v in vehicles], scenario.origin)
