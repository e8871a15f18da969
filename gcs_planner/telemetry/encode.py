"""Fast JSON encoding of decoded pymavlink messages (the logger's hot path).

``msg.to_dict()`` + ``json.dumps`` costs ~6-10 us per message. Instead each message type gets a
``%``-format template built once from its field list, filled from an ``attrgetter`` tuple
(~2 us). Python's ``repr`` of ints, floats and lists of them is valid JSON except for
non-finite floats (``nan``, ``inf``); such rare messages, and anything unexpected (bytes),
take the slow exact path, which writes ``null`` for non-finite floats. Bytes can only come from
``char`` fields (pymavlink gives lists of ints for other arrays), which go through ``json.dumps``
(a TypeError there also selects the exact path).

float32 fields (MAVLink ``float``) are printed with 9 significant digits (``%.9g``): that is
the shortest fixed precision that round-trips every float32 exactly, and it is about half the
size of ``repr`` of the float32 widened to a double (e.g. 0.012345678918063641). This halves
the compressed size of float-heavy messages such as ATTITUDE.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from operator import attrgetter

__all__ = ["json_encoder", "message_json"]

_ENCODERS: dict[type, Callable[[object], bytes]] = {}


def message_json(msg) -> bytes:
    """The message's fields as a compact JSON object (UTF-8), in pymavlink's field order."""
    return json_encoder(type(msg))(msg)


def json_encoder(cls: type) -> Callable[[object], bytes]:
    """The (cached) encoder of one pymavlink message class: ``encoder(msg) -> JSON bytes``."""
    encoder = _ENCODERS.get(cls)
    if encoder is None:
        encoder = _ENCODERS[cls] = _make_encoder(cls)
    return encoder


def _make_encoder(cls: type) -> Callable[[object], bytes]:
    names = list(cls.fieldnames)
    if not names:
        return lambda msg: b"{}"
    types = list(cls.fieldtypes)
    char_idx = [i for i, t in enumerate(types) if t == "char"]
    may_be_nonfinite = any(t in ("float", "double") for t in types)
    lengths = dict(zip(cls.ordered_fieldnames, cls.array_lengths, strict=True))
    template = "{" + ",".join(f'"{n}":{_conversion(types[i], lengths[n])}' for i, n in enumerate(names)) + "}"
    getter = attrgetter(*names)
    single = len(names) == 1

    def encode(msg) -> bytes:
        try:
            values = getter(msg)
            if single:
                values = (values,)
            if char_idx:
                values = list(values)
                for i in char_idx:
                    values[i] = json.dumps(values[i])
                values = tuple(values)
            text = template % values
            if may_be_nonfinite and ("nan" in text or "inf" in text):
                return _exact(msg, names)
            return text.encode()
        except (TypeError, ValueError):
            return _exact(msg, names)

    return encode


def _conversion(ctype: str, length: int) -> str:
    """%-conversion of one field: JSON string, 9 significant digits for float32 scalars, else repr."""
    if ctype == "char":
        return "%s"
    if ctype == "float" and not length:
        return "%.9g"
    return "%r"


def _exact(msg, names: list[str]) -> bytes:
    return json.dumps(
        {n: _clean(getattr(msg, n)) for n in names}, separators=(",", ":"), allow_nan=False
    ).encode()


def _clean(value):
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, bytes | bytearray):
        return value.decode("latin-1")
    if isinstance(value, list | tuple):
        return [_clean(v) for v in value]
    return value
