"""Lean MAVLink 2 codec for the common frame: unsigned, fixed-size numeric fields, one per datagram.

pymavlink's ``MAVLink.decode`` and ``message.pack`` handle every case (MAVLink 1, signing, arrays,
strings) and walk the message's fields one by one in Python. A mission upload decodes one request
and packs one item per item, and the GCS decodes every telemetry frame of the fleet, so these take
the common case with what each message class needs looked up once (``_plan``: its struct, CRC
extra and C-level field getters). They use pymavlink's own message classes, struct layouts and CRC
extras for the frames they cover and return None for the rest, so the caller falls back to
pymavlink. Tests check both paths agree byte for byte on every message of the dialect.

Below messages, for a hot path that builds none (a mission upload's request -> item): ``intact``
checks a received frame's length and CRC, ``fields`` reads its payload, ``packer(cls)`` packs a
payload from the constructor's arguments once, and ``frame`` puts a header and CRC around it.
"""

from __future__ import annotations

import os
import struct
from collections.abc import Callable
from functools import cache, lru_cache
from operator import attrgetter, itemgetter
from typing import NamedTuple

from fastcrc import crc16

os.environ.setdefault("MAVLINK20", "1")

from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

__all__ = ["Packer", "crc_fails", "decode", "encode", "fields", "frame", "intact", "packer"]

_HEADER = struct.Struct("<BBBBBBBHB")  # magic, len, incompat, compat, seq, sysid, compid, msgid lo16, hi8
_HEADER_LEN = 10
_V2_MAGIC = 0xFD
_MAP = mavlink.mavlink_map
_MAVError = mavlink.MAVError
_Header = mavlink.MAVLink_header
_SIGNED = mavlink.MAVLINK_IFLAG_SIGNED
_SIGNATURE_LEN = 13
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


def _plan_of_id(msgid: int) -> _Plan | None:
    """Not cached by id: junk frames carry any of 2^24 ids; ``_plan`` caches per dialect class."""
    cls = _MAP.get(msgid)
    return None if cls is None else _plan(cls)


class Packer(NamedTuple):
    """One covered message's payload from its constructor's arguments, without the message object."""

    msgid: int
    crc_extra: bytes
    pack: Callable[..., bytes]  # constructor-order values -> the payload, trailing zeros dropped


@cache
def packer(cls: type[mavlink.MAVLink_message]) -> Packer:
    """The Packer of a covered dialect class (ValueError for the rest)."""
    plan = _plan(cls)
    if plan is None:
        raise ValueError(f"{cls.__name__} is not covered by codec.py")
    to_wire = _tuple_getter(itemgetter, [cls.fieldnames.index(n) for n in cls.ordered_fieldnames])
    wire = plan.wire

    def pack(*values: object) -> bytes:
        payload = wire.pack(*to_wire(values))
        return payload.rstrip(b"\x00") or payload[:1]  # MAVLink 2 drops trailing zeros, keeps one byte

    return Packer(cls.id, plan.crc_extra, pack)


def frame(
    msgid: int, crc_extra: bytes, payload: bytes, seq: int, sysid: int, compid: int, incompat: int = 0
) -> bytes:
    """One MAVLink 2 frame of a packed ``payload`` (a Packer's), up to its CRC; ``incompat`` = SIGNED
    for a frame that a signature block will follow (the flag is under the CRC)."""
    head = _HEADER.pack(_V2_MAGIC, len(payload), incompat, 0, seq, sysid, compid, msgid & 0xFFFF, msgid >> 16)
    body = head + payload
    return body + _mcrf4xx(crc_extra, _mcrf4xx(body[1:])).to_bytes(2, "little")


@lru_cache(maxsize=1024)  # bounded: received frames name any msgid
def _crc_extra_of(msgid: int) -> bytes | None:
    cls = _MAP.get(msgid)
    return None if cls is None else bytes((cls.crc_extra,))


def intact(raw: bytes) -> bool:
    """``raw`` is one whole MAVLink 2 frame (signed or not; the signature is not checked here) of a
    dialect message, with the right length and CRC and no unknown incompatibility flag."""
    if len(raw) < _HEADER_LEN + 2 or raw[0] != _V2_MAGIC or raw[2] & ~_SIGNED:
        return False
    crc_extra = _crc_extra_of(raw[7] | raw[8] << 8 | raw[9] << 16)
    end = _HEADER_LEN + raw[1]
    if crc_extra is None or len(raw) != end + 2 + (_SIGNATURE_LEN if raw[2] & _SIGNED else 0):
        return False
    return _crc_matches(raw, end, crc_extra)


def crc_fails(raw: bytes) -> bool:
    """``raw``, a MAVLink 1 or 2 frame cut by its length fields, cannot be one: an incompatibility
    flag MAVLink 2 does not define, or a dialect message's CRC that does not match (False where the
    CRC cannot be checked: an unknown message id)."""
    v2 = raw[0] == _V2_MAGIC
    if v2 and raw[2] & ~_SIGNED:
        return True
    header = _HEADER_LEN if v2 else 6
    crc_extra = _crc_extra_of(raw[7] | raw[8] << 8 | raw[9] << 16 if v2 else raw[5])
    if crc_extra is None:
        return False
    return not _crc_matches(raw, header + raw[1], crc_extra)


def _crc_matches(raw: bytes, end: int, crc_extra: bytes) -> bool:
    """The CRC after the payload (which ends at ``end``) is that of the header and payload."""
    return _mcrf4xx(crc_extra, _mcrf4xx(raw[1:end])) == raw[end] | raw[end + 1] << 8


def fields(raw: bytes, wire: struct.Struct) -> tuple:
    """The payload of an ``intact`` frame unpacked with ``wire`` (its class's ``unpacker``): the
    values in wire order, the dropped trailing zeros restored."""
    payload = raw[_HEADER_LEN : _HEADER_LEN + raw[1]]
    size = wire.size
    return wire.unpack(payload[:size] if len(payload) >= size else payload + bytes(size - len(payload)))


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
    return frame(plan.cls.id, plan.crc_extra, payload, mav.seq, mav.srcSystem, mav.srcComponent)
