"""Parameter files: Mission Planner / MAVProxy ``.param`` and QGroundControl ``.params``.

Formats, as their tools write and read them:

- Mission Planner ``.param``: ``NAME,VALUE`` per line, ``#`` comment lines (it writes a ``#NOTE:``
  header). MAVProxy's ``param save`` (pymavlink mavparm.py ``MAVParmDict.save``) writes
  ``NAME VALUE`` with the name padded to 16 characters and floats as ``%f``; its ``param load``
  reads both (a comma becomes a space, a ``#`` starts a comment anywhere on the line, exactly two
  fields, ``0x`` hex values), and so does this reader.
- QGroundControl ``.params``: ``#`` header lines, then ``vehicle-id component-id name value type``
  separated by tabs, type the MAV_PARAM_TYPE (QGC ParameterManager, "# Vehicle-Id Component-Id Name
  Value Type").

Reading tells the two apart by content, not by the file name: the first line holding a parameter
decides (five fields: QGC; two: Mission Planner / MAVProxy) and every other line must be of the
same kind. Every line is checked before anything is returned; a bad one is one InputError naming
the file, the line number and its text. Names are 1-16 letters, digits or underscores (the MAVLink
param_id); values finite numbers, a float within float32's range.

Writing picks the format by the file's extension: ``.params`` -> QGC, anything else -> Mission
Planner. Lines are sorted by name (as Mission Planner, MAVProxy and QGC write them). An integer
parameter is written as an integer; a REAL32 as the shortest decimal that reads back as the same
float32 (0.3, not 0.300000011920929 or MAVProxy's 0.300000), with ``.0`` on whole numbers.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from gcs_planner.core.validation import InputError, read_text, write_text_atomic
from gcs_planner.mavlink.params import TYPE_NAMES, Param, fits_float32, float32

__all__ = [
    "ParamEntry", "format_value", "is_param_name", "is_qgc_name", "parse_params", "read_param_file",
    "render_params", "write_param_file",
]  # fmt: skip

QGC_SUFFIX = ".params"
_NAME = re.compile(r"[A-Za-z0-9_]{1,16}")
_MAX_TEXT = 80  # characters of a bad line quoted in an error


@dataclass(frozen=True)
class ParamEntry:
    """One parameter line of a file: ``value`` an int when written as one (decimal or 0x hex), else
    a float; ``line`` its 1-based line number; ``param_type`` and ``compid`` from a QGC file (None
    in a Mission Planner one)."""

    name: str
    value: int | float
    line: int
    param_type: int | None = None
    compid: int | None = None


def read_param_file(path: str | Path) -> list[ParamEntry]:
    """The parameters of a Mission Planner / MAVProxy or QGC file (see the module docstring)."""
    return parse_params(read_text(path, "parameter file"), str(path))


def parse_params(text: str, what: str = "parameter file") -> list[ParamEntry]:
    """The parameters in ``text`` (a file's content; ``what`` names it in errors)."""
    entries: list[ParamEntry] = []
    kind: str | None = None
    seen: dict[tuple[int | None, str], int] = {}
    for number, line in enumerate(text.splitlines(), start=1):
        fields = line.split("#", 1)[0].replace(",", " ").split()
        if not fields:
            continue
        kind = kind or ("qgc" if len(fields) == 5 else "mp")
        entry = _entry(fields, kind, number, line, what)
        key = (entry.compid, entry.name)
        if key in seen:
            raise _bad(what, number, line, f"{entry.name} is also on line {seen[key]}")
        seen[key] = number
        entries.append(entry)
    if not entries:
        raise InputError(f"{what}: no parameter lines (NAME,VALUE or QGC's tab-separated five fields)")
    return entries


def _entry(fields: list[str], kind: str, number: int, line: str, what: str) -> ParamEntry:
    """One line's parameter, checked; InputError naming the line."""
    if kind == "mp":
        if len(fields) != 2:
            raise _bad(what, number, line, "expected NAME,VALUE or NAME VALUE")
        name, text = fields
        return ParamEntry(_name(name, what, number, line), _value(text, what, number, line), number)
    if len(fields) != 5:
        raise _bad(what, number, line, "expected QGC's five fields: vehicle-id component-id name value type")
    sysid, compid, name, text, type_text = fields
    if not (_whole(sysid, 0, 255) and _whole(compid, 0, 255)):
        raise _bad(what, number, line, "vehicle and component ids must be integers 0..255")
    if not _whole(type_text, 1, max(TYPE_NAMES)):
        raise _bad(what, number, line, f"type {type_text!r} is not a MAV_PARAM_TYPE (1..{max(TYPE_NAMES)})")
    value = _value(text, what, number, line)
    return ParamEntry(_name(name, what, number, line), value, number, int(type_text), int(compid))


def _whole(text: str, lo: int, hi: int) -> bool:
    return text.isdigit() and lo <= int(text) <= hi


def is_param_name(text: str) -> bool:
    """1-16 letters, digits or _: every name ArduPilot and PX4 use, and all a file line can hold."""
    return _NAME.fullmatch(text) is not None


def _name(text: str, what: str, number: int, line: str) -> str:
    if not is_param_name(text):
        raise _bad(what, number, line, f"parameter name {text!r} is not 1-16 letters, digits or _")
    return text


def _value(text: str, what: str, number: int, line: str) -> int | float:
    """A value as MAVProxy reads it: decimal, or 0x hex (an int); finite; a float within float32."""
    try:
        if text.lower().startswith(("0x", "-0x", "+0x")):
            return int(text, 16)
        if re.fullmatch(r"[+-]?\d+", text):
            return int(text)
        value = float(text)
    except ValueError:
        raise _bad(what, number, line, f"value {text!r} is not a number") from None
    if not (math.isfinite(value) and fits_float32(value)):
        raise _bad(what, number, line, f"value {text!r} is not a finite float32")
    return value


def _bad(what: str, number: int, line: str, why: str) -> InputError:
    text = line.strip()
    text = text if len(text) <= _MAX_TEXT else text[: _MAX_TEXT - 3] + "..."
    return InputError(f"{what} line {number}: {why}: {text!r}")


def format_value(value: int | float) -> str:
    """An int as an int; a float as the shortest decimal that reads back as the same float32."""
    if isinstance(value, int):
        return str(value)
    if not math.isfinite(value):
        return repr(value)
    target = float32(value)
    for digits in range(1, 10):  # 9 significant digits always read back as the same float32
        shortest = float(f"{value:.{digits}g}")
        if fits_float32(shortest) and float32(shortest) == target:
            break
    return repr(shortest)  # as Python writes it: 10.0, 0.3, 1e-05, 3.4028235e+38


def render_params(
    params: Iterable[Param], qgc: bool, sysid: int = 1, compid: int = 1, stack: str = ""
) -> str:
    """The text of a parameter file: QGC ``.params`` when ``qgc``, else Mission Planner ``.param``."""
    rows = sorted(params, key=lambda p: p.name)
    if qgc:
        lines = [f"# Onboard parameters for Vehicle {sysid}", "#"]
        lines += [f"# Stack: {stack}", "#"] if stack else []
        lines.append("# Vehicle-Id Component-Id Name Value Type")
        lines += [f"{sysid}\t{compid}\t{p.name}\t{format_value(p.value)}\t{p.param_type}" for p in rows]
    else:
        source = f"vehicle {sysid} component {compid}" + (f" ({stack})" if stack else "")
        lines = [f"# Onboard parameters of {source}"]
        lines += [f"{p.name},{format_value(p.value)}" for p in rows]
    return "\n".join(lines) + "\n"


def is_qgc_name(path: str | Path) -> bool:
    """Whether ``path`` is written as a QGC ``.params`` file (else Mission Planner ``.param``)."""
    return Path(path).suffix.lower() == QGC_SUFFIX


def write_param_file(
    path: str | Path, params: Iterable[Param], sysid: int = 1, compid: int = 1, stack: str = ""
) -> None:
    """Write ``params`` to ``path`` atomically, in the format its extension names."""
    write_text_atomic(path, render_params(params, is_qgc_name(path), sysid, compid, stack))
