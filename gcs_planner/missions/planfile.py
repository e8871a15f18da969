"""QGroundControl .plan files (JSON): mission, planned home, geofence and rally points.

Layout written (QGC's own, plan version 1 / mission version 2)::

    {"fileType": "Plan", "version": 1, "groundStation": "gcs-planner",
     "mission": {"version": 2, "firmwareType", "vehicleType", "cruiseSpeed", "hoverSpeed",
                 "plannedHomePosition": [lat, lon, alt AMSL], "items": [SimpleItem, ...]},
     "geoFence": {"version": 2, "polygons": [...], "circles": [...], "breachReturn"?},
     "rallyPoints": {"version": 2, "points": [[lat, lon, alt], ...]}}

Read as QGroundControl reads (sources in docs/mission-files.md): SimpleItems with seven ``params``
or the older ``coordinate`` + four params; the old ``.mission`` file (the mission object alone,
no ``fileType``); geoFence version 1 (one ``polygon``) and 2; ``null`` params are NaN (QGC's
JsonHelper), null params 5/6 of a command without a position are 0 (MISSION_ITEM_INT x/y are
integers); a "calculated above terrain" waypoint (AltitudeMode 3) with no AMSL altitude yet is
the terrain frame at its ``Altitude`` (QGC would ask its terrain server; the vehicle can follow
terrain itself). DO_JUMP param1 is a doJumpId and becomes the target's position + 1. A
ComplexItem (survey, corridor scan) contributes the SimpleItems QGC generated in
``TransectStyleComplexItem.Items``; one without them (structure scan) is an error.

Written: params 5/6 in degrees for a position, metres for local frames, plain numbers otherwise;
NaN as null; doJumpId = position + 1; fence items as polygons, circles and a breach return point;
a file with no home gets plannedHomePosition [0, 0, 0], which reads back as no home.
``plan_losses`` lists what a .plan cannot carry (a WPL row 0's frame or params, comments, fence
and rally fields beyond position, radius and vertex count).
"""

from __future__ import annotations

import json
import math
from dataclasses import replace
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs_planner.missions.mission_file import (
    DO_JUMP,
    Loss,
    MissionFile,
    MissionFileError,
    default_home_item,
    ranges,
    unknown_command_notes,
)
from gcs_planner.missions.validate import MAX_MISSION_COUNT
from gcs_planner.wire.dialect import has_position
from gcs_planner.wire.types import MissionItem, MissionType
from gcs_planner.wire.units import e7, half_away

__all__ = ["dumps_plan", "loads_plan", "plan_losses"]

POLYGON = {
    True: mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION,
    False: mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION,
}
CIRCLE = {True: mavlink.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, False: mavlink.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION}
RETURN_POINT = mavlink.MAV_CMD_NAV_FENCE_RETURN_POINT
# What QGC sends (GeoFenceManager / RallyPointManager::sendToVehicle): vertices and circles in
# MAV_FRAME_GLOBAL at z 0, the breach return point and rally points relative to home; autocontinue 0.
FENCE_FRAME = mavlink.MAV_FRAME_GLOBAL
RETURN_FRAME = RALLY_FRAME = mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT
ABOVE_TERRAIN = mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT
LOCAL_FRAMES = frozenset({1, 4, 7, 8, 9, 12, 20, 21, 22, 23})  # x/y in metres (MISSION_ITEM_INT: x 1e4)
ALTITUDE_MODE = {  # QGroundControl AltitudeMode by file frame: relative 1, AMSL 2, terrain frame 4
    mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT: 1,
    mavlink.MAV_FRAME_GLOBAL: 2,
    mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT: 4,
}
CALC_ABOVE_TERRAIN = 3  # AltitudeMode: QGC computes AMSL altitudes from its terrain server
NO_SUCH_FENCE = "not written: QGC's geoFence has no such kind of item"
FENCE_LAYOUT = "becomes polygons, circles, breach return (QGC's order)"


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


