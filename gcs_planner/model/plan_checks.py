"""Checks of plan.json's content before it becomes a Plan: types, shapes, physical limits.

Limits are those of gcs_planner.core.validation (docs/input-validation.md): positions within
MAX_RANGE_M of the origin and between MIN_ALT_M and MAX_ALT_M, speeds in [0, MAX_SPEED_MPS],
radii in [0, MAX_RADIUS_M], times in [0, MAX_DURATION_S] and never decreasing.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from gcs_planner.core.fleet_ids import MAX_NETWORK, fleet_id
from gcs_planner.core.geo import Origin
from gcs_planner.core.validation import (
    MAX_ALT_M,
    MAX_DURATION_S,
    MAX_RADIUS_M,
    MAX_RANGE_M,
    MAX_SPEED_MPS,
    MAX_WAYPOINTS,
    MIN_ALT_M,
    InputError,
    integer,
    items_of,
    name,
    number,
    table,
)
from gcs_planner.core.validation import origin as checked_origin

__all__ = ["plan_fields", "vehicle_fields"]

VEHICLE_TYPES = ("multirotor", "fixed_wing")
FINAL_ACTIONS = ("land", "rtl", "loiter")
MAX_PATH_SAMPLES = 1_000_000
REQUIRED = ("vehicle_id", "sysid", "waypoints", "times_s", "speeds_mps", "path", "path_times_s")
OPTIONAL = ("vehicle_type", "turn_radius_m", "takeoff_delay_s", "final_action", "acceptance_radius_m",
            "cost", "feasible", "notes", "altitude_frame")  # fmt: skip
ALTITUDE_FRAMES = ("relative", "amsl")


def plan_fields(d: Any) -> tuple[Origin, str, list[dict], dict, list]:
    """(origin, planner, vehicle rows, metrics, events) of a plan.json document, checked."""
    d = table(d, "plan")
    origin = checked_origin(d.get("origin"), "origin")
    planner = d.get("planner")
    if not isinstance(planner, str):
        raise InputError(f"planner must be a string, got {planner!r}")
    rows = items_of(d.get("vehicles"), "vehicles")
    if not rows:
        raise InputError("vehicles is empty; a plan needs at least one vehicle")
    metrics = table(d.get("metrics", {}), "metrics")
    events = items_of(d.get("events", []), "events")
    return origin, planner, rows, metrics, events


def vehicle_fields(d: Any) -> dict[str, Any]:
    """The VehiclePlan keyword arguments of one plan.json vehicle, every field checked."""
    d = table(d, "vehicle")
    unknown = sorted(set(d) - set(REQUIRED) - set(OPTIONAL))
    if unknown:
        raise InputError(f"unknown field {unknown[0]!r}")
    missing = [k for k in REQUIRED if k not in d]
    if missing:
        raise InputError(f"missing field {missing[0]!r}")
    out: dict[str, Any] = {"vehicle_id": name(d["vehicle_id"], "vehicle_id")}
    where = out["vehicle_id"]
    out["sysid"] = integer(d["sysid"], f"{where}: sysid", 0, fleet_id(MAX_NETWORK, 255))  # a fleet id
    out["waypoints"] = _points(d["waypoints"], f"{where}: waypoints", MAX_WAYPOINTS)
    out["path"] = _points(d["path"], f"{where}: path", MAX_PATH_SAMPLES)
    n, m = len(out["waypoints"]), len(out["path"])
    out["times_s"] = _times(d["times_s"], f"{where}: times_s", n)
    out["path_times_s"] = _times(d["path_times_s"], f"{where}: path_times_s", m)
    out["speeds_mps"] = _series(d["speeds_mps"], f"{where}: speeds_mps", n, 0.0, MAX_SPEED_MPS)
    vtype = d.get("vehicle_type", "multirotor")
    if vtype not in VEHICLE_TYPES:
        raise InputError(f"{where}: vehicle_type must be one of {VEHICLE_TYPES}, got {vtype!r}")
    action = d.get("final_action", "land")
    if action not in FINAL_ACTIONS:
        raise InputError(f"{where}: final_action must be one of {FINAL_ACTIONS}, got {action!r}")
    frame = d.get("altitude_frame", "relative")
    if frame not in ALTITUDE_FRAMES:
        raise InputError(f"{where}: altitude_frame must be one of {ALTITUDE_FRAMES}, got {frame!r}")
    out.update(vehicle_type=vtype, final_action=action, altitude_frame=frame)
    for key, default, hi in (
        ("turn_radius_m", 0.0, MAX_RADIUS_M),
        ("acceptance_radius_m", 2.0, MAX_RADIUS_M),
        ("takeoff_delay_s", 0.0, MAX_DURATION_S),
    ):
        out[key] = number(d.get(key, default), f"{where}: {key}", 0.0, hi)
    out["cost"] = table(d.get("cost", {}), f"{where}: cost")
    feasible = d.get("feasible", True)
    if not isinstance(feasible, bool):
        raise InputError(f"{where}: feasible must be true or false, got {feasible!r}")
    out["feasible"] = feasible
    out["notes"] = items_of(d.get("notes", []), f"{where}: notes", str)
    return out


def _numbers(value: Any, field: str) -> np.ndarray:
    """A flat list of real numbers (no bools, no strings) -> float array."""
    if not isinstance(value, list):
        raise InputError(f"{field} must be a list of numbers, got {type(value).__name__}")
    for i, v in enumerate(value):
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise InputError(f"{field}[{i}] must be a number, got {v!r}")
    try:
        arr = np.asarray(value, dtype=float)
    except OverflowError:
        raise InputError(f"{field}: a number is out of range") from None
    bad = np.flatnonzero(~np.isfinite(arr))
    if bad.size:
        raise InputError(f"{field}[{bad[0]}] must be finite, got {value[bad[0]]!r}")
    return arr


def _points(value: Any, field: str, max_len: int) -> np.ndarray:
    """[[x, y, z], ...] (1..max_len points) within the range and altitude limits -> (N, 3)."""
    if not isinstance(value, list) or not 1 <= len(value) <= max_len:
        raise InputError(f"{field} must be a list of 1..{max_len} [x, y, z] points")
    for i, p in enumerate(value):
        if not (isinstance(p, list) and len(p) == 3):
            raise InputError(f"{field}[{i}] must be [x, y, z] in metres, got {_short(p)}")
        if not all(_finite(c) for c in p):
            raise InputError(f"{field}[{i}] must be 3 finite numbers, got {_short(p)}")
    arr = np.asarray(value, dtype=float)
    far = np.flatnonzero(np.abs(arr[:, :2]).max(axis=1) > MAX_RANGE_M)
    if far.size:
        raise InputError(f"{field}[{far[0]}] = {value[far[0]]} is over {MAX_RANGE_M:g} m from the origin")
    alt = np.flatnonzero((arr[:, 2] < MIN_ALT_M) | (arr[:, 2] > MAX_ALT_M))
    if alt.size:
        raise InputError(
            f"{field}[{alt[0]}] altitude {value[alt[0]][2]!r} is outside [{MIN_ALT_M:g}, {MAX_ALT_M:g}] m"
        )
    return arr


def _finite(c: Any) -> bool:
    """A real number (not bool) that is finite as a float."""
    if isinstance(c, bool) or not isinstance(c, int | float):
        return False
    try:
        return math.isfinite(c)
    except OverflowError:  # an int too large for a float
        return False


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _series(value: Any, field: str, n: int, lo: float, hi: float) -> np.ndarray:
    """n numbers in [lo, hi]."""
    arr = _numbers(value, field)
    if len(arr) != n:
        raise InputError(f"{field} has {len(arr)} entries; it needs one per point ({n})")
    out = np.flatnonzero((arr < lo) | (arr > hi))
    if out.size:
        raise InputError(f"{field}[{out[0]}] = {value[out[0]]!r} is outside [{lo:g}, {hi:g}]")
    return arr


def _times(value: Any, field: str, n: int) -> np.ndarray:
    """n times in [0, MAX_DURATION_S] s that never decrease."""
    arr = _series(value, field, n, 0.0, MAX_DURATION_S)
    back = np.flatnonzero(np.diff(arr) < 0)
    if back.size:
        i = back[0] + 1
        raise InputError(f"{field}[{i}] = {value[i]!r} is earlier than the time before it")
    return arr
