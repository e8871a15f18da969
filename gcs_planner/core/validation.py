"""Input checks shared by every reader: types, ranges, physical limits, unique ids, safe files.

Every check raises InputError with one line naming the field and the bad value; the CLI prints it
and exits 2. Readers check everything before they send or write anything, and outputs are
written atomically (:func:`atomic_write`), so a bad input loses nothing. The physical limits
(docs/input-validation.md) are deliberately loose: they reject nonsense, not unusual missions.
"""

from __future__ import annotations

import argparse
import contextlib
import difflib
import json
import math
import os
import tempfile
import tomllib
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

from gcs_planner.core.errors import UserError, shorten

if TYPE_CHECKING:  # gcs_planner.core.geo imports numpy and pyproj: only the readers of origins need it
    from gcs_planner.core.geo import Origin

__all__ = [
    "FLOAT32_MAX", "MAX_ALT_M", "MAX_DURATION_S", "MAX_INPUT_BYTES", "MAX_RADIUS_M", "MAX_RANGE_M",
    "MAX_SPEED_MPS", "MAX_WAYPOINTS", "MIN_ALT_M", "MIN_DISTANCE_STEP_M", "MIN_SPEED_MPS", "MIN_TIME_STEP_S",
    "MIN_TURN_RADIUS_M", "InputError", "atomic_write", "file_stem", "integer",
    "items_of", "load_json", "load_toml", "name", "not_an_input", "number", "number_flag", "output_dir",
    "output_file", "read_text", "same_file", "table", "too_big", "unique", "write_text_atomic",
]  # fmt: skip

FLOAT32_MAX = 3.4028234663852886e38  # MAVLink float fields (z, param1..4)
MAX_SPEED_MPS = 340.0  # speed of sound at sea level: no UAV mission is faster
MIN_SPEED_MPS = 0.01  # ArduCopter's slowest waypoint speed (AC_WPNav WPNAV_WP_SPEED_MIN_MS)
MIN_TURN_RADIUS_M = 1.0  # a turn radius below this is a turn on the spot (0)
MIN_TIME_STEP_S = 0.01  # a planner's time step: 100 Hz, finer than any autopilot follows a path
MIN_DISTANCE_STEP_M = 0.1  # a planner's distance step: finer than GNSS places a vehicle
MIN_ALT_M = -11_000.0  # deeper than the deepest ocean trench (relative altitude below a mountain home)
MAX_ALT_M = 100_000.0  # the Karman line
MAX_RANGE_M = 1_000_000.0  # east / north from the scenario origin (local ENU stays accurate)
MAX_RADIUS_M = 100_000.0  # turn, acceptance, loiter, separation, obstacle and fence radii
MAX_DURATION_S = 7 * 86_400.0  # times, delays, timeouts: one week
MAX_WAYPOINTS = 10_000  # per vehicle (a mission holds at most 65535 items)
MAX_INPUT_BYTES = 256 * 2**20  # scenario, plan.json, .plan, WPL, study (100k vehicles' plan.json: 60 MB)


class InputError(UserError, ValueError):
    """A value in an input (file, flag) is invalid; the message names the field and the value."""


def number(
    value: Any,
    field: str,
    lo: float | None = None,
    hi: float | None = None,
    *,
    lo_open: bool = False,
    finite: bool = True,
) -> float:
    """``value`` as a float, checked: a real number (not bool), finite, within [lo, hi] (lo
    excluded when ``lo_open``); otherwise InputError naming ``field``."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InputError(f"{field} must be a number, got {value!r}")
    try:
        x = float(value)
    except OverflowError:
        raise InputError(f"{field} = {value!r} is out of range") from None
    if math.isnan(x) or (finite and math.isinf(x)):
        raise InputError(f"{field} must be a finite number, got {value!r}")
    if lo is not None and (x <= lo if lo_open else x < lo):
        raise InputError(f"{field} must be {'>' if lo_open else '>='} {lo:g}, got {value!r}")
    if hi is not None and x > hi:
        raise InputError(f"{field} must be <= {hi:g}, got {value!r}")
    return x


def integer(value: Any, field: str, lo: int | None = None, hi: int | None = None) -> int:
    """``value`` as an int (a whole float such as 3.0 is accepted), within [lo, hi]."""
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    if isinstance(value, bool) or not isinstance(value, int):
        raise InputError(f"{field} must be an integer, got {value!r}")
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        if lo is not None and hi is not None:
            span = f"{lo}..{hi}"
        else:
            span = f">= {lo}" if lo is not None else f"<= {hi}"
        raise InputError(f"{field} must be an integer {span}, got {value!r}")
    return value


def name(value: Any, field: str) -> str:
    """An id: a printable string of 1..64 characters."""
    if not isinstance(value, str) or not 1 <= len(value) <= 64 or not value.isprintable():
        raise InputError(f"{field} must be a printable name of 1..64 characters, got {_short(value)}")
    return value


def table(value: Any, field: str) -> dict[str, Any]:
    """``value`` if it is a table (dict), else InputError."""
    if not isinstance(value, dict):
        raise InputError(f"{field} must be a table, got {_short(value)}")
    return value


def origin(value: Any, field: str) -> Origin:
    """A local frame's origin table {lat_deg, lon_deg, alt_m [AMSL, default 0]}, checked."""
    from gcs_planner.core.geo import Origin

    o = known_keys(table(value, field), ("lat_deg", "lon_deg", "alt_m"), field)
    try:
        return Origin(
            lat_deg=number(o.get("lat_deg"), "origin.lat_deg", -90.0, 90.0),
            lon_deg=number(o.get("lon_deg"), "origin.lon_deg", -180.0, 180.0),
            alt_m=number(o.get("alt_m", 0.0), "origin.alt_m", MIN_ALT_M, MAX_ALT_M),
        )
    except ValueError as exc:
        raise InputError(str(exc)) from None