def plan_losses(mf: MissionFile) -> list[Loss]:
    """What a .plan of ``mf`` cannot carry, one Loss per part and field."""
    losses = []
    if mf.home_item is not None:
        plain = default_home_item()
        fields = tuple(
            f for f in ("frame", "command", "param1", "param2", "param3", "param4", "autocontinue")
            if not _same(getattr(mf.home_item, f), getattr(plain, f))
        )  # fmt: skip
        if fields:
            losses.append(Loss("home", fields, (), "of the WPL home row are not carried by a .plan"
                               " (plannedHomePosition is latitude, longitude, altitude)"))  # fmt: skip
    if mf.comments:
        losses.append(Loss("comments", ("every line",), (), "not carried by a .plan"))
    losses += _item_losses("fence", mf.fence, _fence_carried)
    losses += _item_losses("rally", mf.rally, _rally_carried)
    dropped = tuple(i for i, it in enumerate(mf.fence) if it.command not in FENCE_KINDS)
    if dropped:
        losses.append(
            Loss("fence", ("every field",), dropped, "not written: QGC's geoFence has no such item")
        )
    kept = [it for it in mf.fence if it.command in FENCE_KINDS]
    if [it.command for it in kept] != [it.command for it in _fence_order(kept)]:
        losses.append(
            Loss("fence", ("order",), (), "becomes breach return, polygons, circles (QGC's layout)")
        )
    return losses


def _same(a: float, b: float) -> bool:
    return a == b or (math.isnan(a) and math.isnan(b))


def _item_losses(part: str, items: list[MissionItem], carried) -> list[Loss]:
    """Group the fields each item has but the format drops: field -> item indexes."""
    by_field: dict[str, list[int]] = {}
    for i, it in enumerate(items):
        reference = carried(it)
        if reference is None:
            continue
        for f in ("frame", "autocontinue", "param1", "param2", "param3", "param4", "z"):
            if not _same(getattr(it, f), getattr(reference, f)):
                by_field.setdefault(f, []).append(i)
    return [
        Loss(
            part,
            (f,),
            tuple(idx),
            f"not carried by a .plan (reads back as {getattr(carried(items[idx[0]]), f)!r})",
        )
        for f, idx in by_field.items()
    ]


def _fence_carried(it: MissionItem) -> MissionItem | None:
    """What reading a .plan gives back of a fence item (None: not written at all)."""
    if it.command not in FENCE_KINDS:
        return None
    if it.command == RETURN_POINT:
        return _fence_item(it.command, 0.0, 0.0, z=it.z)
    return _fence_item(it.command, 0.0, 0.0, it.param1)


def _rally_carried(it: MissionItem) -> MissionItem:
    return _rally_item(0.0, 0.0, it.z)


def _json_num(value: float) -> float | None:
    return None if math.isnan(value) else float(value)


def _xy_to_file(it: MissionItem) -> list[float]:
    """MISSION_ITEM_INT x/y -> params 5/6 of a SimpleItem (degrees, metres or plain numbers)."""
    if not has_position(it.command):
        return [it.x, it.y]
    scale = 1e4 if it.frame in LOCAL_FRAMES else 1e7
    return [it.x / scale, it.y / scale]


def _simple_item(it: MissionItem, index: int) -> dict[str, Any]:
    d: dict[str, Any] = {
        "type": "SimpleItem",
        "autoContinue": bool(it.autocontinue),
        "command": int(it.command),
        "doJumpId": index + 1,
        "frame": int(it.frame),
        "params": [_json_num(p) for p in (it.param1, it.param2, it.param3, it.param4)]
        + _xy_to_file(it)
        + [_json_num(it.z)],
    }
    if it.frame in ALTITUDE_MODE:
        d.update(
            {
                "AMSLAltAboveTerrain": None,
                "Altitude": _json_num(it.z),
                "AltitudeMode": ALTITUDE_MODE[it.frame],
            }
        )
    return d


def _fence_order(items: list[MissionItem]) -> list[MissionItem]:
    """QGC's upload order: polygons, then circles, then the breach return point."""
    rank = {**{c: 0 for c in POLYGON.values()}, **{c: 1 for c in CIRCLE.values()}, RETURN_POINT: 2}
    return sorted(items, key=lambda it: rank[it.command])


