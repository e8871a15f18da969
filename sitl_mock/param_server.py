"""The mock autopilot's parameter protocol: PARAM_REQUEST_LIST, PARAM_REQUEST_READ, PARAM_SET; I/O-free.

``ParamServer`` serves the vehicle's own ``params`` dict (name -> value, a float; the flight code
reads it) with each name's MAV_PARAM_TYPE (``types``; REAL32 where absent), numbered by name:
param_index is a name's position in the sorted names, param_count their number. ``handle(msg)``
and ``poll()`` (once a tick) return the messages to send. What each autopilot does, from its source:

ArduPilot (libraries/GCS_MAVLink/GCS_Param.cpp):
- PARAM_REQUEST_LIST: ``handle_param_request_list`` starts a stream that ``queued_param_send``
  sends: every parameter with its param_index (0 .. count - 1) and param_count, at most 5 a call on
  a link without flow control (UDP); the mock sends 5 a tick. ArduPilot's order is its parameter
  table's (``AP_Param::first`` / ``next_scalar``), the mock's by name: any fixed order serves a
  GCS, which keys on the index. A new PARAM_REQUEST_LIST restarts the stream.
- PARAM_REQUEST_READ (``param_io_timer``): param_index >= 0 -> that parameter, the reply carrying
  the index asked; -1 -> by name, the reply's index -1; an unknown one -> no reply.
- PARAM_SET (``handle_param_set``): the parameter keeps its own type whatever param_type says
  (``AP_Param::find`` -> ``user_set_value``); an integer is rounded as ``AP_Param::set_float`` does
  (+-0.01 before the cast, clamped to its range); NaN / inf or an unknown name -> nothing. The new
  value goes out with index -1 (``GCS::send_parameter_value``).
- Every type's value travels cast to float (``cast_to_float``); ArduPilot's types are INT8, INT16,
  INT32 and REAL32.
PX4 (src/modules/mavlink/mavlink_parameters.cpp, ``MavlinkParametersManager``):
- PARAM_REQUEST_LIST: first ``_HASH_CHECK`` (param_index -1, UINT32, a hash of the values; the
  mock's a CRC-32), then every parameter, up to 20 a ``send()`` on UDP (the mock: 20 a tick), in
  PX4's order, which is by name (its parameter table is generated sorted). A request while a
  stream runs restarts it at index 0 without the hash.
- An INT32's four bytes go in the float field (bytewise: ``send_param``'s memcpy); types INT32 and
  REAL32.
- PARAM_SET: taken only in the parameter's own type (INT32 with MAV_PARAM_TYPE_INT32, a float with
  REAL32); any other -> nothing sent ("invalid param" on PX4's console), as for an unknown name.
  The echo carries the parameter's index (``send_param``).
- PARAM_REQUEST_READ: by index, or by name (param_index -1), answered with the real index.

``sets`` lists the name of every PARAM_SET received, taken or not (tests count them).
"""

from __future__ import annotations

import math
import struct
import zlib
from dataclasses import dataclass

from sitl_mock.link import mavlink

__all__ = ["PARAM_RULES", "STOCK_PARAMS", "ParamRules", "ParamServer", "stock_params"]

REAL32 = mavlink.MAV_PARAM_TYPE_REAL32
INT8, INT16, INT32 = mavlink.MAV_PARAM_TYPE_INT8, mavlink.MAV_PARAM_TYPE_INT16, mavlink.MAV_PARAM_TYPE_INT32
_INT_FORMATS = {
    INT8: ("<b", -(2**7), 2**7 - 1),
    INT16: ("<h", -(2**15), 2**15 - 1),
    INT32: ("<i", -(2**31), 2**31 - 1),
}
HASH_CHECK = "_HASH_CHECK"


@dataclass(frozen=True)
class ParamRules:
    """How one autopilot family runs the parameter protocol (see the module docstring)."""

    per_tick: int  # PARAM_VALUEs of a list stream sent a tick
    bytewise: bool  # an integer's bytes in the float field (PX4), else cast to float (ArduPilot)
    hash_first: bool  # a list starts with _HASH_CHECK (PX4)
    real_index: bool  # the answers to a read by name and to a set carry the index (PX4), else -1
    strict_set_type: bool  # PARAM_SET refused unless param_type is the parameter's own (PX4)


PARAM_RULES = {
    "ardupilot": ParamRules(5, bytewise=False, hash_first=False, real_index=False, strict_set_type=False),
    "px4": ParamRules(20, bytewise=True, hash_first=True, real_index=True, strict_set_type=True),
}

