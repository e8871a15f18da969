"""Typed configuration tables: msgspec Structs that refuse unknown keys and out-of-range values.

Every planner's ``[planner]`` table (and the planner-specific world tables) is a ``Config``
subclass whose fields carry their types and bounds (``Annotated[float, Meta(...)]``). ``parse``
checks a TOML table against one: an unknown key is an error naming the key and the nearest known
one, a bad value an error naming the field and the value, both one line (InputError).

msgspec rather than pydantic: it converts plain TOML tables with the same strictness (no bool
for int, no string for float, NaN/inf fail every bound), and it imports in ~5 ms against
pydantic's ~150 ms, which every short CLI command would pay.
"""

from __future__ import annotations

import re
import types
import typing
from typing import Annotated, Any, TypeVar

import msgspec
from msgspec import Meta

from gcs_planner.core.validation import (
    MAX_ALT_M,
    MAX_DURATION_S,
    MAX_RADIUS_M,
    MAX_RANGE_M,
    MAX_SPEED_MPS,
    MIN_ALT_M,
    MIN_DISTANCE_STEP_M,
    MIN_TIME_STEP_S,
    InputError,
    known_keys,
)

__all__ = [
    "Altitude", "Config", "Count", "Coordinate", "Distance", "DistanceStep", "Duration", "Fraction",
    "NonNegative", "Positive", "PositiveDistance", "Seed", "Speed", "TimeStep", "parse",
]  # fmt: skip

T = TypeVar("T", bound="Config")

MAX_COUNT = 1_000_000
MAX_FACTOR = 1e9  # weights and other dimensionless factors

Seed = Annotated[int, Meta(ge=0, le=2**63 - 1)]
Count = Annotated[int, Meta(ge=1, le=MAX_COUNT)]
Fraction = Annotated[float, Meta(ge=0.0, le=1.0)]
NonNegative = Annotated[float, Meta(ge=0.0, le=MAX_FACTOR)]
Positive = Annotated[float, Meta(gt=0.0, le=MAX_FACTOR)]
Distance = Annotated[float, Meta(ge=0.0, le=MAX_RADIUS_M)]
PositiveDistance = Annotated[float, Meta(gt=0.0, le=MAX_RADIUS_M)]
Coordinate = Annotated[float, Meta(ge=-MAX_RANGE_M, le=MAX_RANGE_M)]
Altitude = Annotated[float, Meta(ge=MIN_ALT_M, le=MAX_ALT_M)]
Duration = Annotated[float, Meta(ge=0.0, le=MAX_DURATION_S)]
Speed = Annotated[float, Meta(gt=0.0, le=MAX_SPEED_MPS)]
TimeStep = Annotated[float, Meta(ge=MIN_TIME_STEP_S, le=MAX_DURATION_S)]  # a sampling step in time
DistanceStep = Annotated[float, Meta(ge=MIN_DISTANCE_STEP_M, le=MAX_RADIUS_M)]  # ... in space


class Config(msgspec.Struct, forbid_unknown_fields=True, frozen=True, kw_only=True):
    """A typed table: fields are the known keys, with their defaults and bounds."""


def parse(kind: type[T], data: Any, field: str) -> T:
    """``data`` (a TOML table) as ``kind``; InputError naming the field and value otherwise."""
    _check_keys(kind, data, field)
    try:
        return msgspec.convert(data, kind)
    except msgspec.ValidationError as exc:
        raise InputError(_said(str(exc), data, field)) from None


def _check_keys(kind: Any, data: Any, field: str) -> None:
    """Unknown keys anywhere in ``data`` against the Structs of ``kind``, with the nearest name."""
    kind = _bare(kind)
    if isinstance(kind, type) and issubclass(kind, msgspec.Struct):
        if not isinstance(data, dict):
            return  # msgspec names the type error
        hints = typing.get_type_hints(kind, include_extras=True)
        known_keys(data, [*hints, *_tag(kind)], field)
        for key, value in data.items():
            if key in hints:
                _check_keys(hints[key], value, f"{field}.{key}")
    elif typing.get_origin(kind) in (list, tuple) and isinstance(data, list):
        args = [a for a in typing.get_args(kind) if a is not Ellipsis]
        if len(args) == 1:
            for i, item in enumerate(data):
                _check_keys(args[0], item, f"{field}[{i}]")


def _bare(kind: Any) -> Any:
    """``kind`` without Annotated metadata or an ``| None``."""
    if typing.get_origin(kind) is Annotated:
        kind = typing.get_args(kind)[0]
    args = [a for a in typing.get_args(kind) if a is not type(None)]
    if typing.get_origin(kind) in (typing.Union, types.UnionType) and len(args) == 1:
        return args[0]
    return kind


def _tag(kind: type[msgspec.Struct]) -> list[str]:
    tag_field = kind.__struct_config__.tag_field
    return [tag_field] if tag_field else []


_AT = re.compile(r"^(?P<what>.*?)(?: - at `\$(?P<path>[^`]*)`)?$")


def _said(message: str, data: Any, field: str) -> str:
    """msgspec's "Expected `int` >= 1, got `float` - at `$.a[0]`" as "FIELD.a[0] must be an int >= 1,
    got 2.5" (the value, not its type)."""
    match = _AT.match(message)
    what, path = match["what"], match["path"] or ""
    missing = re.match(r"Object missing required field `(.*)`", what)
    if missing:
        return f"{field}{path}: the key {missing[1]!r} is required"
    what = re.sub(r", got `?[^`,]*`?$", "", what)
    what = re.sub(r"^Expected (?:an? )?`?(\w+)`?", lambda m: "must be " + _WORDS.get(m[1], m[1]), what)
    what = re.sub(r"^Invalid (enum )?value.*", "is not one of the allowed values", what)
    value = _at(data, path)
    got = "" if value is _MISSING else f", got {_short(value)}"
    return f"{field}{path} {what}{got}"


_WORDS = {
    "int": "an integer", "float": "a number", "str": "a string", "bool": "true or false",
    "array": "a list", "object": "a table",
}  # fmt: skip
_MISSING = object()


def _at(data: Any, path: str) -> Any:
    for part in re.findall(r"\.([^.\[]+)|\[(\d+)\]", path):
        key, index = part
        try:
            data = data[key] if key else data[int(index)]
        except (KeyError, IndexError, TypeError):
            return _MISSING
    return data


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."