FENCE_KINDS = frozenset({RETURN_POINT, *POLYGON.values(), *CIRCLE.values()})


def _fence_to_json(items: list[MissionItem]) -> dict[str, Any]:
    polygons, circles, fence = [], [], {"version": 2}
    items = _fence_order([it for it in items if it.command in FENCE_KINDS])
    i = 0
    while i < len(items):
        it = items[i]
        if it.command == RETURN_POINT:
            fence["breachReturn"] = [it.x / 1e7, it.y / 1e7, float(it.z)]
            i += 1
        elif it.command in POLYGON.values():
            count = int(it.param1) if math.isfinite(it.param1) else 0
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
        else:
            circles.append(
                {
                    "circle": {"center": [it.x / 1e7, it.y / 1e7], "radius": _json_num(it.param1)},
                    "inclusion": it.command == CIRCLE[True],
                    "version": 1,
                }
            )
            i += 1
    fence["polygons"] = polygons
    fence["circles"] = circles
    return fence


# ---------------------------------------------------------------- import


class _Notes:
    """What the reader interpreted, as item indexes per kind; one line each at the end."""

    def __init__(self) -> None:
        self.by_kind: dict[str, list[int]] = {}

    def add(self, kind: str, index: int) -> None:
        self.by_kind.setdefault(kind, []).append(index)

    def lines(self) -> list[str]:
        return [
            f"mission item{'s' if len(idx) > 1 else ''} {ranges(tuple(idx))}: {kind}"
            for kind, idx in self.by_kind.items()
        ]


def loads_plan(text: str, where: str = ".plan file") -> MissionFile:
    """.plan JSON (or QGC's older .mission JSON) -> MissionFile; errors name the JSON path and value."""
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise MissionFileError(f"{where}: not valid JSON: {exc}") from None
    except RecursionError:
        raise MissionFileError(f"{where}: nested too deeply") from None
    except ValueError as exc:  # an integer of more than 4300 digits
        raise MissionFileError(f"{where}: not valid JSON: {str(exc)[:80]}") from None
    if isinstance(doc, dict) and "fileType" not in doc and isinstance(doc.get("items"), list):
        mission, fence, rally = doc, {}, {}  # a .mission file: the mission object alone
        lists = frozenset({MissionType.MISSION})
    elif isinstance(doc, dict) and doc.get("fileType") == "Plan":
        if not isinstance(doc.get("mission"), dict) or not isinstance(doc["mission"].get("items"), list):
            # QGroundControl and MAVSDK refuse such a file; reading it as empty would clear the vehicle
            raise MissionFileError(f'{where}: a .plan needs a "mission" object with an "items" list')
        mission, fence, rally = (
            doc.get("mission", {}),
            doc.get("geoFence") or {},
            doc.get("rallyPoints") or {},
        )
        lists = frozenset(MissionType(t) for t in (0, 1, 2))
    else:
        raise MissionFileError(f"{where}: fileType must be 'Plan', got {_get(doc, 'fileType')!r}")
    if not isinstance(mission, dict):
        raise MissionFileError(f"{where}: mission must be an object")
    if mission.get("complexItems"):
        raise MissionFileError(
            f"{where}: complexItems (QGC version 1 surveys) cannot be imported; open and save the file"
            " in QGroundControl to convert it"
        )
    notes = _Notes()
    items, jump_ids = [], []
    raws = _list(mission.get("items", []), where, "mission.items")
    _count(len(raws), where, "mission.items")
    for i, raw in enumerate(raws):
        path = f"mission.items[{i}]"
        kind = _get(raw, "type")
        if kind in ("SimpleItem", "missionItem"):
            subs = [(raw, path)]
        elif kind == "ComplexItem":
            inner = _get(_get(raw, "TransectStyleComplexItem"), "Items")
            inner = inner if inner is None else _list(inner, where, f"{path}.TransectStyleComplexItem.Items")
            if not isinstance(inner, list):
                raise MissionFileError(
                    f"{where}: {path}: ComplexItem {_get(raw, 'complexItemType')!r} has no"
                    " TransectStyleComplexItem.Items to import"
                )
            subs = [(sub, f"{path}.TransectStyleComplexItem.Items[{j}]") for j, sub in enumerate(inner)]
        else:
            raise MissionFileError(f"{where}: {path}: type must be SimpleItem or ComplexItem, got {kind!r}")
        _count(len(items) + len(subs), where, "mission.items (with their survey items)")
        for sub, sub_path in subs:
            items.append(_parse_simple(sub, where, sub_path, notes, len(items)))
            jump_ids.append(_get(sub, "doJumpId"))
    items = _resolve_jumps([it.with_seq(k) for k, it in enumerate(items)], jump_ids, notes)
    home = _home(mission.get("plannedHomePosition"), where)
    kwargs = {}
    for key, name in (
        ("firmwareType", "firmware_type"),
        ("vehicleType", "vehicle_type"),
        ("cruiseSpeed", "cruise_speed_mps"),
        ("hoverSpeed", "hover_speed_mps"),
    ):
        value = mission.get(key)
        if isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value):
            kwargs[name] = value
    return MissionFile(
        mission=items,
        home=home,
        fence=_parse_fence(_dict(fence or {}, where, "geoFence"), where),
        rally=_parse_rally(_dict(rally or {}, where, "rallyPoints"), where),
        lists=lists,
        notes=notes.lines() + unknown_command_notes(items, "mission"),
        **kwargs,
    )


