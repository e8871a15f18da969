"""Mission Planner / MAVProxy "QGC WPL 110" text files.

Format: a first line ``QGC WPL 110``, then one line per item, tab-separated:
INDEX CURRENT FRAME COMMAND P1 P2 P3 P4 LAT LON ALT AUTOCONTINUE; ``#`` lines are comments.

Choices (sources in docs/mission-files.md):
- Row 0 of a mission is the planned home for every autopilot (QGroundControl's
  MissionController::_loadTextMissionFile); a row 0 at 0, 0 means "no home" (what this writer and
  Mission Planner write without one). A file of fence commands (5000-5005) is a fence list, of
  rally points (5100) a rally list; these have no home row (MAVProxy's fence and rally files).
- Frames are kept as written. x/y: degE7 in global frames, metres x 1e4 in local ones, the plain
  number for a command without a position (MAVLink hasLocation="false", as ArduPilot reads it).
- Exact round trip: latitude/longitude written from the integer degE7 with 7 decimals (pymavlink's
  mavwp writes ``%f``, 6 decimals, losing up to 5.6 cm); params and altitude as Python's shortest
  exact float repr. NaN is written as 0 with a warning: no spelling reads everywhere (Mission
  Planner's double.Parse wants ``NaN``, QGC's toDouble ``nan``); ``nan`` and ``NaN`` are read.
- ``#`` comment lines are kept in place: read into MissionFile.comments, written back where they were.
- The INDEX column is informational: rows are numbered in file order on reading.
- A WPL file holds one list: a MissionFile with a mission and a fence or rally is written with
  the mission only, and ``wpl_losses`` says so.
"""

from __future__ import annotations

import io
import math
import re
from dataclasses import replace

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs_planner.autopilots import Conventions
from gcs_planner.missions.mission_file import (
    DO_JUMP,
    FENCE_COMMANDS,
    LIST_NAMES,
    RALLY_COMMANDS,
    Loss,
    MissionFile,
    MissionFileError,
    mission_type_of,
    unknown_command_notes,
)
from gcs_planner.wire.dialect import has_position
from gcs_planner.wire.types import MissionItem, MissionType
from gcs_planner.wire.units import e7, half_away

MAX_ROWS = 65536  # 65535 items (MISSION_COUNT is uint16) and a home row

__all__ = ["HEADER", "dumps_mission_file", "dumps_wpl", "loads_wpl", "loads_wpl_items", "wpl_losses"]

HEADER = "QGC WPL 110"
VERSIONS = ("110", "120")  # QGC reads both (MissionController::_loadTextMissionFile)
NAN_AS_ZERO = "NaN (use the default) written as 0: Mission Planner cannot read nan, QGC cannot read NaN"
SEPARATORS = re.compile(r"[\t ,]+")  # Mission Planner splits on tab, space and comma
LOCAL_FRAMES = frozenset(
    {
        mavlink.MAV_FRAME_LOCAL_NED,
        mavlink.MAV_FRAME_LOCAL_ENU,
        mavlink.MAV_FRAME_LOCAL_OFFSET_NED,
        mavlink.MAV_FRAME_BODY_NED,
        mavlink.MAV_FRAME_BODY_OFFSET_NED,
        mavlink.MAV_FRAME_BODY_FRD,
        mavlink.MAV_FRAME_LOCAL_FRD,
        mavlink.MAV_FRAME_LOCAL_FLU,
    }
)
COLUMNS = ("index", "current", "frame", "command", "param1", "param2", "param3", "param4", "x", "y", "z")


def _scale(frame: int, command: int) -> tuple[float, int]:
    """(int units per file unit, decimals) for x/y: degE7 in global frames, metres x 1e4 in local
    ones, the plain number for a command without a position (as MAVProxy and ArduPilot read it)."""
    if not has_position(command):
        return 1.0, 0
    return (1e4, 4) if frame in LOCAL_FRAMES else (1e7, 7)


def _fixed(value: int, decimals: int) -> str:
    """Integer ``value`` x 10^-decimals as an exact decimal string (no float rounding)."""
    if decimals == 0:
        return f"{int(value)}.0"
    sign = "-" if value < 0 else ""
    whole, frac = divmod(abs(int(value)), 10**decimals)
    return f"{sign}{whole}.{frac:0{decimals}d}"


def _num(value: float) -> str:
    return "0.0" if math.isnan(value) else repr(float(value))