# A realistic handful of each autopilot's own parameters, beyond the ones the flight rules serve
# (sitl_mock/profiles.py): name -> (default, MAV_PARAM_TYPE). "SYSID" is the vehicle's system id.
# ArduCopter and ArduPlane: the defaults of ArduPilot's parameter reference
# (ardupilot.org/copter/docs/parameters.html, /plane/docs/parameters.html) and the types of their
# declarations (AP_Int8 / AP_Int16 / AP_Int32 / AP_Float; RTL_ALT an AP_Int32 in
# ArduCopter/Parameters.h), under the names ArduPilot 4.7 / 4.8 uses (MAV_SYSID, WP_SPD:
# docs/real-autopilots.md). PX4: the defaults of PX4's parameter reference
# (docs.px4.io/main/en/advanced_config/parameter_reference.html), INT32 or FLOAT (PX4's BOOL, sent
# as UINT8, is not modelled). The defaults were written from those references, not measured on a
# SITL: a release may differ.
STOCK_PARAMS: dict[str, dict[str, tuple[float, int] | str]] = {
    "ArduCopter": {
        "MAV_SYSID": "SYSID",
        "WP_SPD": (10.0, REAL32),  # [m/s]
        "RTL_ALT": (1500.0, INT32),  # [cm]
        "RTL_LOIT_TIME": (5000.0, INT32),  # [ms]
        "LAND_SPEED": (50.0, INT16),  # [cm/s]
        "FENCE_ENABLE": (0.0, INT8),
        "FENCE_TYPE": (7.0, INT8),  # altitude, circle and polygon
        "FENCE_ACTION": (1.0, INT8),  # RTL or land
        "FENCE_ALT_MAX": (100.0, REAL32),  # [m]
        "FENCE_RADIUS": (300.0, REAL32),  # [m]
        "DISARM_DELAY": (10.0, INT8),  # [s]: FlightRules.auto_disarm_s
        "FS_GCS_ENABLE": (0.0, INT8),
        "FS_THR_ENABLE": (1.0, INT8),
        "FLTMODE_CH": (5.0, INT8),
        "BATT_CAPACITY": (3300.0, INT32),  # [mAh]
        "LOG_BITMASK": (176126.0, INT32),
    },
    "ArduPlane": {
        "MAV_SYSID": "SYSID",
        "WP_RADIUS": (90.0, INT16),  # [m]
        "WP_LOITER_RAD": (60.0, INT16),  # [m]
        "TECS_CLMB_MAX": (5.0, REAL32),  # [m/s]
        "TECS_SINK_MAX": (5.0, REAL32),  # [m/s]
        "PTCH_LIM_MAX_DEG": (20.0, REAL32),  # [deg]
        "PTCH_LIM_MIN_DEG": (-25.0, REAL32),  # [deg]
        "FENCE_ENABLE": (0.0, INT8),
        "FENCE_ALT_MAX": (100.0, REAL32),  # [m]
        "FS_SHORT_ACTN": (0.0, INT8),
        "FS_LONG_ACTN": (0.0, INT8),
        "BATT_CAPACITY": (3300.0, INT32),  # [mAh]
    },
    "PX4": {
        "MAV_SYS_ID": "SYSID",
        "MPC_XY_CRUISE": (5.0, REAL32),  # [m/s]
        "MPC_XY_VEL_MAX": (12.0, REAL32),  # [m/s]
        "MPC_Z_VEL_MAX_UP": (3.0, REAL32),  # [m/s]
        "MPC_Z_VEL_MAX_DN": (1.5, REAL32),  # [m/s]
        "MIS_TAKEOFF_ALT": (2.5, REAL32),  # [m]
        "NAV_ACC_RAD": (10.0, REAL32),  # [m]
        "RTL_RETURN_ALT": (60.0, REAL32),  # [m]
        "RTL_DESCEND_ALT": (30.0, REAL32),  # [m]
        "COM_DISARM_PRFLT": (10.0, REAL32),  # [s]: FlightRules.auto_disarm_s
        "COM_RC_LOSS_T": (0.5, REAL32),  # [s]
        "NAV_DLL_ACT": (0.0, INT32),  # data link loss: disabled
        "NAV_RCL_ACT": (2.0, INT32),  # RC loss: return
        "GF_ACTION": (2.0, INT32),  # geofence breach: hold
        "GF_MAX_HOR_DIST": (0.0, REAL32),  # [m], 0: off
        "GF_MAX_VER_DIST": (0.0, REAL32),  # [m], 0: off
    },
}


def stock_params(flight_name: str, sysid: int) -> dict[str, tuple[float, int]]:
    """STOCK_PARAMS of a FlightRules.name (none for one not listed), the system id filled in
    (ArduPilot's MAV_SYSID an AP_Int16, PX4's MAV_SYS_ID an INT32)."""
    out = {}
    for name, spec in STOCK_PARAMS.get(flight_name, {}).items():
        out[name] = (float(sysid), INT16 if name == "MAV_SYSID" else INT32) if spec == "SYSID" else spec
    return out