def _count(n: int, where: str, path: str) -> None:
    """MissionFileError when a list holds more items than MISSION_COUNT can (65,535), checked
    before the items are built (a huge file is one line, not minutes of parsing)."""
    if n > MAX_MISSION_COUNT:
        raise MissionFileError(f"{where}: {path} holds {n:,} items; a mission list holds at most "
                               f"{MAX_MISSION_COUNT:,} (MISSION_COUNT is 16-bit)")  # fmt: skip


def _home(value: Any, where: str) -> tuple[float, float, float] | None:
    """plannedHomePosition: [lat, lon, alt] (or an old SimpleItem with ``coordinate``); 0, 0 is none."""
    if value is None:
        return None
    path = "mission.plannedHomePosition"
    if isinstance(value, dict):
        value, path = value.get("coordinate"), f"{path}.coordinate"
    lat, lon, alt = _numbers(value, 3, where, path)
    _check_lat_lon(lat, lon, where, path)
    return None if (lat, lon) == (0.0, 0.0) else (lat, lon, alt)


def _resolve_jumps(items: list[MissionItem], jump_ids: list[Any], notes: _Notes) -> list[MissionItem]:
    """DO_JUMP param1 (a doJumpId in the file) -> the target's position + 1 (ArduPilot's seq)."""
    position = {jid: k + 1 for k, jid in enumerate(jump_ids) if isinstance(jid, int)}
    out = []
    for k, it in enumerate(items):
        if it.command == DO_JUMP and math.isfinite(it.param1):
            target = position.get(int(it.param1)) if it.param1.is_integer() else None
            if target is None:
                notes.add(f"DO_JUMP target doJumpId {it.param1:g} is not in the file; kept as written", k)
            else:
                it = replace(it, param1=float(target))
        out.append(it)
    return out


def _list(value: Any, where: str, path: str) -> list:
    if not isinstance(value, list):
        raise MissionFileError(f"{where}: {path} must be a list, got {value!r}")
    return value


def _dict(value: Any, where: str, path: str) -> dict:
    if not isinstance(value, dict):
        raise MissionFileError(f"{where}: {path} must be an object, got {value!r}")
    return value


def _get(d: Any, key: str) -> Any:
    return d.get(key) if isinstance(d, dict) else None


def _numbers(value: Any, n: int, where: str, path: str, allow_null: bool = False) -> list[float]:
    ok = isinstance(value, list) and len(value) == n
    out = []
    for v in value if ok else []:
        if v is None and allow_null:
            out.append(math.nan)
        elif isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v):
            out.append(float(v))
        else:
            ok = False
    if not ok:
        kind = "finite numbers or null" if allow_null else "finite numbers"
        raise MissionFileError(f"{where}: {path} must be a list of {n} {kind}, got {value!r}")
    return out


