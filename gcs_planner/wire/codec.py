"""Lean MAVLink 2 codec for the common frame: unsigned, fixed-size numeric fields, one per datagram.

pymavlink's ``MAVLink.decode`` and ``message.pack`` handle every case (MAVLink 1, signing, arrays,
strings) and walk the message's fields one by one in Python. A mission upload decodes one request
and packs one item per item, and the GCS decodes every telemetry frame of the fleet, so these take
the common case with what each message class needs looked up once (``_plan``: its struct, CRC
extra and C-level field getters). They use pymavlink's own message classes, struct layouts and CRC
extras for the frames they cover and return None for the rest, so the caller falls back to
pymavlink. Tests check both paths agree byte for byte on every message of the dialect.
"""

from __future__ import annotations

import os
import struct
from collections.abc import Callable
from functools import cache
from operator import attrgetter, itemgetter
from typing import NamedTuple

from fastcrc import crc16

os.environ.setdefault("MAVLINK20", "1")

from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

__all__ = ["decode", "encode"]

_HEADER = struct.Struct("<BBBBBBBHB")  # magic, len, incompat, compat, seq, sysid, compid, msgid lo16, hi8
_HEADER_LEN = 10
_V2_MAGIC = 0xFD
_MAP = mavlink.mavlink_map
_MAVError = mavlink.MAVError
_Header = mavlink.MAVLink_header
_SIGNED = mavlink.MAVLINK_IFLAG_SIGNED
_mcrf4xx = crc16.mcrf4xx


class _Plan(NamedTuple):
    """What encoding and decoding one covered message class needs, looked up once per class."""

    cls: type[mavlink.MAVLink_message]
    wire: struct.Struct  # the payload in wire order
    crc_extra: bytes
    values: Callable[[mavlink.MAVLink_message], tuple]  # the message's field values in wire order
    orders: Callable[[tuple], tuple]  # wire-order values -> the constructor's order


def _tuple_getter(getter: Callable, keys: list) -> Callable:
    """``getter(*keys)`` that returns a tuple for one key too (operator's getters return the bare item)."""
    get = getter(*keys)
    return get if len(keys) > 1 else lambda obj: (get(obj),)


@cache
def _covered(cls: type[mavlink.MAVLink_message]) -> bool:
    """Numeric scalar fields only: no arrays, no char strings (those need pymavlink's conversions)."""
    return all(n == 1 for n in cls.lengths) and not set(bytes(cls.native_format)) & set(b"sc")


@cache
def _plan(cls: type[mavlink.MAVLink_message]) -> _Plan | None:
    """The plan of a covered dialect class; None for the rest (and for subclasses with their own pack)."""
    if _MAP.get(cls.id) is not cls or not _covered(cls) or not cls.ordered_fieldnames:
        return None
    values = _tuple_getter(attrgetter, list(cls.ordered_fieldnames))
    return _Plan(cls, cls.unpacker, bytes((cls.crc_extra,)), values, _tuple_getter(itemgetter, cls.orders))


@cache
def _plan_of_id(msgid: int) -> _Plan | None:
    cls = _MAP.get(msgid)
    return None if cls is None else _plan(cls)


def decode(raw: bytes) -> mavlink.MAVLink_message | None:
    """The message in ``raw`` (exactly one unsigned MAVLink 2 frame), as pymavlink would decode it;
    None if the frame is not covered; raises mavlink.MAVError for a bad length or CRC."""
    if len(raw) < _HEADER_LEN + 2 or raw[0] != _V2_MAGIC or raw[2] & _SIGNED:
        return None
    _, mlen, incompat, compat, seq, sysid, compid, low, high = _HEADER.unpack_from(raw)
    msgid = low | high << 16
    plan = _plan_of_id(msgid)
    if plan is None:
        return None
    end = _HEADER_LEN + mlen
    if len(raw) != end + 2:
        raise _MAVError(f"invalid MAVLink message length {len(raw)} for payload {mlen}, msgId={msgid}")
    crc = raw[end] | raw[end + 1] << 8
    if _mcrf4xx(plan.crc_extra, _mcrf4xx(raw[1:end])) != crc:
        raise _MAVError(f"invalid MAVLink CRC in msgID {msgid}")
    size = plan.wire.size
    payload = raw[_HEADER_LEN:end]
    msg = plan.cls(
        *plan.orders(plan.wire.unpack(payload[:size] if mlen >= size else payload + bytes(size - mlen)))
    )
    msg._header = _Header(msgid, incompat, compat, mlen, seq, sysid, compid)
    msg._msgbuf = bytearray(raw)
    msg._payload = raw[6:end]  # pymavlink's own slice (it starts inside the header)
    msg._crc = crc
    return msg


def encode(msg: mavlink.MAVLink_message, mav: mavlink.MAVLink) -> bytes | None:
    """``msg`` as one unsigned MAVLink 2 frame from ``mav``'s system, component and sequence number
    (the caller advances it); None when not covered (signing, strings, arrays, or a subclass with
    its own ``pack`` such as wire.py's extension-carrying messages)."""
    plan = _plan(type(msg))
    if plan is None or mav.signing.sign_outgoing:
        return None
    payload = plan.wire.pack(*plan.values(msg))
    payload = payload.rstrip(b"\x00") or payload[:1]  # MAVLink 2 drops trailing zeros, keeps one byte
    msgid = plan.cls.id
    frame = _HEADER.pack(
        _V2_MAGIC, len(payload), 0, 0, mav.seq, mav.srcSystem, mav.srcComponent, msgid & 0xFFFF, msgid >> 16
    )
    frame += payload
    crc = _mcrf4xx(plan.crc_extra, _mcrf4xx(frame[1:]))
    return frame + crc.to_bytes(2, "little")
