"""What an autopilot gives back of an uploaded mission item: the model a verify compares with.

A ``Model`` maps an item SENT to the item the autopilot returns on the wire for it, computed in the
autopilot's own arithmetic: float32 (numpy) where it keeps a float, C integer conversions where it
keeps an integer, ArduPilot's ``packet.z * 100.0f`` truncated to int32 cm and ``alt * 0.01f`` back,
PX4's float32 ``wrap_2pi(radians(yaw))`` and ``degrees()`` back. Fields it drops become 0, frames
it rewrites are rewritten. Every float of a model's result is a float32 value and x / y are int32,
i.e. exactly what a MISSION_ITEM_INT carries. ``compare_items`` (mission.py) applies the model to
the item sent only and then wants the item downloaded equal to it, field for field, exactly.

Two conventions where C leaves the result undefined: a float out of an integer field's range is
saturated to the range and NaN becomes 0 (what an ARM VCVT instruction does); an item the autopilot
refuses (``refusal`` says with which MISSION_ACK result) is returned as sent, since no read-back
follows a refused upload.

The rules, with the autopilot source they come from, are in docs/real-autopilots.md. The mock
autopilot has its own implementation of the same sources (sitl_mock/storage.py); a test checks that
the two agree.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from gcs_planner.wire.dialect import has_position
from gcs_planner.wire.enums import MissionResult
from gcs_planner.wire.types import MissionItem, MissionType

__all__ = ["ARDUCOPTER", "ARDUPLANE", "GENERIC", "PX4", "Model", "refusal", "wire"]

Model = Callable[[MissionItem], MissionItem]
F32 = np.float32

# AP_Mission::stored_in_location: the commands ArduPilot keeps a Location for
_AP_LOCATION = frozenset({16, 17, 18, 19, 21, 22, 30, 31, 82, 84, 85, 92, 94, 179, 188, 189, 191, 195, 201})
# sent -> reported frame (absolute / relative / terrain)
_AP_FRAMES = {0: 0, 2: 0, 5: 0, 3: 3, 6: 3, 10: 10, 11: 10}
_PX4_FRAMES = {0: 5, 5: 5, 3: 6, 6: 6}  # PX4 reports the _INT frame from altitude_is_relative
# AP_Common/Location.h LOCATION_ALT_MAX_M (83000 m): AP_Mission refuses fabsf(packet.z) >= it
# with MAV_MISSION_INVALID_PARAM7
LOCATION_ALT_MAX_M = F32(83000)


def _f32(v: float) -> np.float32:
    """The float32 a float becomes on the wire (out of float32's range: +-inf, as a C cast)."""
    with np.errstate(over="ignore", invalid="ignore"):
        return F32(v)


def _c_int(v: np.float32, lo: int, hi: int) -> np.float32:
    """A float32 stored in a C integer field and read back as float32: truncated toward zero,
    saturated to [lo, hi], NaN -> 0."""
    if np.isnan(v):
        return F32(0)
    if np.isinf(v):
        return F32(hi if v > 0 else lo)
    return F32(min(max(int(v), lo), hi))


def _u8(v: np.float32) -> np.float32:
    return _c_int(v, 0, 255)


def _u16(v: np.float32) -> np.float32:
    return _c_int(v, 0, 65535)


def _i8(v: np.float32) -> np.float32:
    return _c_int(v, -128, 127)


def _i16(v: np.float32) -> np.float32:
    return _c_int(v, -32768, 32767)


def _sign(v: np.float32) -> np.float32:
    return F32(-1) if v < 0 else F32(1)


def _flag(v: np.float32) -> np.float32:
    return F32(1) if v > 0 else F32(0)


def _signed_u16(v: np.float32) -> np.float32:
    """A radius kept as uint16 magnitude plus a direction bit (loiter_ccw = v < 0)."""
    magnitude = _u16(abs(v)) if not np.isnan(v) else F32(0)
    return -magnitude if v < 0 else magnitude


_ZERO = F32(0)

# command -> (param1..4 as ArduPilot returns them) from the sent float32 params; missing: kept as sent.
# AP_Mission::mavlink_int_to_mission_cmd / mission_cmd_to_mavlink_int (see docs/real-autopilots.md)
_AP_PARAMS = {
    17: lambda p: (_ZERO, _ZERO, _signed_u16(p[2]), _ZERO),
    18: lambda p: (_u8(p[0]), _ZERO, _signed_u16(p[2]), _flag(p[3])),
    19: lambda p: (_u16(p[0]), _ZERO, _sign(p[2]), _flag(p[3])),
    20: lambda p: (_ZERO, _ZERO, _ZERO, _ZERO),
    21: lambda p: (_u16(p[0]), _ZERO, _ZERO, _sign(p[3])),
    22: lambda p: (_u16(p[0]), _ZERO, _ZERO, _ZERO),
    31: lambda p: (_ZERO, _signed_u16(p[1]), _ZERO, _flag(p[3])),
    82: lambda p: (_u16(p[0]), _ZERO, _ZERO, _ZERO),
    84: lambda p: (_ZERO, _ZERO, _ZERO, _ZERO),
    85: lambda p: (_u16(p[0]), _ZERO, _ZERO, _ZERO),
    93: lambda p: (p[0], _i8(p[1]), _i8(p[2]), _i8(p[3])),
    112: lambda p: (p[0], _ZERO, _ZERO, _ZERO),
    115: lambda p: (p[0], p[1], _i8(p[2]), _u8(p[3])),
    177: lambda p: (_u16(p[0]), _i16(p[1]), _ZERO, _ZERO),
    178: lambda p: (_u8(p[0]), p[1], p[2], _ZERO),
    179: lambda p: (_u16(p[0]), _ZERO, _ZERO, _ZERO),
    181: lambda p: (_u8(p[0]), _u8(p[1]), _ZERO, _ZERO),
    183: lambda p: (_u8(p[0]), _u16(p[1]), _ZERO, _ZERO),
    189: lambda p: (_ZERO, _ZERO, _ZERO, _ZERO),
    201: lambda p: (_u16(p[0]), _ZERO, _ZERO, _ZERO),
    202: lambda p: (_u8(p[0]), _u16(p[1]), _u8(p[2]), _u16(p[3])),
    203: lambda p: (_u8(p[0]), _u8(p[1]), _i8(p[2]), _u8(p[3])),
    205: lambda p: (p[0], p[1], p[2], _ZERO),
    206: lambda p: (p[0], _ZERO, _u8(p[2]), _ZERO),
    1000: lambda p: (_i8(p[0]), _i16(p[1]), _i8(p[2]), _i8(p[3])),
    2000: lambda p: (_u8(p[0]), p[1], _u16(p[2]), _u16(p[3])),
    2001: lambda p: (_u16(p[0]), _ZERO, _ZERO, _ZERO),
    2500: lambda p: (_u8(p[0]), _ZERO, _ZERO, _ZERO),
    2501: lambda p: (_u8(p[0]), _ZERO, _ZERO, _ZERO),
    3000: lambda p: (_u8(p[0]), _ZERO, _ZERO, _ZERO),
}
_AP_RAW_XYZ = {  # positionless commands that keep x / y / z: (x, y, z) from the sent ones
    202: lambda it: (int(_u8(F32(it.x))), int(_u8(F32(it.y))), _f32(it.z)),
    203: lambda it: (int(_u8(F32(it.x))), int(_u8(F32(it.y))), _ZERO),
    205: lambda it: (0, 0, F32(2)),  # MAV_MOUNT_MODE_MAVLINK_TARGETING
    1000: lambda it: (int(_u8(F32(it.x))), 0, _u8(_f32(it.z))),
}


def _params(item: MissionItem) -> tuple[np.float32, ...]:
    return tuple(_f32(v) for v in (item.param1, item.param2, item.param3, item.param4))


def _with(item: MissionItem, p, **fields) -> MissionItem:
    """``item`` with params ``p`` and the other fields given, every float a float32 value."""
    z = fields.pop("z", item.z)
    return replace(
        item, param1=float(p[0]), param2=float(p[1]), param3=float(p[2]), param4=float(p[3]),
        z=float(_f32(z)), **fields,
    )  # fmt: skip


def wire(item: MissionItem) -> MissionItem:
    """``item`` as a MISSION_ITEM_INT carries it: params and z rounded to float32."""
    return _with(item, _params(item))


def _ap_alt_back(z: np.float32) -> np.float32:
    """A Location altitude: ``alt = packet.z * 100.0f`` (float32, truncated to int32 cm) on upload,
    ``packet.z = alt * 0.01f`` (float32) on download; z = 65.38 comes back as 65.369995."""
    cm = int(z * F32(100))  # |z| < 83000: no overflow, 8.3e6 cm is exact in float32
    return F32(cm) * F32(0.01)


def _ap_refusal(item: MissionItem) -> MissionResult | None:
    if item.mission_type == MissionType.MISSION and item.command not in _AP_LOCATION:
        return None
    z = _f32(item.z)
    if np.isnan(z) or abs(z) >= LOCATION_ALT_MAX_M:
        return MissionResult.INVALID_PARAM7
    return None


def _px4_refusal(item: MissionItem) -> MissionResult | None:
    # the mock's convention (sitl_mock/mission_server.py): a non-finite z is refused
    return None if np.isfinite(_f32(item.z)) else MissionResult.INVALID_PARAM7


def refusal(model: Model, item: MissionItem) -> MissionResult | None:
    """The MISSION_ACK error with which the autopilot of ``model`` refuses ``item`` for its altitude
    (ArduPilot: ``isnan(packet.z) || fabsf(packet.z) >= LOCATION_ALT_MAX_M`` on an item stored in a
    Location), None when it stores it."""
    if model in (ARDUCOPTER, ARDUPLANE):
        return _ap_refusal(item)
    if model is PX4:
        return _px4_refusal(item)
    return None


def _ardupilot(item: MissionItem, plane: bool) -> MissionItem:
    """AP_Mission::mavlink_int_to_mission_cmd, then mission_cmd_to_mavlink_int (AP_Mission.cpp):
    autocontinue always 1; a Location keeps lat/lon exactly and the altitude in cm, reported in
    frame 0 / 3 / 10; positionless commands come back in frame 0 with x = y = z = 0 unless they
    store them raw."""
    if _ap_refusal(item) is not None:
        return wire(item)
    item = replace(item, autocontinue=1)
    c = item.command
    p = _params(item)
    if item.mission_type != MissionType.MISSION or c in _AP_LOCATION:
        item = replace(item, frame=_AP_FRAMES.get(item.frame, item.frame), z=_ap_alt_back(_f32(item.z)))
    else:
        x, y, z = _AP_RAW_XYZ[c](item) if c in _AP_RAW_XYZ else (0, 0, _ZERO)
        item = replace(item, frame=0, x=x, y=y, z=z)
    if item.mission_type != MissionType.MISSION:
        return _with(item, p)
    if c == 16:  # one 16-bit p1: ArduPlane radius | pass radius << 8, the rest hold time
        p = ((_ZERO, min(_u16(p[1]), F32(255)), min(_u16(p[2]), F32(255)), _ZERO) if plane
             else (_u16(p[0]), _ZERO, _ZERO, _ZERO))  # fmt: skip
    elif c in _AP_PARAMS:
        p = _AP_PARAMS[c](p)
    return _with(item, p)


def ARDUCOPTER(item: MissionItem) -> MissionItem:  # noqa: N802 - a model, named like the constants
    return _ardupilot(item, plane=False)


def ARDUPLANE(item: MissionItem) -> MissionItem:  # noqa: N802
    return _ardupilot(item, plane=True)


# PX4 mathlib / matrix, all in float: radians(x) = x * (float(M_PI) / 180.f),
# degrees(x) = x * (180.f / float(M_PI)), wrap_2pi(x) = wrap(x, 0.f, float(M_TWOPI))
_D2R = F32(np.pi) / F32(180)
_R2D = F32(180) / F32(np.pi)
_TWO_PI = F32(2 * np.pi)
_INV_TWO_PI = F32(1) / _TWO_PI


def _px4_yaw(deg: np.float32) -> np.float32:
    """param4 -> ``yaw = wrap_2pi(math::radians(param4))`` -> ``param4 = math::degrees(yaw)``."""
    with np.errstate(invalid="ignore", over="ignore"):
        r = deg * _D2R
        if not (F32(0) <= r < _TWO_PI):  # matrix::detail::wrap_floating
            r = r - _TWO_PI * np.floor((r - F32(0)) * _INV_TWO_PI)
        return r * _R2D


# command -> param1..4 as PX4 returns them (mavlink_mission.cpp format_mavlink_mission_item)
_PX4_PARAMS = {
    16: lambda p: (p[0], p[1], _ZERO, _px4_yaw(p[3])),
    17: lambda p: (_ZERO, _ZERO, p[2], _px4_yaw(p[3])),
    19: lambda p: (p[0], _flag(p[1]), p[2], _flag(p[3])),
    21: lambda p: (_ZERO, _u16(p[1]), _ZERO, _px4_yaw(p[3])),
    22: lambda p: (_ZERO, _ZERO, _ZERO, _px4_yaw(p[3])),
    31: lambda p: (_flag(p[0]), p[1], _ZERO, _flag(p[3])),
    84: lambda p: (_ZERO, _ZERO, _ZERO, _px4_yaw(p[3])),
    85: lambda p: (_ZERO, _ZERO, _ZERO, _px4_yaw(p[3])),
    177: lambda p: (_i16(p[0]), _u16(p[1]), p[2], p[3]),  # do_jump_mission_index / repeat_count
}


def _px4_param_xy(v: int) -> int:
    """x / y of a MAV_FRAME_MISSION item: kept in a float32 params[4] / params[5], sent back as
    ``round(params[4])`` (C round: half away from zero), saturated to int32."""
    f = float(F32(v))
    r = int(np.floor(abs(f) + 0.5)) * (1 if f >= 0 else -1)
    return min(max(r, -(2**31)), 2**31 - 1)


def PX4(item: MissionItem) -> MissionItem:  # noqa: N802
    """mavlink_mission.cpp parse_mavlink_mission_item / format_mavlink_mission_item: fence points
    keep position and radius / vertex count (frame GLOBAL_INT, autocontinue 0), rally points their
    position; positional items come back in the _INT frames, positionless ones as sent with x / y
    through a float32."""
    if _px4_refusal(item) is not None:
        return wire(item)
    p = _params(item)
    if item.mission_type == MissionType.FENCE:  # vertex_count = (uint16_t)(param1 + 0.5f), circle_radius
        c = item.command
        p1 = _u16(p[0] + F32(0.5)) if c in (5001, 5002) else p[0] if c in (5003, 5004) else _ZERO
        return _with(replace(item, frame=5, autocontinue=0), (p1, _ZERO, _ZERO, _ZERO))
    if item.mission_type == MissionType.RALLY:
        return _with(replace(item, frame=_PX4_FRAMES.get(item.frame, item.frame)), (_ZERO,) * 4)
    rule = _PX4_PARAMS.get(item.command)
    if has_position(item.command):  # format sets param1..4 = 0, then the command's own fields
        item = replace(item, frame=_PX4_FRAMES.get(item.frame, item.frame))
        return _with(item, (_ZERO,) * 4 if rule is None else rule(p))
    if item.frame == 2:  # MAV_FRAME_MISSION
        item = replace(item, x=_px4_param_xy(item.x), y=_px4_param_xy(item.y))
    return _with(item, p if rule is None else rule(p))


def GENERIC(item: MissionItem) -> MissionItem:  # noqa: N802
    """A store-everything vehicle (MAVSDK's MissionRawServer): what was sent comes back."""
    return wire(item)