def dumps_wpl(items: list[MissionItem], comments: list[tuple[int, str]] = ()) -> str:
    """Rows (an ArduPilot-style list: home at seq 0) -> QGC WPL 110 text; ``comments`` as
    (rows before it, line) go back where they were."""
    lines = [HEADER]
    pending = sorted(comments, key=lambda c: c[0])
    for i, it in enumerate(items):
        while pending and pending[0][0] <= i:
            lines.append(pending.pop(0)[1])
        _, decimals = _scale(it.frame, it.command)
        row = [
            str(i),
            str(int(it.current)),
            str(it.frame),
            str(it.command),
            *(_num(p) for p in (it.param1, it.param2, it.param3, it.param4)),
            _fixed(it.x, decimals),
            _fixed(it.y, decimals),
            _num(it.z),
            str(int(it.autocontinue)),
        ]
        lines.append("\t".join(row))
    lines += [line for _, line in pending]
    return "\n".join(lines) + "\n"


def _wpl_list(mf: MissionFile) -> MissionType:
    """The one list a WPL file of ``mf`` holds: the mission, else the fence, else the rally points."""
    if mf.mission or not (mf.fence or mf.rally):
        return MissionType.MISSION
    return MissionType.FENCE if mf.fence else MissionType.RALLY


def dumps_mission_file(mf: MissionFile) -> str:
    """MissionFile -> WPL text of its one list (``_wpl_list``): a mission with its home at row 0,
    a fence or rally list after its home row only if it was read with one (Mission Planner's)."""
    kind = _wpl_list(mf)
    rows = mf.list_items(kind, Conventions.ARDUPILOT)
    if kind != MissionType.MISSION and mf.home_item is not None:
        rows = [mf.items(Conventions.ARDUPILOT)[0], *rows]
    return dumps_wpl(rows, mf.comments)


def wpl_losses(mf: MissionFile) -> list[Loss]:
    """What a WPL file of ``mf`` leaves out: the other lists, the .plan settings, NaN params."""
    kind = _wpl_list(mf)
    losses = [
        Loss(name, ("every item",), tuple(range(len(items))), "not written: a WPL file holds one list")
        for t, name, items in ((MissionType.FENCE, "fence", mf.fence), (MissionType.RALLY, "rally", mf.rally))
        if items and t != kind
    ]
    defaults = MissionFile()
    settings = tuple(
        name
        for name in ("firmware_type", "vehicle_type", "cruise_speed_mps", "hover_speed_mps")
        if getattr(mf, name) != getattr(defaults, name)
    )
    if settings:
        losses.append(Loss("settings", settings, (), "not carried by WPL (a .plan keeps them)"))
    if mf.home is not None and any(e7(v) / 1e7 != v for v in mf.home[:2]):
        losses.append(Loss("home", ("position",), (), "rounded to 1e-7 deg (row 0 holds degE7, ~1 cm)"))
    name = LIST_NAMES[kind]
    for f in ("param1", "param2", "param3", "param4"):
        nan = tuple(i for i, it in enumerate(getattr(mf, name)) if math.isnan(getattr(it, f)))
        if nan:
            losses.append(Loss(name, (f,), nan, NAN_AS_ZERO))
    return losses


def loads_wpl_items(text: str, where: str = "WPL file") -> list[MissionItem]:
    """QGC WPL 110 text -> items exactly as listed (seq renumbered in file order, type guessed)."""
    rows, _, _ = _read(text, where)
    kind, home_row = _list_kind([_int(f[3], "command", ln, where) for ln, f in rows])
    return [
        _item(seq, ln, f, MissionType.MISSION if seq == 0 and home_row else kind, where)
        for seq, (ln, f) in enumerate(rows)
    ]


def _read(text: str, where: str) -> tuple[list[tuple[int, list[str]]], list[tuple[int, str]], str]:
    """(rows as (line number, 12 fields), comments as (rows before it, line), format version)."""
    lines = iter(text.splitlines() if len(text) < 1_000_000 else io.StringIO(text))  # lazily if big
    first = next(lines, "")
    header = first.split()
    if header not in (["QGC", "WPL", v] for v in VERSIONS):
        raise MissionFileError(f"{where}: line 1 must be {HEADER!r}, got {first.strip()[:40]!r}")
    rows, comments = [], []
    for lineno, line in enumerate(lines, start=2):
        if len(rows) > MAX_ROWS:  # checked while reading: a huge file stops here, not after parsing
            raise MissionFileError(
                f"{where}: line {lineno}: more than {MAX_ROWS} rows; a mission holds at most 65535 items"
            )
        if line.lstrip().startswith("#"):
            comments.append((len(rows), line.rstrip("\r\n")))
            continue
        fields = SEPARATORS.split(line.strip())
        if fields == [""]:
            continue
        if len(fields) != 12:
            raise MissionFileError(
                f"{where}: line {lineno}: expected 12 tab-separated fields, got {len(fields)}"
            )
        rows.append((lineno, fields))
    return rows, comments, header[2]


