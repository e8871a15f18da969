"""A vehicle's parameters over MAVLink: download them all, read one, set one, typed.

The parameter protocol (https://mavlink.io/en/services/parameter.html) as implemented here:

- Download (``download_params``): PARAM_REQUEST_LIST, then every PARAM_VALUE from the vehicle's
  component is kept by its ``param_index`` (0 .. ``param_count`` - 1). One with an index outside
  that range is not part of the list: PX4's ``_HASH_CHECK`` (index -1, sent first) and the echo of a
  PARAM_SET (ArduPilot index -1, ``GCS::send_parameter_value``). When no new PARAM_VALUE came for
  ``QUIET_S``, the missing indices are asked for ``READ_BATCH`` at a time with PARAM_REQUEST_READ
  (param_index = i, empty name), the next batch as soon as one is answered, as MAVProxy does
  (mavproxy_param.py ``fetch_check``: 10 at a time after 1 s of silence; ArduPilot queues at most
  20 such requests, GCS_Param.cpp ``param_requests(20)``). No answer at all to PARAM_REQUEST_LIST
  for ``QUIET_S``: it is sent again. The download fails (UserError naming the vehicle and how many
  are missing) when ``timeout_s`` passes without a new parameter, or once the vehicle's
  ``param_count`` is known, after the mission transfers' overall bound (20 s + 1 s a parameter,
  transfer.py), so a vehicle that dribbles one new value every few seconds cannot hold it for
  hours. Deadlines read the loop's clock (gcs_planner.core.lockstep.now_s).
- Values: the 4 bytes of PARAM_VALUE.param_value are read from the frame itself. ArduPilot sends
  every type as a float (C cast, ``AP_Param::cast_to_float``); PX4 copies an integer's bytes into
  the float field (bytewise: ``MavlinkParametersManager::send_param``'s memcpy), as MAVProxy reads
  it for a vehicle whose HEARTBEAT says MAV_AUTOPILOT_PX4 (``handle_px4_param_value``). A REAL32
  stays the float32 the vehicle sent; an integer type becomes a Python int. pymavlink's own float
  would turn a signalling-NaN bit pattern (some negative int32s, bytewise) into a quiet one, so
  neither reading nor sending goes through it for the value.
- Set (``set_param``): PARAM_SET with the parameter's own MAV_PARAM_TYPE (PX4 refuses a type that
  is not the parameter's, ``handle_message``: "invalid param"; ArduPilot uses its own type
  whatever the message says), confirmed by the PARAM_VALUE echo (ArduPilot and PX4 answer every
  PARAM_SET with the parameter's new value), resent like a command. ``read_param``:
  PARAM_REQUEST_READ by name, resent the same way; ArduPilot does not answer for a name it does not
  have (``GCS_MAVLINK::handle_param_request_read``), so no reply means None.
"""

from __future__ import annotations

import asyncio
import math
import struct
from collections.abc import Callable
from dataclasses import dataclass

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs_planner.core.errors import UserError
from gcs_planner.core.lockstep import now_s
from gcs_planner.mavlink.command import COMMAND_RETRIES, COMMAND_RETRY_S
from gcs_planner.mavlink.link import MavlinkLink
from gcs_planner.mavlink.transfer import DEADLINE_BASE_S, DEADLINE_PER_ITEM_S

__all__ = [
    "DOWNLOAD_TIMEOUT_S", "INT_RANGES", "QUIET_S", "READ_BATCH", "REAL32", "TYPE_NAMES", "Param",
    "download_params", "fits_float32", "float32", "from_wire", "read_param", "set_param", "to_wire",
    "type_name",
]  # fmt: skip

