"""What an autopilot gives back of an uploaded mission item: the model a verify compares with.

A ``Model`` maps an item to what the autopilot stores of it: fields it drops become 0, fields it
rounds are rounded the same way, frames it rewrites are rewritten. ``compare_items`` (mission.py)
applies the model to both the item sent and the item downloaded and then wants them equal to
float32 precision, so a real change (a repeat count, a speed type) is never hidden by a tolerance,
and a field the autopilot does not keep never fails a verify.

The rules, with the autopilot source they come from, are in docs/real-autopilots.md.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable
from dataclasses import replace

from gcs_planner.mavlink.dialect import has_position
from gcs_planner.mavlink.types import MissionItem, MissionType

__all__ = ["ARDUCOPTER", "ARDUPLANE", "GENERIC", "PX4", "Model"]

Model = Callable[[MissionItem], MissionItem]

# AP_Mission::stored_in_location: the commands ArduPilot keeps a Location for
_AP_LOCATION = frozenset({16, 17, 18, 19, 21, 22, 30, 31, 82, 84, 85, 92, 94, 179, 188, 189, 191, 195, 201})
_AP_FRAMES = {
    0: 0,
    2: 0,
    5: 0,
    3: 3,
    6: 3,
    10: 10,
    11: 10,
}  # sent -> reported (absolute / relative / terrain)
_PX4_FRAMES = {0: 5, 5: 5, 3: 6, 6: 6}  # PX4 reports the _INT frame from altitude_is_relative


def _int(v: float, lo: int, hi: int) -> float:
    """A float stored in a C integer field: truncated toward zero, kept in the type's range."""
    return float(min(max(int(v), lo), hi)) if math.isfinite(v) else 0.0


def _u8(v: float) -> float:
    return _int(v, 0, 255)


def _u16(v: float) -> float:
    return _int(v, 0, 65535)


def _i8(v: float) -> float:
    return _int(v, -128, 127)


def _sign(v: float) -> float:
    return -1.0 if v < 0 else 1.0


def _flag(v: float) -> float:
    return 1.0 if v > 0 else 0.0


def _signed_int(v: float) -> float:
    return math.copysign(_u16(abs(v)), v) if v else 0.0


# command -> (param1..4 as ArduPilot returns them) from the sent params; missing command: kept as sent.
# AP_Mission::mavlink_int_to_mission_cmd / mission_cmd_to_mavlink_int (see docs/real-autopilots.md)
_AP_PARAMS = {
    17: lambda p: (0.0, 0.0, _signed_int(p[2]), 0.0),
    18: lambda p: (_u8(p[0]), 0.0, _signed_int(p[2]), _flag(p[3])),
    19: lambda p: (_u16(p[0]), 0.0, _sign(p[2]), _flag(p[3])),
    20: lambda p: (0.0, 0.0, 0.0, 0.0),
    21: lambda p: (_u16(p[0]), 0.0, 0.0, _sign(p[3]) if math.isfinite(p[3]) else 1.0),
    22: lambda p: (_u16(p[0]), 0.0, 0.0, 0.0),
    31: lambda p: (0.0, _signed_int(p[1]), 0.0, _flag(p[3])),
    82: lambda p: (_u16(p[0]), 0.0, 0.0, 0.0),
    84: lambda p: (0.0, 0.0, 0.0, 0.0),
    85: lambda p: (_u16(p[0]), 0.0, 0.0, 0.0),
    93: lambda p: (p[0], _i8(p[1]), _i8(p[2]), _i8(p[3])),
    112: lambda p: (p[0], 0.0, 0.0, 0.0),
    115: lambda p: (p[0], p[1], _i8(p[2]), _u8(p[3])),
    177: lambda p: (_u16(p[0]), _int(p[1], -32768, 32767), 0.0, 0.0),
    178: lambda p: (_u8(p[0]), p[1], p[2], 0.0),
    179: lambda p: (_u16(p[0]), 0.0, 0.0, 0.0),
    181: lambda p: (_u8(p[0]), _u8(p[1]), 0.0, 0.0),
    183: lambda p: (_u8(p[0]), _u16(p[1]), 0.0, 0.0),
    189: lambda p: (0.0, 0.0, 0.0, 0.0),
    201: lambda p: (_u16(p[0]), 0.0, 0.0, 0.0),
    202: lambda p: (_u8(p[0]), _u16(p[1]), _u8(p[2]), _u16(p[3])),
    203: lambda p: (_u8(p[0]), _u8(p[1]), _i8(p[2]), _u8(p[3])),
    205: lambda p: (p[0], p[1], p[2], 0.0),
    206: lambda p: (p[0], 0.0, _u8(p[2]), 0.0),
    1000: lambda p: (_i8(p[0]), _int(p[1], -32768, 32767), _i8(p[2]), _i8(p[3])),
    2000: lambda p: (_u8(p[0]), p[1], _u16(p[2]), _u16(p[3])),
    2001: lambda p: (_u16(p[0]), 0.0, 0.0, 0.0),
    2500: lambda p: (_u8(p[0]), 0.0, 0.0, 0.0),
    2501: lambda p: (_u8(p[0]), 0.0, 0.0, 0.0),
    3000: lambda p: (_u8(p[0]), 0.0, 0.0, 0.0),
}
_AP_RAW_XYZ = {  # positionless commands that keep x / y / z: (x, y, z) from the sent ones
    202: lambda it: (int(_u8(it.x)), int(_u8(it.y)), it.z),
    203: lambda it: (int(_u8(it.x)), int(_u8(it.y)), 0.0),
    205: lambda it: (0, 0, 2.0),  # MAV_MOUNT_MODE_MAVLINK_TARGETING
    1000: lambda it: (int(_u8(it.x)), 0, _u8(it.z)),
}


