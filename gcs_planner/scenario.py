"""Scenario files (missions/*.toml): origin, vehicles, obstacles and the planner to run.

A scenario is TOML. Common sections are parsed here into typed objects; planner-specific
sections (targets, manned traffic, terrain peaks, ...) stay in ``Scenario.raw`` for the planner
that reads them. Every error names the file, the field and the bad value.

    name = "open field"
    [origin]            lat_deg, lon_deg, alt_m (AMSL)
    [planner]           name = "priority_swarm", seed = 1, plus planner parameters
    [[vehicles]]        id, sysid (MAVLink system id 1..255; 0 or absent = planning only, e.g. a
                        500-UAV study), type ("multirotor" | "fixed_wing"), start = [x, y, z],
                        goal = [x, y, z], speed_mps, turn_radius_m, min_alt_m, max_alt_m,
                        separation_m, priority
    [[obstacles.cylinders]]    x, y, radius_m, z_min_m (default 0), z_max_m, buffer_m
    [[obstacles.hemispheres]]  x, y, z (default 0), radius_m  (radar domes)
    [bounds]            x = [min, max], y = [...], z = [...]
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gcs_planner.errors import UserError
from gcs_planner.geo import Origin

__all__ = ["Cylinder", "Hemisphere", "Scenario", "ScenarioError", "Vehicle", "load_scenario"]

VEHICLE_TYPES = ("multirotor", "fixed_wing")


class ScenarioError(UserError, ValueError):
    """A scenario file is invalid; the message names the field and the value."""


@dataclass(frozen=True)
class Vehicle:
    id: str
    sysid: int
    type: str
    start: tuple[float, float, float]
    goal: tuple[float, float, float]
    speed_mps: float = 10.0
    turn_radius_m: float = 20.0
    min_alt_m: float = 10.0
    max_alt_m: float = 120.0
    separation_m: float = 5.0
    priority: float = 1.0


@dataclass(frozen=True)
class Cylinder:
    """Vertical cylinder obstacle; buffer_m is the extra keep-out band around radius_m."""

    x: float
    y: float
    radius_m: float
    z_max_m: float
    z_min_m: float = 0.0
    buffer_m: float = 0.0


@dataclass(frozen=True)
class Hemisphere:
    """Radar dome: a hemisphere of radius_m centred at (x, y, z)."""

    x: float
    y: float
    radius_m: float
    z: float = 0.0


@dataclass
class Scenario:
    name: str
    origin: Origin
    planner: dict[str, Any]
    vehicles: list[Vehicle]
    cylinders: list[Cylinder] = field(default_factory=list)
    hemispheres: list[Hemisphere] = field(default_factory=list)
    bounds: dict[str, tuple[float, float]] = field(default_factory=dict)
    raw: dict[str, Any] = field(default_factory=dict)
    path: Path | None = None

    @property
    def planner_name(self) -> str:
        return self.planner["name"]

    def vehicle(self, vehicle_id: str) -> Vehicle:
        for v in self.vehicles:
            if v.id == vehicle_id:
                return v
        raise KeyError(f"no vehicle {vehicle_id!r} in scenario {self.name!r}")


def load_scenario(path: str | Path) -> Scenario:
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise ScenarioError(f"{path}: no such scenario file") from None
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{path}: not valid TOML: {exc}") from None
    scenario = parse_scenario(data, where=str(path))
    scenario.path = path
    return scenario


def parse_scenario(data: dict[str, Any], where: str = "scenario") -> Scenario:
    origin_d = _table(data, "origin", where)
    try:
        origin = Origin(
            lat_deg=_number(origin_d, "lat_deg", f"{where}: origin"),
            lon_deg=_number(origin_d, "lon_deg", f"{where}: origin"),
            alt_m=_number(origin_d, "alt_m", f"{where}: origin", default=0.0),
        )
    except ValueError as exc:
        raise ScenarioError(f"{where}: {exc}") from None
    planner = dict(_table(data, "planner", where))
    if not isinstance(planner.get("name"), str):
        raise ScenarioError(f"{where}: planner.name must be a string, got {planner.get('name')!r}")
    vehicles = [_vehicle(v, f"{where}: vehicles[{i}]") for i, v in enumerate(data.get("vehicles", []))]
    _unique([v.id for v in vehicles], "id", where)
    _unique([v.sysid for v in vehicles if v.sysid], "sysid", where)
    obstacles = data.get("obstacles", {})
    cylinders = [
        Cylinder(
            x=_number(c, "x", f"{where}: obstacles.cylinders[{i}]"),
            y=_number(c, "y", f"{where}: obstacles.cylinders[{i}]"),
            radius_m=_number(c, "radius_m", f"{where}: obstacles.cylinders[{i}]", positive=True),
            z_max_m=_number(c, "z_max_m", f"{where}: obstacles.cylinders[{i}]", default=math.inf),
            z_min_m=_number(c, "z_min_m", f"{where}: obstacles.cylinders[{i}]", default=0.0),
            buffer_m=_number(c, "buffer_m", f"{where}: obstacles.cylinders[{i}]", default=0.0),
        )
        for i, c in enumerate(obstacles.get("cylinders", []))
    ]
    hemispheres = [
        Hemisphere(
            x=_number(h, "x", f"{where}: obstacles.hemispheres[{i}]"),
            y=_number(h, "y", f"{where}: obstacles.hemispheres[{i}]"),
            radius_m=_number(h, "radius_m", f"{where}: obstacles.hemispheres[{i}]", positive=True),
            z=_number(h, "z", f"{where}: obstacles.hemispheres[{i}]", default=0.0),
        )
        for i, h in enumerate(obstacles.get("hemispheres", []))
    ]
    bounds = {}
    for axis, rng in data.get("bounds", {}).items():
        if not (isinstance(rng, list) and len(rng) == 2 and rng[0] < rng[1]):
            raise ScenarioError(f"{where}: bounds.{axis} must be [min, max] with min < max, got {rng!r}")
        bounds[axis] = (float(rng[0]), float(rng[1]))
    return Scenario(
        name=str(data.get("name", where)),
        origin=origin,
        planner=planner,
        vehicles=vehicles,
        cylinders=cylinders,
        hemispheres=hemispheres,
        bounds=bounds,
        raw=data,
    )


def _vehicle(d: dict[str, Any], where: str) -> Vehicle:
    vtype = d.get("type", "multirotor")
    if vtype not in VEHICLE_TYPES:
        raise ScenarioError(f"{where}: type must be one of {VEHICLE_TYPES}, got {vtype!r}")
    sysid = d.get("sysid", 0)
    if not isinstance(sysid, int) or not 0 <= sysid <= 255:
        raise ScenarioError(
            f"{where}: sysid must be an integer in 1..255 (0 or absent: planning only), got {sysid!r}"
        )
    if "id" not in d and sysid == 0:
        raise ScenarioError(f"{where}: a vehicle needs an id or a sysid")
    return Vehicle(
        id=str(d.get("id", f"uav{sysid}")),
        sysid=sysid,
        type=vtype,
        start=_point(d, "start", where),
        goal=_point(d, "goal", where),
        speed_mps=_number(d, "speed_mps", where, default=10.0, positive=True),
        turn_radius_m=_number(d, "turn_radius_m", where, default=20.0),
        min_alt_m=_number(d, "min_alt_m", where, default=10.0),
        max_alt_m=_number(d, "max_alt_m", where, default=120.0),
        separation_m=_number(d, "separation_m", where, default=5.0),
        priority=_number(d, "priority", where, default=1.0),
    )


def _table(data: dict[str, Any], key: str, where: str) -> dict[str, Any]:
    value = data.get(key)
    if not isinstance(value, dict):
        raise ScenarioError(f"{where}: missing [{key}] table")
    return value


def _number(
    d: dict[str, Any], key: str, where: str, default: float | None = None, positive: bool = False
) -> float:
    value = d.get(key, default)
    if value is None:
        raise ScenarioError(f"{where}: missing {key}")
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ScenarioError(f"{where}: {key} must be a number, got {value!r}")
    value = float(value)
    if math.isnan(value) or (positive and not value > 0):
        raise ScenarioError(f"{where}: {key} must be {'> 0' if positive else 'a number'}, got {value!r}")
    return value


def _point(d: dict[str, Any], key: str, where: str) -> tuple[float, float, float]:
    value = d.get(key)
    if not (isinstance(value, list) and len(value) == 3):
        raise ScenarioError(f"{where}: {key} must be [x, y, z] in metres, got {value!r}")
    arr = np.asarray(value, dtype=float)
    if not np.all(np.isfinite(arr)):
        raise ScenarioError(f"{where}: {key} must be finite, got {value!r}")
    return tuple(float(v) for v in arr)


def _unique(values: list, name: str, where: str) -> None:
    seen = set()
    for v in values:
        if v in seen:
            raise ScenarioError(f"{where}: vehicles have duplicate {name} {v!r}")
        seen.add(v)
