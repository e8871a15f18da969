"""Mission Planner / MAVProxy "QGC WPL 110" text files.

Format: a first line ``QGC WPL 110``, then one line per item, tab-separated:
INDEX CURRENT FRAME COMMAND P1 P2 P3 P4 LAT LON ALT AUTOCONTINUE (``#`` lines are comments).
ArduPilot files hold home as row 0.

Choices:
- Exact round trip: latitude/longitude are written from the integer degE7 with exactly 7 decimals
  (pymavlink's mavwp writes ``%f``, 6 decimals, losing up to 5.6 cm); params and altitude are
  written as Python's shortest exact float repr. Reading rounds degrees to degE7 half away from
  zero, so any file written here reads back to the same MissionItems.
- Frames are stored as the float frame numbers Mission Planner uses (see gcs_planner.mavlink.files).
- Local frames store x/y in metres (MISSION_ITEM_INT holds metres x 1e4); commands without a
  position (MAVLink hasLocation="false": DO_DIGICAM_CONTROL, RTL, ...) store params 5/6 as the
  plain numbers MISSION_ITEM_INT carries, unscaled (MAVProxy sends them so, ArduPilot reads them so).
- Row 0 is the planned home for every autopilot (QGroundControl's reading); a list written for a
  vehicle without a home item gets one (the planned home, or zeros when there is none, as QGC).
- The INDEX column is informational: rows are numbered in file order on reading.
- The mission type is not in the file: a file of fence commands (5000-5004) reads as a fence,
  of rally points (5100) as rally points, anything else as a mission.
"""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs_planner.mavlink.files import MissionFile, MissionFileError, file_frame, item_frame, mission_type_of
from gcs_planner.mavlink.items import half_away
from gcs_planner.mavlink.readback import has_position
from gcs_planner.mavlink.types import MissionItem, MissionType

__all__ = ["HEADER", "dumps_wpl", "loads_wpl", "loads_wpl_items"]

HEADER = "QGC WPL 110"
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
    return repr(float(value))


def dumps_wpl(items: list[MissionItem]) -> str:
    """Items (as uploaded: ArduPilot lists include home at seq 0) -> QGC WPL 110 text."""
    lines = [HEADER]
    for i, it in enumerate(items):
        _, decimals = _scale(it.frame, it.command)
        row = [
            str(i),
            str(int(it.current)),
            str(file_frame(it.frame)),
            str(it.command),
            *(_num(p) for p in (it.param1, it.param2, it.param3, it.param4)),
            _fixed(it.x, decimals),
            _fixed(it.y, decimals),
            _num(it.z),
            str(int(it.autocontinue)),
        ]
        lines.append("\t".join(row))
    return "\n".join(lines) + "\n"


def loads_wpl_items(text: str, where: str = "WPL file") -> list[MissionItem]:
    """QGC WPL 110 text -> items exactly as listed (seq renumbered in file order, type guessed)."""
    lines = text.splitlines()
    if not lines or lines[0].strip() != HEADER:
        first = lines[0].strip() if lines else ""
        raise MissionFileError(f"{where}: line 1 must be {HEADER!r}, got {first[:40]!r}")
    rows = []
    for lineno, line in enumerate(lines[1:], start=2):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        fields = line.split()
        if len(fields) != 12:
            raise MissionFileError(
                f"{where}: line {lineno}: expected 12 tab-separated fields, got {len(fields)}"
            )
        rows.append((lineno, fields))
    mission_type = mission_type_of([_int(f[3], "command", ln, where) for ln, f in rows])
    items = []
    for seq, (lineno, f) in enumerate(rows):
        frame = item_frame(_int(f[2], "frame", lineno, where))
        command = _int(f[3], "command", lineno, where)
        global_frame = frame in (0, 3, 5, 6, 10, 11)
        if not has_position(command) and global_frame and mission_type == MissionType.MISSION:
            frame = mavlink.MAV_FRAME_MISSION  # a command without a position has no frame (PX4 insists)
        scale, _ = _scale(frame, command)
        x, y = (_float(f[k], COLUMNS[k], lineno, where) for k in (8, 9))
        if not (math.isfinite(x) and math.isfinite(y)):
            raise MissionFileError(f"{where}: line {lineno}: x/y must be finite, got {f[8]!r}, {f[9]!r}")
        items.append(
            MissionItem(
                seq=seq,
                frame=frame,
                command=_int(f[3], "command", lineno, where),
                current=_int(f[1], "current", lineno, where),
                autocontinue=_int(f[11], "autocontinue", lineno, where),
                param1=_float(f[4], "param1", lineno, where),
                param2=_float(f[5], "param2", lineno, where),
                param3=_float(f[6], "param3", lineno, where),
                param4=_float(f[7], "param4", lineno, where),
                x=half_away(x * scale),
                y=half_away(y * scale),
                z=_float(f[10], "z", lineno, where),
                mission_type=mission_type,
            )
        )
    return items


def loads_wpl(text: str, autopilot: str = "ardupilot", where: str = "WPL file") -> MissionFile:
    """QGC WPL 110 text -> MissionFile; row 0 of a mission is the planned home, whatever the
    autopilot (QGroundControl's MissionController::_loadTextMissionFile reads every WPL 110 file so),
    so a PX4 upload leaves it out. ``autopilot`` is kept for callers; it changes nothing."""
    items = loads_wpl_items(text, where)
    kind = items[0].mission_type if items else MissionType.MISSION
    if kind == MissionType.FENCE:
        return MissionFile(fence=items)
    if kind == MissionType.RALLY:
        return MissionFile(rally=items)
    return MissionFile.from_items(items, autopilot="ardupilot")


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
        return float(text)
    except ValueError:
        raise MissionFileError(f"{where}: line {lineno}: field {name} = {text!r} is not a number") from None