def _value_bytes(msg: mavlink.MAVLink_message) -> bytes:
    """The 4 bytes of a PARAM_SET's param_value, from its frame (pymavlink's float would quiet a
    signalling-NaN pattern: a bytewise int32 such as -5000000)."""
    frame = getattr(msg, "_msgbuf", None)
    start = {0xFD: 10, 0xFE: 6}.get(frame[0]) if frame else None
    if start is not None and len(frame) >= start + 4:
        return bytes(frame[start : start + 4])
    return struct.pack("<f", msg.param_value)


class _ParamValue(mavlink.MAVLink_param_value_message):
    """PARAM_VALUE whose param_value is the 4 bytes given (a bytewise int32 may be a signalling-NaN
    pattern, which a Python float would quiet)."""

    def __init__(self, name: str, data: bytes, param_type: int, count: int, index: int) -> None:
        super().__init__(name.encode(), struct.unpack("<f", data)[0], param_type, count, index)
        self.value_bytes = data

    def pack(self, mav: mavlink.MAVLink, force_mavlink1: bool = False) -> bytes:
        index = self.param_index & 0xFFFF  # a uint16 on the wire: -1 goes as 65535, as C sends it
        ids = (self.param_count, index, self._param_id_raw, self.param_type)
        payload = self.value_bytes + self.unpacker.pack(0.0, *ids)[4:]
        return self._pack(mav, self.crc_extra, payload, force_mavlink1=force_mavlink1)


class ParamServer:
    """The parameter protocol of one vehicle over its ``params`` and ``types`` (see the module docstring)."""

    def __init__(self, profile: str, params: dict[str, float], types: dict[str, int]) -> None:
        self.rules = PARAM_RULES[profile]
        self.params, self.types = params, types
        self.sets: list[str] = []
        self._stream: list[str] = []  # names still to send of a PARAM_REQUEST_LIST
        self._streaming = False

    def handle(self, msg: mavlink.MAVLink_message) -> list[mavlink.MAVLink_message]:
        kind = msg.get_type()
        if kind == "PARAM_REQUEST_LIST":
            return self._request_list()
        if kind == "PARAM_REQUEST_READ":
            return self._request_read(msg)
        if kind == "PARAM_SET":
            return self._set(msg)
        return []

    def poll(self) -> list[mavlink.MAVLink_message]:
        """The next PARAM_VALUEs of a list stream."""
        if not self._stream:
            self._streaming = False
            return []
        batch, self._stream = self._stream[: self.rules.per_tick], self._stream[self.rules.per_tick :]
        return [self._value(name, self._names().index(name)) for name in batch]

    def stop(self) -> None:
        """Forget a list stream (a reboot)."""
        self._stream, self._streaming = [], False

    def _names(self) -> list[str]:
        return sorted(self.params)

    def _request_list(self) -> list[mavlink.MAVLink_message]:
        names = self._names()
        restart = self._streaming
        self._stream, self._streaming = list(names), True
        if not self.rules.hash_first or restart:
            return []
        digest = zlib.crc32(b"".join(n.encode() + self._bytes(n) for n in names))
        uint32 = mavlink.MAV_PARAM_TYPE_UINT32
        return [_ParamValue(HASH_CHECK, struct.pack("<I", digest), uint32, len(names), -1)]

    def _request_read(self, msg: mavlink.MAVLink_message) -> list[mavlink.MAVLink_message]:
        names = self._names()
        if msg.param_index >= 0:
            if msg.param_index >= len(names):
                return []
            return [self._value(names[msg.param_index], msg.param_index)]
        if msg.param_id not in self.params:
            return []
        return [self._value(msg.param_id, names.index(msg.param_id) if self.rules.real_index else -1)]

    def _set(self, msg: mavlink.MAVLink_message) -> list[mavlink.MAVLink_message]:
        name = msg.param_id
        self.sets.append(name)
        own = self.types.get(name, REAL32)
        if name not in self.params or (self.rules.strict_set_type and msg.param_type != own):
            return []
        data = _value_bytes(msg)
        if own in _INT_FORMATS and self.rules.bytewise:
            value = float(struct.unpack(_INT_FORMATS[own][0], data)[0])
        else:
            value = struct.unpack("<f", data)[0]
        if not math.isfinite(value):
            return []
        if own in _INT_FORMATS and not self.rules.bytewise:  # AP_Param::set_float
            _, lo, hi = _INT_FORMATS[own]
            value = float(int(min(max(value + math.copysign(0.01, value), lo), hi)))
        self.params[name] = value
        return [self._value(name, self._names().index(name) if self.rules.real_index else -1)]

    def _bytes(self, name: str) -> bytes:
        """The 4 bytes of ``name``'s value as this autopilot sends them."""
        own = self.types.get(name, REAL32)
        if own in _INT_FORMATS and self.rules.bytewise:
            return struct.pack(_INT_FORMATS[own][0], int(self.params[name]))
        return struct.pack("<f", self.params[name])

    def _value(self, name: str, index: int) -> mavlink.MAVLink_message:
        own = self.types.get(name, REAL32)
        return _ParamValue(name, self._bytes(name), own, len(self.params), index)