def known_keys(value: dict[str, Any], allowed: Iterable[str], field: str) -> dict[str, Any]:
    """``value`` if every key is in ``allowed``; else InputError naming the key and the nearest
    known one (a misspelt ``[obstacle]`` must not silently drop every obstacle)."""
    allowed = sorted(allowed)
    for key in value:
        if key not in allowed:
            near = difflib.get_close_matches(str(key), allowed, n=1)
            hint = f"; did you mean {near[0]!r}?" if near else f"; known: {', '.join(allowed)}"
            raise InputError(f"{field}: unknown key {key!r}{hint}")
    return value


def items_of(value: Any, field: str, kind: type = dict) -> list:
    """``value`` if it is a list whose entries are all ``kind`` (a list of tables by default)."""
    if not isinstance(value, list):
        raise InputError(f"{field} must be a list, got {_short(value)}")
    for i, entry in enumerate(value):
        if not isinstance(entry, kind):
            what = "a table" if kind is dict else f"a {kind.__name__}"
            raise InputError(f"{field}[{i}] must be {what}, got {_short(entry)}")
    return value


def unique(values: Iterable, field: str) -> None:
    """InputError naming the first value that repeats."""
    seen = set()
    for v in values:
        if v in seen:
            raise InputError(f"{field} {shorten(v)} appears twice; each must be unique")
        seen.add(v)


def read_text(path: str | Path, what: str) -> str:
    """A UTF-8 text file (a leading byte-order mark is dropped), with one-line errors."""
    try:
        with open(path, "rb") as f:  # at most one byte over the limit: /dev/zero is refused too
            data = f.read(MAX_INPUT_BYTES + 1)
    except FileNotFoundError:
        raise InputError(f"{what} {str(path)!r}: no such file") from None
    except IsADirectoryError:
        raise InputError(f"{what} {str(path)!r} is a folder, not a file") from None
    except OSError as exc:
        raise InputError(f"{what} {str(path)!r}: cannot read: {exc.strerror or exc}") from None
    too_big(len(data), path, what)
    try:
        return data.decode("utf-8").removeprefix("\ufeff")
    except UnicodeDecodeError as exc:
        raise InputError(f"{what} {str(path)!r}: not UTF-8 text (byte {exc.start})") from None


def too_big(size: int, path: str | Path, what: str) -> None:
    """InputError when a text input of ``size`` bytes is over MAX_INPUT_BYTES (read no further)."""
    if size > MAX_INPUT_BYTES:
        raise InputError(f"{what} {str(path)!r} is over {MAX_INPUT_BYTES // 2**20} MiB, the limit for"
                         " a text input")  # fmt: skip


def load_json(text: str, what: str) -> Any:
    """JSON text -> value; syntax errors and deep nesting are one line. NaN / Infinity are read
    (our own metrics may hold them); fields that must be finite are checked where they are used."""
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(f"{what}: not valid JSON: {exc}") from None
    except RecursionError:
        raise InputError(f"{what}: nested too deeply") from None
    except ValueError as exc:  # an integer of more than 4300 digits (int_max_str_digits)
        raise InputError(f"{what}: not valid JSON: {_short(str(exc))}") from None