def _params(raw: dict, where: str, path: str) -> list[float]:
    """params 1..7: seven ``params``, or QGC's older four ``params`` (or ``param1``..``param4``)
    + ``coordinate`` [lat, lon, alt] (MissionItem::_convertJsonV1ToV2 / _convertJsonV2ToV3)."""
    if "coordinate" not in raw:
        return _numbers(raw.get("params"), 7, where, f"{path}.params", allow_null=True)
    if "params" in raw:
        first = _numbers(raw.get("params"), 4, where, f"{path}.params", allow_null=True)
    else:
        first = [_numbers([raw.get(f"param{k}")], 1, where, f"{path}.param{k}")[0] for k in range(1, 5)]
    return first + _numbers(raw.get("coordinate"), 3, where, f"{path}.coordinate", allow_null=True)


def _parse_simple(raw: Any, where: str, path: str, notes: _Notes, index: int) -> MissionItem:
    if _get(raw, "type") not in ("SimpleItem", "missionItem"):  # "missionItem": QGC's version 1
        raise MissionFileError(f"{where}: {path}: type must be SimpleItem, got {_get(raw, 'type')!r}")
    for key in ("command", "frame"):
        if not isinstance(raw.get(key), int) or isinstance(raw.get(key), bool):
            raise MissionFileError(f"{where}: {path}.{key} must be an integer, got {raw.get(key)!r}")
    command, frame = raw["command"], raw["frame"]
    p = _params(raw, where, path)
    if has_position(command):
        if not (math.isfinite(p[4]) and math.isfinite(p[5])):
            raise MissionFileError(
                f"{where}: {path}.params[4:6] (latitude, longitude) must be numbers, got {p[4:6]}"
            )
        scale = 1e4 if frame in LOCAL_FRAMES else 1e7
        if scale == 1e7:
            _check_lat_lon(p[4], p[5], where, f"{path}.params[4:6]")
        x, y = (_int32(half_away(v * scale), where, f"{path}.params[4:6]") for v in p[4:6])
    else:
        if not (math.isfinite(p[4]) and math.isfinite(p[5])):
            notes.add("params 5/6 null, sent as 0 (MISSION_ITEM_INT x/y are integers)", index)
        x, y = (_int32(half_away(v), where, f"{path}.params[4:6]") if math.isfinite(v) else 0 for v in p[4:6])
    z = p[6]
    if not math.isfinite(z):
        frame, z = _null_altitude(raw, frame, command, where, path, notes, index)
    return MissionItem(
        seq=0,
        frame=frame,
        command=command,
        autocontinue=int(bool(raw.get("autoContinue", True))),
        param1=p[0],
        param2=p[1],
        param3=p[2],
        param4=p[3],
        x=x,
        y=y,
        z=z,
    )


def _null_altitude(
    raw: dict, frame: int, command: int, where: str, path: str, notes: _Notes, index: int
) -> tuple[int, float]:
    """(frame, z) for params[6] = null: QGC's not-yet-computed terrain altitude, or a positionless 0."""
    amsl, altitude = raw.get("AMSLAltAboveTerrain"), raw.get("Altitude")
    if raw.get("AltitudeMode") == CALC_ABOVE_TERRAIN and isinstance(amsl, int | float):
        return frame, float(amsl)
    if raw.get("AltitudeMode") == CALC_ABOVE_TERRAIN and isinstance(altitude, int | float):
        notes.add(
            "QGC 'calculated above terrain' altitude with no AMSL value in the file: sent in"
            " MAV_FRAME_GLOBAL_TERRAIN_ALT at its Altitude above terrain",
            index,
        )
        return ABOVE_TERRAIN, float(altitude)
    if not has_position(command):
        notes.add("params 7 (altitude) null, sent as 0", index)
        return frame, 0.0
    raise MissionFileError(f"{where}: {path}.params[6] (altitude) must be a number, got null")