QUIET_S = 1.0  # no new PARAM_VALUE this long -> ask for the missing ones [s]
READ_BATCH = 10  # PARAM_REQUEST_READs in flight at once (MAVProxy's batch)
DOWNLOAD_TIMEOUT_S = 10.0  # no new parameter this long -> the download fails [s]
REAL32 = mavlink.MAV_PARAM_TYPE_REAL32
TYPE_NAMES = {
    mavlink.MAV_PARAM_TYPE_UINT8: "UINT8", mavlink.MAV_PARAM_TYPE_INT8: "INT8",
    mavlink.MAV_PARAM_TYPE_UINT16: "UINT16", mavlink.MAV_PARAM_TYPE_INT16: "INT16",
    mavlink.MAV_PARAM_TYPE_UINT32: "UINT32", mavlink.MAV_PARAM_TYPE_INT32: "INT32",
    mavlink.MAV_PARAM_TYPE_UINT64: "UINT64", mavlink.MAV_PARAM_TYPE_INT64: "INT64",
    REAL32: "REAL32", mavlink.MAV_PARAM_TYPE_REAL64: "REAL64",
}  # fmt: skip
# the integer types that fit the 4-byte value field: (struct format of their bytes, lowest, highest)
_INTS = {
    mavlink.MAV_PARAM_TYPE_UINT8: ("<B", 0, 2**8 - 1),
    mavlink.MAV_PARAM_TYPE_INT8: ("<b", -(2**7), 2**7 - 1),
    mavlink.MAV_PARAM_TYPE_UINT16: ("<H", 0, 2**16 - 1),
    mavlink.MAV_PARAM_TYPE_INT16: ("<h", -(2**15), 2**15 - 1),
    mavlink.MAV_PARAM_TYPE_UINT32: ("<I", 0, 2**32 - 1),
    mavlink.MAV_PARAM_TYPE_INT32: ("<i", -(2**31), 2**31 - 1),
}
INT_RANGES = {t: (lo, hi) for t, (_, lo, hi) in _INTS.items()}
_F32 = struct.Struct("<f")


@dataclass(frozen=True)
class Param:
    """One parameter as the vehicle holds it: ``value`` an int for integer types, else the float32
    it sent (as a Python float); ``param_type`` its MAV_PARAM_TYPE; ``index`` its param_index."""

    name: str
    value: int | float
    param_type: int
    index: int = -1


def type_name(param_type: int) -> str:
    return TYPE_NAMES.get(param_type, f"type {param_type}")


def from_wire(data: bytes, param_type: int, bytewise: bool) -> int | float:
    """The value of a param_value field's 4 bytes ``data`` (little endian) for ``param_type``."""
    if param_type in _INTS and bytewise:
        fmt = _INTS[param_type][0]
        return struct.unpack_from(fmt, data)[0]
    value = _F32.unpack(data)[0]
    if param_type in _INTS and math.isfinite(value):
        return int(value)  # ArduPilot's cast of an integer to float is exact below 2^24
    return value


def to_wire(value: float, param_type: int, bytewise: bool, name: str = "parameter") -> bytes:
    """The 4 bytes of param_value holding ``value`` as ``param_type``; UserError when it cannot."""
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise UserError(f"parameter {name} must be a finite number, got {value!r}")
    if param_type == REAL32:
        if not fits_float32(value):
            raise UserError(f"parameter {name} = {value!r} is beyond the float32 range of a REAL32")
        return _F32.pack(value)
    if param_type not in _INTS:
        raise UserError(f"parameter {name} is {type_name(param_type)}, which PARAM_SET cannot carry")
    fmt, lo, hi = _INTS[param_type]
    if value != int(value) or not lo <= value <= hi:
        raise UserError(f"parameter {name} is {type_name(param_type)} ({lo}..{hi}), got {value!r}")
    if bytewise:
        return struct.pack(fmt, int(value)).ljust(4, b"\0")
    return _F32.pack(float(value))


def float32(value: float) -> float:
    """``value`` rounded to the nearest float32 (as a Python float); OverflowError beyond its range."""
    return _F32.unpack(_F32.pack(value))[0]


def fits_float32(value: float) -> bool:
    """Whether ``value`` rounds to a finite float32 (3.4028235e38 does, 3.5e38 does not)."""
    try:
        _F32.pack(value)
    except OverflowError:
        return False
    return True


