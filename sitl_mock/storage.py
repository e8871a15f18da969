"""What the mock autopilot stores of an uploaded mission item, and what a download then returns.

A second implementation, written from the autopilots' sources independently of the client's
read-back model (gcs_planner/autopilots/readback.py), so that a test can check one against the other
(tests/test_readback_crosscheck.py). Each autopilot is modelled in two steps as in its C code:
``_parse`` turns the MISSION_ITEM_INT into the record the autopilot keeps (typed fields: C integers,
float32, double), ``_format`` turns the record back into the MISSION_ITEM_INT it sends.

- ArduPilot (ArduCopter / ArduPlane): libraries/AP_Mission/AP_Mission.cpp,
  ``AP_Mission::mavlink_int_to_mission_cmd`` (upload: Mission_Command with a 16-bit p1, typed
  content fields, a Location whose altitude is ``packet.z * 100.0f`` truncated to int32 cm; an item
  kept in a Location with ``isnan(packet.z) || fabsf(packet.z) >= LOCATION_ALT_MAX_M`` (83000 m,
  AP_Common/Location.h) is refused with MAV_MISSION_INVALID_PARAM7) and
  ``AP_Mission::mission_cmd_to_mavlink_int`` (download: ``packet.z = alt * 0.01f``, frame from
  relative_alt / terrain_alt, autocontinue 1).
- PX4: src/modules/mavlink/mavlink_mission.cpp,
  ``MavlinkMissionManager::parse_mavlink_mission_item`` (mission_item_s: double lat/lon, float32
  params[7] aliasing time_inside / acceptance_radius / loiter_radius / yaw / altitude, yaw as
  ``wrap_2pi(math::radians(param4))`` in float) and ``format_mavlink_mission_item`` (param4 =
  ``math::degrees(yaw)``, x / y = ``round(params[4])`` for MAV_FRAME_MISSION items). A non-finite
  altitude is refused with MAV_MISSION_INVALID_PARAM7 (the mock's rule, kept from before).

float32 arithmetic is done in double and rounded once to float32 (``_f32``): for + - * / of two
float32 operands that gives the correctly rounded float32 result. A float stored in a C integer
field is truncated toward zero and saturated to the field's range, NaN -> 0 (ARM VCVT; C leaves
it undefined).
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field

from gcs_planner.wire.dialect import has_position
from gcs_planner.wire.enums import MissionResult
from gcs_planner.wire.types import MissionItem, MissionType

__all__ = ["ARDUCOPTER", "ARDUPLANE", "PX4", "Refused", "Storage", "refuses"]

_FLOAT = struct.Struct("<f")
_INT_RANGE = {"u8": (0, 0xFF), "u16": (0, 0xFFFF), "i8": (-0x80, 0x7F), "i16": (-0x8000, 0x7FFF)}


class Refused(Exception):
    """The autopilot refuses the item: ``result`` is its MISSION_ACK type."""

    def __init__(self, result: MissionResult) -> None:
        super().__init__(result.name)
        self.result = result


def _f32(v: float) -> float:
    """Rounded to the nearest float32 (beyond its range: +-inf, NaN stays NaN)."""
    try:
        return _FLOAT.unpack(_FLOAT.pack(v))[0]
    except OverflowError:
        return math.copysign(math.inf, v)


def _to_int(v: float, ctype: str) -> int:
    """A float32 assigned to a C integer field of type ``ctype``."""
    lo, hi = _INT_RANGE[ctype]
    if v != v:
        return 0
    if math.isinf(v):
        return hi if v > 0 else lo
    return max(lo, min(hi, math.trunc(v)))


class Storage:
    """An autopilot's mission storage: ``storage(item)`` is what a download returns for ``item``
    (every float a float32 value), or raises :class:`Refused`."""

    name = "storage"

    def __call__(self, item: MissionItem) -> MissionItem:
        return self._format(self._parse(item), item)

    def _parse(self, item: MissionItem) -> dict:
        raise NotImplementedError

    def _format(self, rec: dict, item: MissionItem) -> MissionItem:
        raise NotImplementedError

    def __repr__(self) -> str:
        return f"<storage {self.name}>"


# ------------------------------------------------------------------------------------------ ArduPilot
_LOCATION_ALT_MAX_M = 83000.0
# AP_Mission::stored_in_location
_IN_LOCATION = {16, 17, 18, 19, 21, 22, 30, 31, 82, 84, 85, 92, 94, 179, 188, 189, 191, 195, 201}
# what each of param1..param4 becomes in Mission_Command, and comes back as:
#   "float": a float field, kept; None: not stored, 0; "u8" / "u16" / "i8" / "i16": a C integer;
#   "ccw": uint16 magnitude + loiter_ccw (sign back); "dir": only the sign (+-1); "bool": param > 0
_AP_SLOTS: dict[int, tuple] = {
    17: (None, None, "ccw", None),  # LOITER_UNLIM: p1 = radius, loiter_ccw
    18: ("u8", None, "ccw", "bool"),  # LOITER_TURNS
    19: ("u16", None, "dir", "bool"),  # LOITER_TIME: p1 = seconds, direction, xtrack
    20: (None, None, None, None),
    21: ("u16", None, None, "dir"),
    22: ("u16", None, None, None),
    31: (None, "ccw", None, "bool"),  # LOITER_TO_ALT
    82: ("u16", None, None, None),
    84: (None, None, None, None),
    85: ("u16", None, None, None),
    93: ("float", "i8", "i8", "i8"),
    112: ("float", None, None, None),
    115: ("float", "float", "i8", "u8"),  # CONDITION_YAW
    177: ("u16", "i16", None, None),  # DO_JUMP: target, num_times
    178: ("u8", "float", "float", None),  # DO_CHANGE_SPEED
    179: ("u16", None, None, None),
    181: ("u8", "u8", None, None),
    183: ("u8", "u16", None, None),
    189: (None, None, None, None),
    201: ("u16", None, None, None),
    202: ("u8", "u16", "u8", "u16"),
    203: ("u8", "u8", "i8", "u8"),
    205: ("float", "float", "float", None),
    206: ("float", None, "u8", None),
    1000: ("i8", "i16", "i8", "i8"),
    2000: ("u8", "float", "u16", "u16"),
    2001: ("u16", None, None, None),
    2500: ("u8", None, None, None),
    2501: ("u8", None, None, None),
    3000: ("u8", None, None, None),
}
_KEEP_ALL = ("float", "float", "float", "float")
_COPTER_WP = ("u16", None, None, None)  # hold time
_PLANE_WP = (None, "u8", "u8", None)  # acceptance radius (low byte of p1) | pass radius (high byte)
# positionless commands whose x / y / z Mission_Command keeps: (x, y, z) slot types, a number = constant
_AP_RAW = {
    202: ("u8", "u8", "float"),
    203: ("u8", "u8", 0),
    205: (0, 0, 2),
    1000: ("u8", 0, "u8"),
}


def _store_slot(kind, v: float):
    v = _f32(v)
    if kind is None:
        return 0
    if kind == "float":
        return v
    if kind == "ccw":
        return (_to_int(abs(v), "u16"), v < 0)
    if kind == "dir":
        return v < 0
    if kind == "bool":
        return v > 0
    return _to_int(v, kind)


def _report_slot(kind, stored) -> float:
    if kind == "ccw":
        magnitude, ccw = stored
        return -float(magnitude) if ccw else float(magnitude)
    if kind == "dir":
        return -1.0 if stored else 1.0
    return float(stored)


class ArduPilotStorage(Storage):
    def __init__(self, plane: bool) -> None:
        self.plane = plane
        self.name = "arduplane" if plane else "arducopter"

    def _slots(self, item: MissionItem) -> tuple:
        if item.mission_type != MissionType.MISSION:
            return _KEEP_ALL
        if item.command == 16:
            return _PLANE_WP if self.plane else _COPTER_WP
        return _AP_SLOTS.get(item.command, _KEEP_ALL)

    def _parse(self, item: MissionItem) -> dict:
        slots = self._slots(item)
        params = (item.param1, item.param2, item.param3, item.param4)
        rec: dict = {"id": item.command, "slots": slots}
        rec["content"] = [_store_slot(k, v) for k, v in zip(slots, params, strict=True)]
        if item.mission_type != MissionType.MISSION or item.command in _IN_LOCATION:
            z = _f32(item.z)
            if z != z or abs(z) >= _LOCATION_ALT_MAX_M:
                raise Refused(MissionResult.INVALID_PARAM7)
            rec["location"] = {
                "lat": item.x,
                "lng": item.y,
                "alt": math.trunc(_f32(z * 100.0)),  # int32 cm
                "relative_alt": item.frame in (3, 6, 10, 11),
                "terrain_alt": item.frame in (10, 11),
                "frame": item.frame,
            }
        else:
            raw = _AP_RAW.get(item.command, (0, 0, 0))
            rec["raw"] = [
                kind if not isinstance(kind, str) else _store_slot(kind, v)
                for kind, v in zip(raw, (item.x, item.y, item.z), strict=True)
            ]
        return rec

    def _format(self, rec: dict, item: MissionItem) -> MissionItem:
        params = [_report_slot(k, s) for k, s in zip(rec["slots"], rec["content"], strict=True)]
        loc = rec.get("location")
        if loc is not None:
            frame = 10 if loc["terrain_alt"] else 3 if loc["relative_alt"] else 0
            if loc["frame"] not in (0, 2, 3, 5, 6, 10, 11):
                frame = loc["frame"]  # AP refuses other frames (UNSUPPORTED_FRAME); kept as sent
            x, y, z = loc["lat"], loc["lng"], _f32(_f32(float(loc["alt"])) * _f32(0.01))
        else:
            frame = 0
            x, y, z = int(rec["raw"][0]), int(rec["raw"][1]), _f32(float(rec["raw"][2]))
        return MissionItem(
            item.seq, frame, rec["id"], item.current, 1, *params, x, y, z, item.mission_type
        )  # fmt: skip


# ------------------------------------------------------------------------------------------ PX4
_PI_F = _f32(math.pi)
_TWO_PI_F = _f32(2 * math.pi)  # float(M_TWOPI)
_DEG_TO_RAD = _f32(_PI_F / _f32(180.0))  # math::radians: x * (float(M_PI) / 180.f)
_RAD_TO_DEG = _f32(_f32(180.0) / _PI_F)  # math::degrees: x * (180.f / float(M_PI))
_INV_TWO_PI = _f32(1.0 / _TWO_PI_F)


def _wrap_2pi(x: float) -> float:
    """matrix::wrap(x, 0.f, float(M_TWOPI)) in float32."""
    if 0.0 <= x < _TWO_PI_F:
        return x
    if not math.isfinite(x):
        return math.nan  # floor(inf) = inf, inf - inf = NaN; NaN stays NaN
    wraps = float(math.floor(_f32(x * _INV_TWO_PI)))
    return _f32(x - _f32(_TWO_PI_F * wraps))


def _c_round(v: float) -> int:
    """C round(): half away from zero; then stored in an int32_t (saturated)."""
    r = math.floor(abs(v) + 0.5)
    r = r if v >= 0 else -r
    return max(-(2**31), min(2**31 - 1, r))


@dataclass
class _Px4Item:
    """The fields of mission_item_s the mission protocol touches."""

    nav_cmd: int
    frame: int
    autocontinue: int
    lat: float = 0.0  # double, degrees
    lon: float = 0.0
    params: list[float] = field(default_factory=lambda: [0.0] * 7)  # float32; [6] = altitude
    altitude_is_relative: bool = False
    time_inside: float = 0.0
    acceptance_radius: float = 0.0
    loiter_radius: float = 0.0
    yaw: float = 0.0
    force_heading: bool = False
    loiter_exit_xtrack: bool = False
    land_precision: int = 0
    vertex_count: int = 0
    circle_radius: float = 0.0
    do_jump_mission_index: int = 0
    do_jump_repeat_count: int = 0


_PX4_YAW_COMMANDS = {16, 17, 19, 21, 22, 84, 85}


class Px4Storage(Storage):
    name = "px4"

    def _parse(self, item: MissionItem) -> _Px4Item:
        z = _f32(item.z)
        if not math.isfinite(z):
            raise Refused(MissionResult.INVALID_PARAM7)
        p1, p2, p3, p4 = (_f32(v) for v in (item.param1, item.param2, item.param3, item.param4))
        rec = _Px4Item(item.command, item.frame, item.autocontinue)
        positional = item.mission_type != MissionType.MISSION or has_position(item.command)
        if not positional:
            rec.params = [p1, p2, p3, p4, _f32(float(item.x)), _f32(float(item.y)), z]
            if item.command == 177:
                rec.do_jump_mission_index = _to_int(p1, "i16")
                rec.do_jump_repeat_count = _to_int(p2, "u16")
            return rec
        rec.lat, rec.lon = item.x * 1e-7, item.y * 1e-7
        rec.params[6] = z
        rec.altitude_is_relative = item.frame in (3, 6)
        c = item.command
        if c in _PX4_YAW_COMMANDS:
            rec.yaw = _wrap_2pi(_f32(p4 * _DEG_TO_RAD))
        if c == 16:
            rec.time_inside, rec.acceptance_radius = p1, p2
        elif c == 17:
            rec.loiter_radius = p3
        elif c == 19:
            rec.time_inside, rec.force_heading = p1, p2 > 0
            rec.loiter_radius, rec.loiter_exit_xtrack = p3, p4 > 0
        elif c == 21:
            rec.land_precision = _to_int(p2, "u16")
        elif c == 31:
            rec.force_heading, rec.loiter_radius, rec.loiter_exit_xtrack = p1 > 0, p2, p4 > 0
        elif c in (5001, 5002):
            rec.vertex_count = _to_int(_f32(p1 + 0.5), "u16")  # (uint16_t)(param1 + 0.5f)
        elif c in (5003, 5004):
            rec.circle_radius = p1
        return rec

    def _format(self, rec: _Px4Item, item: MissionItem) -> MissionItem:
        mission_type = item.mission_type
        if rec.frame == 2 and mission_type == MissionType.MISSION and not has_position(rec.nav_cmd):
            p = list(rec.params[:4])
            if rec.nav_cmd == 177:
                p[0], p[1] = float(rec.do_jump_mission_index), float(rec.do_jump_repeat_count)
            x, y = _c_round(rec.params[4]), _c_round(rec.params[5])
            return MissionItem(item.seq, 2, rec.nav_cmd, item.current, rec.autocontinue, *p, x, y,
                               rec.params[6], mission_type)  # fmt: skip
        frame = {0: 5, 5: 5, 3: 6, 6: 6}.get(rec.frame, rec.frame)
        autocontinue = rec.autocontinue
        if mission_type == MissionType.FENCE:  # send_mission_item: a fresh mission_item_s
            frame, autocontinue = 5, 0
        p = [0.0, 0.0, 0.0, 0.0]
        c = rec.nav_cmd
        deg = _f32(rec.yaw * _RAD_TO_DEG) if rec.yaw == rec.yaw else math.nan
        if mission_type == MissionType.FENCE:
            if c in (5001, 5002):
                p[0] = float(rec.vertex_count)
            elif c in (5003, 5004):
                p[0] = rec.circle_radius
        elif mission_type == MissionType.RALLY:
            pass
        elif c == 16:
            p = [rec.time_inside, rec.acceptance_radius, 0.0, deg]
        elif c == 17:
            p = [0.0, 0.0, rec.loiter_radius, deg]
        elif c == 19:
            p = [rec.time_inside, float(rec.force_heading), rec.loiter_radius, float(rec.loiter_exit_xtrack)]
        elif c == 21:
            p = [0.0, float(rec.land_precision), 0.0, deg]
        elif c in (22, 84, 85):
            p[3] = deg
        elif c == 31:
            p = [float(rec.force_heading), rec.loiter_radius, 0.0, float(rec.loiter_exit_xtrack)]
        x, y = _c_round(rec.lat * 1e7), _c_round(rec.lon * 1e7)
        return MissionItem(
            item.seq, frame, c, item.current, autocontinue, *p, x, y, rec.params[6], mission_type
        )


ARDUCOPTER = ArduPilotStorage(plane=False)
ARDUPLANE = ArduPilotStorage(plane=True)
PX4 = Px4Storage()


def refuses(storage, item: MissionItem) -> MissionResult | None:
    """The MISSION_ACK error ``storage`` answers ``item`` with, None if it stores it."""
    try:
        storage(item)
    except Refused as refused:
        return refused.result
    return None
