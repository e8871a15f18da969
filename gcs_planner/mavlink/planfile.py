"""QGroundControl .plan files (JSON): mission, planned home, geofence and rally points.

Layout written (QGC's own, version 1 / mission version 2)::

    {"fileType": "Plan", "version": 1, "groundStation": "gcs-planner",
     "mission": {"version": 2, "firmwareType", "vehicleType", "cruiseSpeed", "hoverSpeed",
                 "plannedHomePosition": [lat, lon, alt AMSL], "items": [SimpleItem, ...]},
     "geoFence": {"version": 2, "polygons": [...], "circles": [...], "breachReturn"?},
     "rallyPoints": {"version": 2, "points": [[lat, lon, alt], ...]}}

Choices:
- SimpleItem ``params`` hold param1..4 then latitude, longitude [deg] and altitude; NaN params are
  written as null (QGC's convention) and read back as NaN. ``doJumpId`` is seq + 1.
- Items keep the file's float frame numbers on disk; see gcs_planner.mavlink.files for the mapping.
- On import, a ComplexItem (survey, corridor scan) contributes the SimpleItems QGC generated in
  ``TransectStyleComplexItem.Items``; a ComplexItem without them (structure scan) is an error,
  since its items are only computed inside QGC.
- Fence items: polygons first, then circles (the order QGC uploads them), frame MAV_FRAME_GLOBAL,
  a polygon vertex's param1 = its vertex count, a circle's param1 = its radius [m]. A breach
  return point, if any, is item 0. Rally points are NAV_RALLY_POINT in GLOBAL_RELATIVE_ALT_INT.
"""

from __future__ import annotations

import json
import math
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs_planner.mavlink.files import MissionFile, MissionFileError, file_frame, item_frame
from gcs_planner.mavlink.items import e7, half_away
from gcs_planner.mavlink.readback import has_position
from gcs_planner.mavlink.types import MissionItem, MissionType

__all__ = ["dumps_plan", "loads_plan"]

POLYGON = {
    True: mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION,
    False: mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION,
}
CIRCLE = {True: mavlink.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, False: mavlink.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION}
RETURN_POINT = mavlink.MAV_CMD_NAV_FENCE_RETURN_POINT
ALTITUDE_MODE = {  # QGroundControl AltitudeMode by file frame: relative 1, AMSL 2, terrain frame 4
    mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT: 1,
    mavlink.MAV_FRAME_GLOBAL: 2,
    mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT: 4,
}


# ---------------------------------------------------------------- export


def dumps_plan(mf: MissionFile) -> str:
    """MissionFile -> .plan JSON text (indented like QGroundControl's)."""
    home = list(mf.home) if mf.home is not None else [0.0, 0.0, 0.0]
    doc = {
        "fileType": "Plan",
        "version": 1,
        "groundStation": "gcs-planner",
        "mission": {
            "version": 2,
            "firmwareType": int(mf.firmware_type),
            "vehicleType": int(mf.vehicle_type),
            "cruiseSpeed": mf.cruise_speed_mps,
            "hoverSpeed": mf.hover_speed_mps,
            "plannedHomePosition": home,
            "items": [_simple_item(it, i) for i, it in enumerate(mf.mission)],
        },
        "geoFence": _fence_to_json(mf.fence),
        "rallyPoints": {
            "version": 2,
            "points": [[it.x / 1e7, it.y / 1e7, _json_num(it.z)] for it in mf.rally],
        },
    }
    return json.dumps(doc, indent=4, allow_nan=False) + "\n"


def _json_num(value: float) -> float | None:
    return None if math.isnan(value) else float(value)


def _simple_item(it: MissionItem, index: int) -> dict[str, Any]:
    frame = file_frame(it.frame)
    d: dict[str, Any] = {
        "type": "SimpleItem",
        "autoContinue": bool(it.autocontinue),
        "command": int(it.command),
        "doJumpId": index + 1,
        "frame": frame,
        "params": [_json_num(p) for p in (it.param1, it.param2, it.param3, it.param4)]
        + ([it.x / 1e7, it.y / 1e7] if has_position(it.command) else [it.x, it.y])
        + [_json_num(it.z)],
    }
    if frame in ALTITUDE_MODE:
        d.update(
            {"AMSLAltAboveTerrain": None, "Altitude": _json_num(it.z), "AltitudeMode": ALTITUDE_MODE[frame]}
        )
    return d