def _with_params(item: MissionItem, p) -> MissionItem:
    return replace(item, param1=p[0], param2=p[1], param3=p[2], param4=p[3])


def _f32(v: float) -> float:
    return struct.unpack("<f", struct.pack("<f", v))[0]


def _cm(z: float) -> float:
    """ArduPilot's Location altitude: ``packet.z * 100.0f`` in float32 (z crossed the wire as one),
    truncated toward zero to int32 centimetres; 83.13 is stored as 8312 cm."""
    return math.trunc(_f32(_f32(z) * 100.0)) / 100.0 if math.isfinite(z) else z


def _ardupilot(item: MissionItem, plane: bool) -> MissionItem:
    """AP_Mission::mavlink_int_to_mission_cmd, then mission_cmd_to_mavlink_int (AP_Mission.cpp):
    autocontinue always 1; a Location keeps lat/lon exactly and the altitude in cm, reported in
    frame 0 / 3 / 10; positionless commands come back in frame 0 with x = y = z = 0 unless they
    store them raw."""
    item = replace(item, autocontinue=1)
    c = item.command
    if item.mission_type != MissionType.MISSION or c in _AP_LOCATION:
        item = replace(item, frame=_AP_FRAMES.get(item.frame, item.frame), z=_cm(item.z))
    else:
        x, y, z = _AP_RAW_XYZ[c](item) if c in _AP_RAW_XYZ else (0, 0, 0.0)
        item = replace(item, frame=0, x=x, y=y, z=z)
    if item.mission_type != MissionType.MISSION:
        return item
    p = (item.param1, item.param2, item.param3, item.param4)
    if c == 16:  # one 16-bit p1: ArduPlane radius | pass radius << 8, the rest hold time
        return _with_params(item, (0.0, min(_u16(p[1]), 255.0), min(_u16(p[2]), 255.0), 0.0) if plane
                            else (_u16(p[0]), 0.0, 0.0, 0.0))  # fmt: skip
    rule = _AP_PARAMS.get(c)
    return item if rule is None else _with_params(item, rule(p))


def ARDUCOPTER(item: MissionItem) -> MissionItem:  # noqa: N802 - a model, named like the constants
    return _ardupilot(item, plane=False)


def ARDUPLANE(item: MissionItem) -> MissionItem:  # noqa: N802
    return _ardupilot(item, plane=True)


def _wrap_deg(v: float) -> float:
    return math.degrees(math.radians(v) % (2 * math.pi)) if math.isfinite(v) else v


# command -> param1..4 as PX4 returns them (mavlink_mission.cpp format_mavlink_mission_item)
_PX4_PARAMS = {
    16: lambda p: (p[0], p[1], 0.0, _wrap_deg(p[3])),
    17: lambda p: (0.0, 0.0, p[2], _wrap_deg(p[3])),
    19: lambda p: (p[0], _flag(p[1]), p[2], _flag(p[3])),
    21: lambda p: (0.0, float(int(p[1])) if math.isfinite(p[1]) else 0.0, 0.0, _wrap_deg(p[3])),
    22: lambda p: (0.0, 0.0, 0.0, _wrap_deg(p[3])),
    31: lambda p: (_flag(p[0]), p[1], 0.0, _flag(p[3])),
    84: lambda p: (0.0, 0.0, 0.0, _wrap_deg(p[3])),
    85: lambda p: (0.0, 0.0, 0.0, _wrap_deg(p[3])),
}


def PX4(item: MissionItem) -> MissionItem:  # noqa: N802
    """mavlink_mission.cpp parse_mavlink_mission_item / format_mavlink_mission_item: fence points
    keep position and radius / vertex count (frame GLOBAL_INT, autocontinue 0), rally points their
    position; positional items come back in the _INT frames, positionless ones as sent."""
    if item.mission_type == MissionType.FENCE:
        p1 = float(int(item.param1 + 0.5)) if item.command in (5001, 5002) else item.param1
        return replace(item, frame=5, autocontinue=0, param1=p1, param2=0.0, param3=0.0, param4=0.0)
    if item.mission_type == MissionType.RALLY:
        return replace(item, frame=_PX4_FRAMES.get(item.frame, item.frame), param1=0.0, param2=0.0,
                       param3=0.0, param4=0.0)  # fmt: skip
    if has_position(item.command):
        item = replace(item, frame=_PX4_FRAMES.get(item.frame, item.frame))
    rule = _PX4_PARAMS.get(item.command)
    return (
        item
        if rule is None
        else _with_params(item, rule((item.param1, item.param2, item.param3, item.param4)))
    )


def GENERIC(item: MissionItem) -> MissionItem:  # noqa: N802
    """A store-everything vehicle (MAVSDK's MissionRawServer): what was sent comes back."""
    return item