def _check_lat_lon(lat: float, lon: float, where: str, path: str) -> None:
    if not (-90 <= lat <= 90 and -180 <= lon <= 180):
        raise MissionFileError(f"{where}: {path}: latitude, longitude {lat!r}, {lon!r} out of range")


def _int32(value: int, where: str, path: str) -> int:
    if not -(2**31) <= value < 2**31:
        raise MissionFileError(f"{where}: {path}: {value} does not fit MISSION_ITEM_INT's int32 x / y")
    return value


def _fence_item(command: int, lat: float, lon: float, param1: float = 0.0, z: float = 0.0) -> MissionItem:
    frame = RETURN_FRAME if command == RETURN_POINT else FENCE_FRAME
    return MissionItem(
        0, frame, command, 0, 0, param1, x=e7(lat), y=e7(lon), z=z, mission_type=MissionType.FENCE
    )


def _rally_item(lat: float, lon: float, alt: float) -> MissionItem:
    return MissionItem(0, RALLY_FRAME, mavlink.MAV_CMD_NAV_RALLY_POINT, 0, 0, x=e7(lat), y=e7(lon), z=alt,
                       mission_type=MissionType.RALLY)  # fmt: skip


def _parse_fence(fence: Any, where: str) -> list[MissionItem]:
    """geoFence version 2 (``polygons``, ``circles``) or 1 (one inclusion ``polygon``), in QGC's
    upload order."""
    if not isinstance(fence, dict):
        raise MissionFileError(f"{where}: geoFence must be an object")
    items = []
    polygons = list(_list(fence.get("polygons", []), where, "geoFence.polygons"))
    if fence.get("polygon"):
        polygons.insert(0, {"polygon": fence["polygon"], "inclusion": True})
    _count(len(polygons), where, "geoFence.polygons")
    for i, poly in enumerate(polygons):
        path = f"geoFence.polygons[{i}]"
        vertices = _get(poly, "polygon")
        if not isinstance(vertices, list) or len(vertices) < 3:
            raise MissionFileError(f"{where}: {path}.polygon must list at least 3 [lat, lon] vertices")
        _count(len(items) + len(vertices), where, "geoFence (polygon vertices)")
        cmd = POLYGON[bool(poly.get("inclusion", True))]
        for j, v in enumerate(vertices):
            lat, lon = _numbers(v, 2, where, f"{path}.polygon[{j}]")
            _check_lat_lon(lat, lon, where, f"{path}.polygon[{j}]")
            items.append(_fence_item(cmd, lat, lon, float(len(vertices))))
    for i, circ in enumerate(_list(fence.get("circles", []), where, "geoFence.circles")):
        path = f"geoFence.circles[{i}]"
        _count(len(items) + 1, where, "geoFence (vertices and circles)")
        lat, lon = _numbers(_get(_get(circ, "circle"), "center"), 2, where, f"{path}.circle.center")
        _check_lat_lon(lat, lon, where, f"{path}.circle.center")
        (radius,) = _numbers([_get(_get(circ, "circle"), "radius")], 1, where, f"{path}.circle.radius")
        items.append(_fence_item(CIRCLE[bool(circ.get("inclusion", True))], lat, lon, radius))
    if fence.get("breachReturn") is not None:
        lat, lon, alt = _numbers(fence["breachReturn"], 3, where, "geoFence.breachReturn")
        _check_lat_lon(lat, lon, where, "geoFence.breachReturn")
        items.append(_fence_item(RETURN_POINT, lat, lon, z=alt))
    return [it.with_seq(k) for k, it in enumerate(items)]


def _parse_rally(rally: Any, where: str) -> list[MissionItem]:
    points = _list(_get(rally, "points") or [], where, "rallyPoints.points")
    _count(len(points), where, "rallyPoints.points")
    items = []
    for i, pt in enumerate(points):
        lat, lon, alt = _numbers(pt, 3, where, f"rallyPoints.points[{i}]")
        _check_lat_lon(lat, lon, where, f"rallyPoints.points[{i}]")
        items.append(_rally_item(lat, lon, alt).with_seq(i))
    return items