def _fence_to_json(items: list[MissionItem]) -> dict[str, Any]:
    polygons, circles, fence = [], [], {"version": 2}
    i = 0
    while i < len(items):
        it = items[i]
        if it.command == RETURN_POINT:
            fence["breachReturn"] = [it.x / 1e7, it.y / 1e7, float(it.z)]
            i += 1
        elif it.command in POLYGON.values():
            count = int(it.param1)
            group = items[i : i + count]
            if count < 3 or len(group) < count or any(g.command != it.command for g in group):
                raise MissionFileError(
                    f"fence item {i}: polygon of param1 = {it.param1!r} vertices is incomplete or too small"
                )
            polygons.append(
                {
                    "inclusion": it.command == POLYGON[True],
                    "polygon": [[g.x / 1e7, g.y / 1e7] for g in group],
                    "version": 1,
                }
            )
            i += count
        elif it.command in CIRCLE.values():
            circles.append(
                {
                    "circle": {"center": [it.x / 1e7, it.y / 1e7], "radius": float(it.param1)},
                    "inclusion": it.command == CIRCLE[True],
                    "version": 1,
                }
            )
            i += 1
        else:
            raise MissionFileError(f"fence item {i}: command {it.command} is not a fence command")
    fence["polygons"] = polygons
    fence["circles"] = circles
    return fence


# ---------------------------------------------------------------- import


def loads_plan(text: str, where: str = ".plan file") -> MissionFile:
    """.plan JSON text -> MissionFile (errors name the JSON path and the value)."""
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise MissionFileError(f"{where}: not valid JSON: {exc}") from None
    if not isinstance(doc, dict) or doc.get("fileType") != "Plan":
        raise MissionFileError(f"{where}: fileType must be 'Plan', got {_get(doc, 'fileType')!r}")
    mission = doc.get("mission", {})
    if not isinstance(mission, dict):
        raise MissionFileError(f"{where}: mission must be an object")
    items: list[MissionItem] = []
    for i, raw in enumerate(mission.get("items", [])):
        path = f"mission.items[{i}]"
        kind = _get(raw, "type")
        if kind == "SimpleItem":
            items.append(_parse_simple(raw, where, path))
        elif kind == "ComplexItem":
            inner = _get(_get(raw, "TransectStyleComplexItem"), "Items")
            if not isinstance(inner, list):
                raise MissionFileError(
                    f"{where}: {path}: ComplexItem {_get(raw, 'complexItemType')!r} has no"
                    " TransectStyleComplexItem.Items to import"
                )
            for j, sub in enumerate(inner):
                items.append(_parse_simple(sub, where, f"{path}.TransectStyleComplexItem.Items[{j}]"))
        else:
            raise MissionFileError(f"{where}: {path}: type must be SimpleItem or ComplexItem, got {kind!r}")
    items = [it.with_seq(k) for k, it in enumerate(items)]
    home = mission.get("plannedHomePosition")
    if home is not None:
        home = tuple(_numbers(home, 3, where, "mission.plannedHomePosition"))
    kwargs = {}
    for key, name in (
        ("firmwareType", "firmware_type"),
        ("vehicleType", "vehicle_type"),
        ("cruiseSpeed", "cruise_speed_mps"),
        ("hoverSpeed", "hover_speed_mps"),
    ):
        if isinstance(mission.get(key), int | float) and not isinstance(mission.get(key), bool):
            kwargs[name] = mission[key]
    return MissionFile(
        mission=items,
        home=home,
        fence=_parse_fence(doc.get("geoFence") or {}, where),
        rally=_parse_rally(doc.get("rallyPoints") or {}, where),
        **kwargs,
    )


def _get(d: Any, key: str) -> Any:
    return d.get(key) if isinstance(d, dict) else None