def _value_bytes(msg, raw: bytes) -> bytes:
    """The 4 bytes of a PARAM_VALUE frame's param_value field (the first of its payload)."""
    start = {0xFD: 10, 0xFE: 6}.get(raw[0]) if raw else None
    if start is not None and len(raw) >= start + 4:
        return bytes(raw[start : start + 4])
    return _F32.pack(msg.param_value)


class _ParamSet(mavlink.MAVLink_param_set_message):
    """PARAM_SET whose param_value is the 4 bytes given: pymavlink packs it from a Python float,
    which would quiet a signalling-NaN bit pattern (a bytewise int32 such as -5000000)."""

    def __init__(self, sysid: int, compid: int, name: str, data: bytes, param_type: int) -> None:
        super().__init__(sysid, compid, name.encode(), _F32.unpack(data)[0], param_type)
        self.value_bytes = data

    def pack(self, mav: mavlink.MAVLink, force_mavlink1: bool = False) -> bytes:
        rest = self.unpacker.pack(0.0, self.target_system, self.target_component, self._param_id_raw,
                                  self.param_type)[4:]  # fmt: skip
        return self._pack(mav, self.crc_extra, self.value_bytes + rest, force_mavlink1=force_mavlink1)


async def download_params(
    link: MavlinkLink,
    sysid: int,
    compid: int = 1,
    *,
    bytewise: bool = False,
    timeout_s: float = DOWNLOAD_TIMEOUT_S,
    progress: Callable[[int, int], None] | None = None,
) -> list[Param]:
    """Every parameter of vehicle ``sysid`` (component ``compid``), in param_index order; see the
    module docstring. ``progress(received, count)`` is called for each new one."""
    link.check_target(sysid)
    got: dict[int, Param] = {}
    count: int | None = None
    outside = 0  # PARAM_VALUEs that are no entry of a list
    arrived = asyncio.Event()

    def on_frame(msg, raw: bytes, t_s: float) -> None:
        nonlocal count, outside
        if msg.get_type() != "PARAM_VALUE" or msg.get_srcComponent() != compid:
            return
        total, index = msg.param_count, msg.param_index
        if not (0 < total < 65535 and 0 <= index < total):
            outside += 1
            return  # _HASH_CHECK, a PARAM_SET's echo: not an entry of the list
        if total != count:  # the first, or the vehicle's list changed: keep what still fits
            count = total
            for i in [i for i in got if i >= total]:
                del got[i]
        if index not in got:
            value = from_wire(_value_bytes(msg, raw), msg.param_type, bytewise)
            got[index] = Param(msg.param_id, value, msg.param_type, index)
            arrived.set()
            if progress is not None:
                progress(len(got), total)

    unsubscribe = link.subscribe(on_frame, sysid=sysid)
    try:
        await _collect(link, sysid, compid, got, lambda: count, arrived, timeout_s)
    except _NoList:
        heard = (
            f" ({outside} outside any list: param_count 0 or 65535, or an index past it)" if outside else ""
        )
        raise UserError(f"vehicle {sysid} component {compid}: no PARAM_VALUE of its list within"
                        f" {timeout_s:g} s of PARAM_REQUEST_LIST{heard}") from None  # fmt: skip
    finally:
        unsubscribe()
    return [got[i] for i in range(len(got))]


class _NoList(Exception):
    """No PARAM_VALUE that is an entry of a list came (download_params words the error)."""


