"""MAVProxy's and Mission Planner's older fence and rally files (read only).

- Fence: one ``lat lon`` pair per line (``#`` comments): the breach return point, the inclusion
  polygon's vertices, then a closing point, which is dropped (pymavlink mavwp
  MissionItemProtocol_Fence.load; Mission Planner's .fen is the same list). At least 5 lines.
- Rally: ``RALLY lat lon alt break_alt land_dir flags`` lines (MissionItemProtocol_Rally.load):
  NAV_RALLY_POINT relative to home at ``alt`` metres (mavwp multiplies it by 1000, a bug not
  followed here); break_alt, land_dir and flags have no field in a MISSION_ITEM_INT rally point.
Both become MISSION_ITEM_INT lists as mavwp builds them (autocontinue 0), degE7 rounded half away.
"""

from __future__ import annotations

import re

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs_planner.missions.mission_file import MissionFile, MissionFileError
from gcs_planner.wire.types import MissionItem, MissionType
from gcs_planner.wire.units import e7

__all__ = ["is_legacy_fence", "is_legacy_rally", "loads_legacy_fence", "loads_legacy_rally"]

FENCE_LINE = re.compile(r"[-0-9.]+\s+[-0-9.]+")
RALLY_LINE = re.compile(r"RALLY\s", re.IGNORECASE)


def _data_lines(text: str) -> list[tuple[int, list[str]]]:
    return [
        (n, line.split())
        for n, line in enumerate(text.splitlines(), start=1)
        if line.strip() and not line.lstrip().startswith("#")
    ]


def is_legacy_fence(text: str) -> bool:
    lines = _data_lines(text)
    return bool(lines) and FENCE_LINE.match(" ".join(lines[0][1])) is not None


def is_legacy_rally(text: str) -> bool:
    lines = _data_lines(text)
    return bool(lines) and RALLY_LINE.match(" ".join(lines[0][1])) is not None


def _number(text: str, name: str, lineno: int, where: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise MissionFileError(f"{where}: line {lineno}: {name} = {text!r} is not a number") from None


def _point(fields: list[str], lineno: int, where: str) -> tuple[float, float]:
    lat, lon = (_number(v, k, lineno, where) for v, k in zip(fields, ("latitude", "longitude")))
    if not (-90 <= lat <= 90 and -180 <= lon <= 180):
        raise MissionFileError(f"{where}: line {lineno}: latitude/longitude {lat}, {lon} out of range")
    return lat, lon


def loads_legacy_fence(text: str, where: str = "fence file") -> MissionFile:
    lines = _data_lines(text)
    for lineno, fields in lines:
        if len(fields) != 2:
            raise MissionFileError(
                f"{where}: line {lineno}: expected 'latitude longitude', got {len(fields)} fields"
            )
    if len(lines) < 5:
        raise MissionFileError(
            f"{where}: {len(lines)} points; a fence list needs a return point, 3 vertices and a closing point"
        )
    points = [_point(fields, lineno, where) for lineno, fields in lines]
    vertices = points[1:-1]
    fence = MissionType.FENCE

    def item(seq: int, command: int, lat: float, lon: float, count: float = 0.0) -> MissionItem:
        return MissionItem(seq, mavlink.MAV_FRAME_GLOBAL, command, 0, 0, count, x=e7(lat), y=e7(lon),
                           mission_type=fence)  # fmt: skip

    items = [item(0, mavlink.MAV_CMD_NAV_FENCE_RETURN_POINT, *points[0])]
    inclusion = mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION
    items += [item(i + 1, inclusion, lat, lon, float(len(vertices))) for i, (lat, lon) in enumerate(vertices)]
    notes = [f"fence: the closing point (line {lines[-1][0]}) is dropped, as MAVProxy does"]
    if points[-1] != points[1]:
        notes[0] += f"; it differs from the first vertex {points[1]}"
    return MissionFile(fence=items, lists=frozenset({fence}), notes=notes)


def loads_legacy_rally(text: str, where: str = "rally file") -> MissionFile:
    items = []
    for lineno, fields in _data_lines(text):
        if len(fields) != 7 or fields[0].lower() != "rally":
            raise MissionFileError(
                f"{where}: line {lineno}: expected 'RALLY lat lon alt break_alt land_dir flags'"
            )
        lat, lon = _point(fields[1:3], lineno, where)
        alt = _number(fields[3], "altitude", lineno, where)
        items.append(
            MissionItem(
                len(items),
                mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT,
                mavlink.MAV_CMD_NAV_RALLY_POINT,
                0,
                0,
                x=e7(lat),
                y=e7(lon),
                z=alt,
                mission_type=MissionType.RALLY,
            )  # fmt: skip
        )
    notes = ["rally: break_alt, land_dir and flags are not carried by MISSION_ITEM_INT rally points; dropped"]
    return MissionFile(rally=items, lists=frozenset({MissionType.RALLY}), notes=notes)