def _list_kind(commands: list[int]) -> tuple[MissionType, bool]:
    """(list type, whether row 0 is a home row): a fence or rally file is all fence / rally rows
    (MAVProxy), or a home row and then those (Mission Planner's savewaypoints writes one)."""
    kind = mission_type_of(commands)
    if kind == MissionType.MISSION and len(commands) > 1 and commands[0] in (0, mavlink.MAV_CMD_NAV_WAYPOINT):
        rest = mission_type_of(commands[1:])
        if rest != MissionType.MISSION:
            return rest, True
    return kind, kind == MissionType.MISSION


def _item(seq: int, lineno: int, f: list[str], mission_type: MissionType, where: str) -> MissionItem:
    frame = _int(f[2], "frame", lineno, where)
    command = _int(f[3], "command", lineno, where)
    scale, _ = _scale(frame, command)
    x, y = (_float(f[k], COLUMNS[k], lineno, where) * scale for k in (8, 9))
    for k, v in ((8, x), (9, y)):
        if not -(2**31) <= v < 2**31:
            raise MissionFileError(
                f"{where}: line {lineno}: field {COLUMNS[k]} = {f[k]!r} does not fit MISSION_ITEM_INT's int32"
            )
    return MissionItem(
        seq=seq,
        frame=frame,
        command=command,
        current=_int(f[1], "current", lineno, where),
        autocontinue=_int(f[11], "autocontinue", lineno, where),
        param1=_float(f[4], "param1", lineno, where),
        param2=_float(f[5], "param2", lineno, where),
        param3=_float(f[6], "param3", lineno, where),
        param4=_float(f[7], "param4", lineno, where),
        x=half_away(x),
        y=half_away(y),
        z=_float(f[10], "z", lineno, where),
        mission_type=mission_type,
    )


def loads_wpl(text: str, autopilot: str = Conventions.ARDUPILOT, where: str = "WPL file") -> MissionFile:
    """WPL text -> MissionFile. Row 0 of a mission is the planned home whatever the autopilot, so
    a PX4 upload leaves it out; ``autopilot`` is kept for callers, it changes nothing. A
    ``QGC WPL 120`` file (QGC's older format) has no home row and DO_JUMP targets one lower."""
    rows, comments, version = _read(text, where)
    kind, home_row = _list_kind([_int(f[3], "command", ln, where) for ln, f in rows])
    if version == "120":
        home_row = False
    items = [
        _item(seq, ln, f, MissionType.MISSION if seq == 0 and home_row else kind, where)
        for seq, (ln, f) in enumerate(rows)
    ]
    _check_kind(rows, kind, home_row, where)
    home_item, body = (items[0], items[1:]) if home_row and items else (None, items)
    if version == "120":
        body = [replace(it, param1=it.param1 + 1) if it.command == DO_JUMP else it for it in body]
    name = LIST_NAMES[kind]
    mf = MissionFile(comments=comments, lists=frozenset({kind}), home_item=home_item)
    if kind == MissionType.MISSION:
        body = [replace(it, current=0) for it in body]  # the upload marks seq 0 current
    setattr(mf, name, [it.with_seq(i) for i, it in enumerate(body)])
    if home_item is not None and (home_item.x, home_item.y) != (0, 0):
        mf.home = (home_item.x / 1e7, home_item.y / 1e7, float(home_item.z))
    mf.notes = unknown_command_notes(body, name)
    return mf


def _check_kind(rows: list[tuple[int, list[str]]], kind: MissionType, home_row: bool, where: str) -> None:
    """A mission WPL holds no fence / rally row: uploaded as mission items they would be flown."""
    if kind != MissionType.MISSION:
        return
    for lineno, f in rows:
        command = _int(f[3], "command", lineno, where)
        if command in FENCE_COMMANDS or command in RALLY_COMMANDS:
            raise MissionFileError(
                f"{where}: line {lineno}: command {command} is a fence / rally row in a mission file;"
                " put fence and rally points in their own file"
            )


def _int(text: str, name: str, lineno: int, where: str) -> int:
    try:
        return int(text)
    except ValueError:
        try:
            value = float(text)  # Mission Planner sometimes writes "16.0"
        except ValueError:
            value = math.nan
        if value.is_integer():
            return int(value)
        raise MissionFileError(f"{where}: line {lineno}: field {name} = {text!r} is not an integer") from None


def _float(text: str, name: str, lineno: int, where: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.inf
    if math.isinf(value) or (math.isnan(value) and name in ("x", "y", "z")):
        raise MissionFileError(f"{where}: line {lineno}: field {name} = {text!r} is not a finite number")
    return value