async def _collect(
    link: MavlinkLink,
    sysid: int,
    compid: int,
    got: dict[int, Param],
    count_of: Callable[[], int | None],
    arrived: asyncio.Event,
    timeout_s: float,
) -> None:
    """Ask for the list, then for what is missing, until every index arrived or ``timeout_s``
    passed without a new one (_NoList: without any entry of a list at all)."""
    request_list = mavlink.MAVLink_param_request_list_message(sysid, compid)
    link.send(request_list)
    started = last_new = now_s()
    asked: set[int] = set()
    while count_of() is None or len(got) < count_of():
        if (count := count_of()) is not None and now_s() - started > (
            limit_s := DEADLINE_BASE_S + DEADLINE_PER_ITEM_S * count
        ):
            raise UserError(f"vehicle {sysid}: {count - len(got)} of {count} parameters missing after"
                            f" {limit_s:g} s")  # fmt: skip
        arrived.clear()
        try:
            await asyncio.wait_for(arrived.wait(), QUIET_S)
            last_new = now_s()
            if asked and asked <= got.keys() and len(got) < count_of():  # a batch answered: the next
                asked = _ask_missing(link, sysid, compid, got, count_of())
            continue
        except TimeoutError:
            pass
        count = count_of()
        if now_s() - last_new >= timeout_s:
            if count is None:
                raise _NoList
            first = min(set(range(count)) - got.keys())
            raise UserError(f"vehicle {sysid}: {count - len(got)} of {count} parameters missing (first:"
                            f" index {first}) after {timeout_s:g} s without a new one")  # fmt: skip
        if count is None:
            link.send(request_list)
        else:
            asked = _ask_missing(link, sysid, compid, got, count)


def _ask_missing(link: MavlinkLink, sysid: int, compid: int, got: dict, count: int) -> set[int]:
    """PARAM_REQUEST_READ by index for the first READ_BATCH missing indices; returns them."""
    missing = [i for i in range(count) if i not in got][:READ_BATCH]
    for index in missing:
        link.send(mavlink.MAVLink_param_request_read_message(sysid, compid, b"", index))
    return set(missing)


async def _param_value(
    link: MavlinkLink, sysid: int, name: str, request, retry_s: float, bytewise: bool = False
) -> tuple[int | float, int] | None:
    """Send ``request`` until the vehicle answers with PARAM_VALUE for ``name``; its (value, type),
    None when it never does."""
    link.check_target(sysid)
    loop = asyncio.get_running_loop()
    for _ in range(COMMAND_RETRIES + 1):
        answer: asyncio.Future = loop.create_future()

        def on_frame(msg, raw: bytes, t_s: float, answer=answer) -> None:
            if not answer.done() and msg.get_type() == "PARAM_VALUE" and msg.param_id == name:
                value = from_wire(_value_bytes(msg, raw), msg.param_type, bytewise)
                answer.set_result((value, msg.param_type))

        unsubscribe = link.subscribe(on_frame, sysid=sysid)  # the matcher exists before the request leaves
        try:
            link.send(request)
            return await asyncio.wait_for(answer, retry_s)
        except TimeoutError:
            continue
        finally:
            unsubscribe()
    return None


async def read_param(
    link: MavlinkLink, sysid: int, name: str, compid: int = 1, retry_s: float = COMMAND_RETRY_S
) -> float | None:
    """Parameter ``name``'s value (as a float), or None when the vehicle does not answer for it."""
    request = mavlink.MAVLink_param_request_read_message(sysid, compid, name.encode(), -1)
    answer = await _param_value(link, sysid, name, request, retry_s)
    return None if answer is None else float(answer[0])


async def set_param(
    link: MavlinkLink,
    sysid: int,
    name: str,
    value: float,
    compid: int = 1,
    retry_s: float = COMMAND_RETRY_S,
    *,
    param_type: int = REAL32,
    bytewise: bool = False,
) -> int | float:
    """Set parameter ``name`` to ``value`` as ``param_type`` (its own type: PX4 refuses another);
    ``bytewise``: an integer's bytes in the float field (PX4). Returns the value the vehicle echoed."""
    data = to_wire(value, param_type, bytewise, name)
    request = _ParamSet(sysid, compid, name, data, param_type)
    answer = await _param_value(link, sysid, name, request, retry_s, bytewise)
    if answer is None:
        raise UserError(f"vehicle {sysid}: no PARAM_VALUE for {name} after {COMMAND_RETRIES + 1} PARAM_SETs")
    echoed = answer[0]
    if param_type in _INTS:
        kept = echoed != int(value)
    else:
        kept = not math.isfinite(echoed) or abs(echoed - value) > 1e-3 * max(1.0, abs(value))
    if kept:
        raise UserError(f"vehicle {sysid} kept {name} = {echoed:g}, asked for {value:g}")
    return echoed