def _numbers(value: Any, n: int, where: str, path: str, allow_null: bool = False) -> list[float]:
    ok = isinstance(value, list) and len(value) == n
    out = []
    for v in value if ok else []:
        if v is None and allow_null:
            out.append(math.nan)
        elif isinstance(v, int | float) and not isinstance(v, bool):
            out.append(float(v))
        else:
            ok = False
    if not ok:
        raise MissionFileError(f"{where}: {path} must be a list of {n} numbers, got {value!r}")
    return out


def _parse_simple(raw: Any, where: str, path: str) -> MissionItem:
    if _get(raw, "type") != "SimpleItem":
        raise MissionFileError(f"{where}: {path}: type must be SimpleItem, got {_get(raw, 'type')!r}")
    for key in ("command", "frame"):
        if not isinstance(raw.get(key), int) or isinstance(raw.get(key), bool):
            raise MissionFileError(f"{where}: {path}.{key} must be an integer, got {raw.get(key)!r}")
    p = _numbers(raw.get("params"), 7, where, f"{path}.params", allow_null=True)
    if not (math.isfinite(p[4]) and math.isfinite(p[5])):
        raise MissionFileError(
            f"{where}: {path}.params[4:6] (latitude, longitude) must be numbers, got {p[4:6]}"
        )
    return MissionItem(
        seq=0,
        frame=item_frame(raw["frame"]),
        command=raw["command"],
        autocontinue=int(bool(raw.get("autoContinue", True))),
        param1=p[0],
        param2=p[1],
        param3=p[2],
        param4=p[3],
        x=e7(p[4]) if has_position(raw["command"]) else half_away(p[4]),  # params 5/6 raw without a position
        y=e7(p[5]) if has_position(raw["command"]) else half_away(p[5]),
        z=p[6],
    )


def _fence_item(command: int, lat: float, lon: float, param1: float = 0.0, z: float = 0.0) -> MissionItem:
    return MissionItem(
        0,
        mavlink.MAV_FRAME_GLOBAL,
        command,
        0,
        1,
        param1,
        x=e7(lat),
        y=e7(lon),
        z=z,
        mission_type=MissionType.FENCE,
    )


def _parse_fence(fence: Any, where: str) -> list[MissionItem]:
    if not isinstance(fence, dict):
        raise MissionFileError(f"{where}: geoFence must be an object")
    items = []
    if fence.get("breachReturn") is not None:
        lat, lon, alt = _numbers(fence["breachReturn"], 3, where, "geoFence.breachReturn")
        items.append(_fence_item(RETURN_POINT, lat, lon, z=alt))
    for i, poly in enumerate(fence.get("polygons", [])):
        path = f"geoFence.polygons[{i}]"
        vertices = _get(poly, "polygon")
        if not isinstance(vertices, list) or len(vertices) < 3:
            raise MissionFileError(f"{where}: {path}.polygon must list at least 3 [lat, lon] vertices")
        cmd = POLYGON[bool(poly.get("inclusion", True))]
        for j, v in enumerate(vertices):
            lat, lon = _numbers(v, 2, where, f"{path}.polygon[{j}]")
            items.append(_fence_item(cmd, lat, lon, float(len(vertices))))
    for i, circ in enumerate(fence.get("circles", [])):
        path = f"geoFence.circles[{i}]"
        lat, lon = _numbers(_get(_get(circ, "circle"), "center"), 2, where, f"{path}.circle.center")
        (radius,) = _numbers([_get(_get(circ, "circle"), "radius")], 1, where, f"{path}.circle.radius")
        items.append(_fence_item(CIRCLE[bool(circ.get("inclusion", True))], lat, lon, radius))
    return [it.with_seq(k) for k, it in enumerate(items)]


def _parse_rally(rally: Any, where: str) -> list[MissionItem]:
    points = _get(rally, "points") or []
    items = []
    for i, pt in enumerate(points):
        lat, lon, alt = _numbers(pt, 3, where, f"rallyPoints.points[{i}]")
        items.append(
            MissionItem(
                i,
                mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                mavlink.MAV_CMD_NAV_RALLY_POINT,
                0,
                1,
                x=e7(lat),
                y=e7(lon),
                z=alt,
                mission_type=MissionType.RALLY,
            )
        )
    return items