def load_toml(text: str, what: str) -> dict[str, Any]:
    """TOML text -> dict; syntax errors and deep nesting are one line."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{what}: not valid TOML: {exc}") from None
    except RecursionError:
        raise InputError(f"{what}: nested too deeply") from None
    except ValueError as exc:  # a huge integer
        raise InputError(f"{what}: not valid TOML: {_short(str(exc))}") from None


def output_file(path: str | Path, flag: str, inputs: Iterable[str | Path | None] = ()) -> Path:
    """An output file path whose folder exists, which is not itself a folder and not one of
    ``inputs`` (writing it would destroy what is being read)."""
    path = Path(path)
    not_an_input(path, inputs, flag)
    if path.is_dir():
        raise InputError(f"{flag} {str(path)!r} is a folder; give a file name")
    parent = path.parent
    if not parent.is_dir():
        state = "is a file" if parent.exists() else "does not exist"
        raise InputError(f"{flag} {str(path)!r}: folder {str(parent)!r} {state}")
    return path


def same_file(a: str | Path, b: str | Path) -> bool:
    """True when ``a`` and ``b`` name one file (symlinks, hard links, ``./x`` and ``x`` alike)."""
    try:
        return os.path.samefile(a, b)
    except OSError:  # one does not exist (yet): compare the resolved names
        return Path(a).resolve() == Path(b).resolve()


def not_an_input(path: str | Path, inputs: Iterable[str | Path | None], flag: str) -> None:
    """InputError when the output ``path`` is one of the ``inputs`` (None entries are skipped)."""
    for source in inputs:
        if source is not None and same_file(path, source):
            raise InputError(f"{flag} {_short(str(path))} is an input of this command; write elsewhere")


def file_stem(value: str, field: str) -> str:
    """``value`` as a file name inside an output folder: no folder parts, not hidden, not empty."""
    bad = not value or value in (".", "..") or value.startswith(".") or any(c in value for c in "/\\\0:")
    if bad or not value.isprintable():
        raise InputError(f"{field} {_short(value)} cannot be a file name (no /, \\, :, leading dot)")
    return value


def output_dir(path: str | Path, flag: str) -> Path:
    """An output folder that exists or can be made (no file in its place); not created here."""
    path = Path(path)
    for p in (path, *path.parents):
        if p.exists():
            if not p.is_dir():
                raise InputError(f"{flag} {str(path)!r}: {str(p)!r} is a file, not a folder")
            break
    return path


@contextlib.contextmanager
def atomic_write(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path next to ``path`` (same suffix, so writers that pick the format by
    suffix still do); on success it replaces ``path``, on any error it
    is removed, so ``path`` is either the old file or the complete new one, never half written.
    An OSError (full disk, no permission) becomes a one-line UserError."""
    path = Path(path)
    try:
        fd, tmp_name = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=f".tmp{path.suffix}", dir=path.parent)
    except OSError as exc:
        raise UserError(f"cannot write {str(path)!r}: {exc.strerror or exc}") from None
    tmp = Path(tmp_name)
    try:
        os.fchmod(fd, _new_file_mode(path))  # mkstemp makes 0600: give what open() would
    except OSError:
        pass
    finally:
        os.close(fd)
    try:
        yield tmp
        os.replace(tmp, path)
    except OSError as exc:
        raise UserError(f"cannot write {str(path)!r}: {exc.strerror or exc}") from None
    finally:
        tmp.unlink(missing_ok=True)


def _new_file_mode(path: Path) -> int:
    """The mode open() would leave: an existing file's own, else 0666 less the umask."""
    try:
        return path.stat().st_mode & 0o7777
    except OSError:
        pass
    mask = os.umask(0o022)  # reading the umask means setting it: put it straight back
    os.umask(mask)
    return 0o666 & ~mask


def write_text_atomic(path: str | Path, text: str) -> None:
    """Write ``text`` to ``path`` atomically (see atomic_write)."""
    with atomic_write(path) as tmp:
        tmp.write_text(text)


def number_flag(
    lo: float | None = None, hi: float | None = None, *, lo_open: bool = False, whole: bool = False
):
    """An argparse ``type``: the flag's text as a finite float (``whole``: an int) within [lo, hi]."""

    def parse(text: str) -> float | int:
        try:
            if whole:
                return integer(int(text), "value", lo, hi)
            return number(float(text), "value", lo, hi, lo_open=lo_open)
        except (ValueError, InputError) as exc:
            problem = str(exc).removeprefix("value ") if isinstance(exc, InputError) else None
            kind = "an integer" if whole else "a number"
            raise argparse.ArgumentTypeError(problem or f"must be {kind}, got {text!r}") from None

    parse.__name__ = "integer" if whole else "number"
    return parse


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def sysids_flag(text: str) -> frozenset[int]:
    """An argparse ``type``: system ids as "1,5,8" or ranges "1-3,7", each 1..255."""
    ids: set[int] = set()
    for part in text.split(","):
        first, _, last = part.strip().partition("-")
        try:
            lo, hi = int(first), int(last or first)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be sysids like 1,5,8 or 1-3, got {text!r}") from None
        if not 1 <= lo <= hi <= 255:
            raise argparse.ArgumentTypeError(f"sysids are 1..255 and ranges run upwards, got {part!r}")
        ids.update(range(lo, hi + 1))
    return frozenset(ids)
