"""Scenario files (missions/*.toml): origin, vehicles, obstacles and the planner to run.

A scenario is TOML. Common sections are parsed here into typed objects; the world tables (manned
traffic, terrain, the site) are checked here and stay in ``Scenario.raw`` for the planners that
read them. A planner's own tables and [[vehicles]] keys are the planner's (``Extensions``: the
planning layer says which, this module knows no planner). Every error names the file, the field
and the bad value.

    name = "open field"
    [origin]            lat_deg, lon_deg, alt_m (AMSL)
    [planner]           name = "priority_swarm", seed = 1, plus the planner's parameters (its Config)
    [[vehicles]]        id, sysid (MAVLink system id 1..255; 0 or absent = planning only, e.g. a
                        500-UAV study), network (0..63, default 0: the --connect that reaches it,
                        for fleets past one network's 254; Vehicle.sysid is then the fleet id
                        network x 256 + sysid), type ("multirotor" | "fixed_wing"), start = [x, y, z],
                        goal = [x, y, z], speed_mps, turn_radius_m, min_alt_m, max_alt_m,
                        separation_m, priority; as `fly` flies it (absent: the paper's model):
                        landing_mps (the landing's descent rate at the goal; absent: the vehicle
                        leaves the airspace on arrival), waits_airborne (true: it waits for its
                        take-off delay hovering at its start; absent: on the ground)
    [[obstacles.cylinders]]    x, y, radius_m, z_min_m (default 0), z_max_m, buffer_m
    [[obstacles.hemispheres]]  x, y, z (default 0), radius_m  (radar domes)
    [bounds]            x = [min, max], y = [...], z = [...]
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from gcs_planner.core.errors import UserError
from gcs_planner.core.fleet_ids import MAX_NETWORK, fleet_id
from gcs_planner.core.geo import Origin, geodetic_to_enu
from gcs_planner.core.validation import (
    MAX_ALT_M,
    MAX_DURATION_S,
    MAX_RADIUS_M,
    MAX_RANGE_M,
    MAX_SPEED_MPS,
    MIN_ALT_M,
    MIN_SPEED_MPS,
    MIN_TURN_RADIUS_M,
    InputError,
    integer,
    items_of,
    known_keys,
    load_toml,
    name,
    number,
    read_text,
    table,
    unique,
)
from gcs_planner.core.validation import (
    origin as checked_origin,
)

if TYPE_CHECKING:  # shapely is imported only when a scenario has a [site]
    from gcs_planner.model.sites.world import Site

__all__ = [
    "Cylinder", "Extensions", "Hemisphere", "Scenario", "ScenarioError", "Vehicle", "load_scenario",
    "parse_scenario",
]  # fmt: skip

VEHICLE_TYPES = ("multirotor", "fixed_wing")
MAX_SEED = 2**63 - 1


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
    landing_mps: float = 0.0  # descent rate of the landing at the goal (0: gone on arrival)
    waits_airborne: bool = False  # waits for its take-off delay hovering at its start

    @property
    def landing_stop_s(self) -> float:
        """Time [s] a landing vehicle hovers at its goal before it descends: its route ends at
        ``speed_mps`` and it stops there first, braking at no less than its turns' acceleration
        v^2 / R, which arrives v / (2a) = R / (2v) later than the constant-speed plan (0 without
        a landing or a turn radius)."""
        if self.landing_mps <= 0 or self.turn_radius_m <= 0 or self.speed_mps <= 0:
            return 0.0
        return self.turn_radius_m / (2.0 * self.speed_mps)


@dataclass(frozen=True)
class Cylinder:
    """Vertical cylinder obstacle; buffer_m is the extra keep-out band around radius_m."""

    x: float
    y: float
    radius_m: float
    z_max_m: float
    z_min_m: float = 0.0
    buffer_m: float = 0.0
    zone: str = ""  # the site no-fly zone this cylinder encloses (fenced and checked as its polygon)


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
    site: Site | None = None  # the exact area, no-fly zones and terrain of a [site] (gcs_planner.model.sites)

    @property
    def planner_name(self) -> str:
        return self.planner["name"]

    def vehicle(self, vehicle_id: str) -> Vehicle:
        for v in self.vehicles:
            if v.id == vehicle_id:
                return v
        raise KeyError(f"no vehicle {vehicle_id!r} in scenario {self.name!r}")


# a table's schema: (its keys, {key: the keys of its rows})
TableSchema = tuple[tuple[str, ...], dict[str, tuple[str, ...]]]
# the world tables, which any planner may read ([planner] is checked against its planner's config
# by gcs_planner.planning); [obstacles] and [[manned]] have their own readers below
WORLD_TABLES: dict[str, TableSchema] = {
    "terrain": (("type", "peaks", "file"), {"peaks": ("h_m", "x_m", "y_m", "sx_m", "sy_m")}),
    "site": (("features", "dem", "terrain_clearance_m", "dem_spacing_m", "margin_m"), {}),
}
SECTIONS = ("name", "origin", "planner", "vehicles", "obstacles", "bounds", "manned", *WORLD_TABLES)
MAX_MANNED = 10_000  # manned tracks in a scenario, and tracks in one mode's history
MAX_MANNED_SAMPLES = 100_000  # samples of one manned track (observed_s / dt_s, track rows)
MAX_START_BELOW_M = 100.0  # a start this far below the origin's ground is underground (a sign error)
MANNED_KEYS = ("id", "dt_s", "track", "position_m", "velocity_mps", "observed_s", "modes")
MANNED_MODE_KEYS = ("name", "history", "velocity_mps", "sigma_mps", "strength", "weight")
# [[vehicles]] keys every scenario may give (a planner may add its own: Extensions)
VEHICLE_KEYS = ("id", "sysid", "network", "type", "start", "goal", "speed_mps", "min_alt_m", "max_alt_m") + (
    "turn_radius_m",
    "separation_m",
    "priority",
    "landing_mps",
    "waits_airborne",
    "start_lla",
    "goal_lla",
)


@dataclass(frozen=True)
class Extensions:
    """What a planner adds to a scenario: its own tables and [[vehicles]] keys."""

    tables: dict[str, TableSchema] = field(default_factory=dict)
    vehicle_keys: tuple[str, ...] = ()


# planner name -> its Extensions (the planning layer's registry)
ExtensionsOf = Callable[[str], Extensions]


def load_scenario(path: str | Path, extensions_of: ExtensionsOf | None = None) -> Scenario:
    path = Path(path)
    data = load_toml(read_text(path, "scenario"), str(path))
    scenario = parse_scenario(data, str(path), extensions_of)
    scenario.path = path
    if "site" in data:  # the map files are read only with the scenario's folder known
        try:
            _add_site(scenario, path.parent)
        except InputError as exc:
            raise ScenarioError(f"{path}: {exc}") from None
    return scenario


def _add_site(scenario: Scenario, base_dir: Path) -> None:
    """The scenario's ``[site]`` read (gcs_planner.model.sites): its area's box as [bounds] x / y, its
    no-fly zones and obstacles as cylinders, the site itself as ``Scenario.site``."""
    from gcs_planner.model.sites.world import read_site  # shapely and the map readers: only for a site

    ends = [v.start[:2] for v in scenario.vehicles] + [v.goal[:2] for v in scenario.vehicles]
    raw = scenario.raw
    site = read_site(
        table(raw["site"], "[site]"), scenario.origin, base_dir, ends, scenario.bounds, "terrain" in raw
    )
    scenario.bounds = {**scenario.bounds, **site.bounds}
    scenario.cylinders = scenario.cylinders + [Cylinder(**c) for c in site.cylinders]
    scenario.site = site


def parse_scenario(
    data: dict[str, Any], where: str = "scenario", extensions_of: ExtensionsOf | None = None
) -> Scenario:
    """A scenario's TOML tables -> Scenario; every value is checked (gcs_planner.core.validation).
    ``extensions_of`` gives the tables and [[vehicles]] keys the scenario's planner adds (none: only
    the common ones are known)."""
    try:
        return _parse(table(data, "scenario"), where, extensions_of or (lambda name: Extensions()))
    except InputError as exc:
        raise ScenarioError(f"{where}: {exc}") from None


def _parse(data: dict[str, Any], where: str, extensions_of: ExtensionsOf) -> Scenario:
    if "acmpso" in data:
        raise InputError('the [acmpso] table\'s keys now belong in [planner] (name = "acmpso")')
    name = data["planner"].get("name") if isinstance(data.get("planner"), dict) else None
    extensions = extensions_of(name) if isinstance(name, str) else Extensions()
    known_keys(data, (*SECTIONS, *extensions.tables), "top level")
    origin = checked_origin(data.get("origin"), "[origin]")
    planner = dict(table(data.get("planner"), "[planner]"))
    if not isinstance(planner.get("name"), str):
        raise InputError(f"planner.name must be a string, got {planner.get('name')!r}")
    if "seed" in planner:
        planner["seed"] = integer(planner["seed"], "planner.seed", 0, MAX_SEED)
    rows = items_of(data.get("vehicles", []), "vehicles")
    if not rows:
        raise InputError("the scenario has no [[vehicles]]; at least one is needed")
    keys = (*VEHICLE_KEYS, *extensions.vehicle_keys)
    vehicles = [_vehicle(v, f"vehicles[{i}]", origin, keys) for i, v in enumerate(rows)]
    unique([v.id for v in vehicles], "vehicle id")
    unique([v.sysid for v in vehicles if v.sysid], "vehicle sysid")
    obstacles = known_keys(
        table(data.get("obstacles", {}), "[obstacles]"), ("cylinders", "hemispheres"), "[obstacles]"
    )
    cylinders = [
        _cylinder(c, f"obstacles.cylinders[{i}]")
        for i, c in enumerate(items_of(obstacles.get("cylinders", []), "obstacles.cylinders"))
    ]
    hemispheres = [
        _hemisphere(h, f"obstacles.hemispheres[{i}]")
        for i, h in enumerate(items_of(obstacles.get("hemispheres", []), "obstacles.hemispheres"))
    ]
    bounds = {}
    for axis, rng in table(data.get("bounds", {}), "[bounds]").items():
        if axis not in ("x", "y", "z") or not (isinstance(rng, list) and len(rng) == 2):
            raise InputError(f"bounds.{axis} must be x, y or z = [min, max], got {rng!r}")
        limit = MAX_RANGE_M if axis != "z" else MAX_ALT_M
        lo, hi = (number(r, f"bounds.{axis}", -limit, limit) for r in rng)
        if not lo < hi:
            raise InputError(f"bounds.{axis} must be [min, max] with min < max, got {rng!r}")
        bounds[axis] = (lo, hi)
    _check_world_tables(data, {**WORLD_TABLES, **extensions.tables})
    name = data.get("name", where)
    if not isinstance(name, str):
        raise InputError(f"name must be a string, got {name!r}")
    return Scenario(
        name=name,
        origin=origin,
        planner=planner,
        vehicles=vehicles,
        cylinders=cylinders,
        hemispheres=hemispheres,
        bounds=bounds,
        raw=data,
    )


def _check_world_tables(data: dict[str, Any], tables: dict[str, TableSchema]) -> None:
    """Unknown keys in the world and the planner's tables (their values are their readers' to check)."""
    for section, (keys, rows) in tables.items():
        if section not in data:
            continue
        known_keys(table(data[section], f"[{section}]"), keys, f"[{section}]")
        for key, row_keys in rows.items():
            for i, row in enumerate(items_of(data[section].get(key, []), f"{section}.{key}")):
                known_keys(row, row_keys, f"{section}.{key}[{i}]")
    terrain = data.get("terrain", {})
    for i, peak in enumerate(terrain.get("peaks", []) if isinstance(terrain.get("peaks"), list) else []):
        _peak(peak, f"terrain.peaks[{i}]")
    manned = items_of(data.get("manned", []), "manned")
    if len(manned) > MAX_MANNED:
        raise InputError(f"manned: {len(manned)} tracks, at most {MAX_MANNED}")
    for i, m in enumerate(manned):
        known_keys(m, MANNED_KEYS, f"manned[{i}]")
        _manned(m, f"manned[{i}]")
        modes = items_of(m.get("modes", []), f"manned[{i}].modes")
        for k, mode in enumerate(modes):
            known_keys(mode, MANNED_MODE_KEYS, f"manned[{i}].modes[{k}]")
            _mode(mode, f"manned[{i}].modes[{k}]")
        if modes and all(mode.get("weight", 1.0) == 0 for mode in modes):
            raise InputError(f"manned[{i}].modes: every weight is 0; give at least one mode a weight above 0")


def _peak(p: dict[str, Any], where: str) -> None:
    """A terrain peak: a finite height within the altitude limits, a place and widths in range."""
    for key in ("h_m", "x_m", "y_m", "sx_m", "sy_m"):
        if key not in p:
            continue
        if key == "h_m":
            number(p[key], f"{where}.h_m", MIN_ALT_M, MAX_ALT_M)
        elif key in ("x_m", "y_m"):
            number(p[key], f"{where}.{key}", -MAX_RANGE_M, MAX_RANGE_M)
        else:
            number(p[key], f"{where}.{key}", 0, MAX_RANGE_M, lo_open=True)


def _vector(value: Any, field: str, limit: float, lo: float | None = None) -> None:
    """[x, y, z]: three finite numbers within +-limit (or [lo, limit])."""
    if not (isinstance(value, list) and len(value) == 3):
        raise InputError(f"{field} must be [x, y, z], got {_short(value)}")
    for k, v in enumerate(value):
        number(v, f"{field}[{k}]", -limit if lo is None else lo, limit)


def _manned(m: dict[str, Any], where: str) -> None:
    """A manned track's numbers: the sample time, the observed state or track, finite and in range."""
    dt = number(m.get("dt_s", 1.0), f"{where}.dt_s", 0, 3600.0, lo_open=True)
    if "position_m" in m:
        _point(m["position_m"], f"{where}.position_m")
    if "velocity_mps" in m:
        _vector(m["velocity_mps"], f"{where}.velocity_mps", MAX_SPEED_MPS)
    observed = number(m.get("observed_s", 10.0), f"{where}.observed_s", 0, MAX_DURATION_S)
    if observed / dt > MAX_MANNED_SAMPLES:
        raise InputError(f"{where}: observed_s / dt_s is {observed / dt:.3g} samples, > {MAX_MANNED_SAMPLES}")
    if "track" in m:
        rows = items_of(m["track"], f"{where}.track", list)
        if not rows or len(rows) > MAX_MANNED_SAMPLES:
            raise InputError(f"{where}.track must hold 1..{MAX_MANNED_SAMPLES} rows, got {len(rows)}")
        for r, row in enumerate(rows):
            if len(row) != 4:
                raise InputError(f"{where}.track[{r}] must be [t_s, x, y, z], got {_short(row)}")
            number(row[0], f"{where}.track[{r}] t_s", -MAX_DURATION_S, MAX_DURATION_S)
            _point(row[1:], f"{where}.track[{r}]")


def _mode(mode: dict[str, Any], where: str) -> None:
    """A manned motion prior: velocity, sigma (> 0), strength (> 0) and weight (>= 0), finite."""
    if "velocity_mps" in mode:
        _vector(mode["velocity_mps"], f"{where}.velocity_mps", MAX_SPEED_MPS)
    if "sigma_mps" in mode:
        _vector(mode["sigma_mps"], f"{where}.sigma_mps", MAX_SPEED_MPS, lo=0.0)
        if any(v == 0 for v in mode["sigma_mps"]):
            raise InputError(f"{where}.sigma_mps must be > 0 in each axis, got {_short(mode['sigma_mps'])}")
    if "strength" in mode:
        number(mode["strength"], f"{where}.strength", 0, 1e6, lo_open=True)
    if "weight" in mode:
        number(mode["weight"], f"{where}.weight", 0, 1e6)
    if "history" in mode:
        tracks = items_of(mode["history"], f"{where}.history", list)
        if not tracks or len(tracks) > MAX_MANNED:
            raise InputError(f"{where}.history must hold 1..{MAX_MANNED} tracks, got {len(tracks)}")
        for t, track in enumerate(tracks):
            if not track or len(track) > MAX_MANNED_SAMPLES:
                raise InputError(f"{where}.history[{t}] must hold 1..{MAX_MANNED_SAMPLES} points")
            for k, point in enumerate(track):
                _point(point, f"{where}.history[{t}][{k}]")


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _vehicle(d: dict[str, Any], where: str, origin: Origin, keys: tuple[str, ...]) -> Vehicle:
    known_keys(d, keys, where)
    d = {**d, **_geodetic_ends(d, where, origin)}
    vtype = d.get("type", "multirotor")
    if vtype not in VEHICLE_TYPES:
        raise InputError(f"{where}.type must be one of {VEHICLE_TYPES}, got {vtype!r}")
    sysid = d.get("sysid", 0)
    if isinstance(sysid, bool) or not isinstance(sysid, int) or not 0 <= sysid <= 255:
        raise InputError(
            f"{where}.sysid must be an integer in 1..255 (0 or absent: planning only), got {sysid!r}"
        )
    if "id" not in d and sysid == 0:
        raise InputError(f"{where}: a vehicle needs an id or a sysid")
    network = integer(d.get("network", 0), f"{where}.network", 0, MAX_NETWORK)
    if network and not sysid:
        raise InputError(f"{where}.network is {network}, but the vehicle has no sysid to be reached by")
    vid = name(d.get("id", f"uav{sysid}"), f"{where}.id")
    min_alt = number(d.get("min_alt_m", 10.0), f"{where}.min_alt_m", MIN_ALT_M, MAX_ALT_M)
    max_alt = number(d.get("max_alt_m", 120.0), f"{where}.max_alt_m", MIN_ALT_M, MAX_ALT_M)
    if min_alt > max_alt:
        raise InputError(f"{where}: min_alt_m {min_alt:g} is above max_alt_m {max_alt:g}")
    start, goal = _start(d.get("start"), f"{where}.start"), _point(d.get("goal"), f"{where}.goal")
    speed = number(d.get("speed_mps", 10.0), f"{where}.speed_mps", MIN_SPEED_MPS, MAX_SPEED_MPS)
    landing = _zero_or_at_least(
        d.get("landing_mps", 0.0), f"{where}.landing_mps", MIN_SPEED_MPS, MAX_SPEED_MPS
    )
    _within_a_week(start, goal, speed, landing, where)
    return Vehicle(
        id=vid,
        sysid=fleet_id(network, sysid),
        type=vtype,
        start=start,
        goal=goal,
        speed_mps=speed,
        turn_radius_m=_zero_or_at_least(
            d.get("turn_radius_m", 20.0), f"{where}.turn_radius_m", MIN_TURN_RADIUS_M, MAX_RADIUS_M
        ),
        min_alt_m=min_alt,
        max_alt_m=max_alt,
        separation_m=number(d.get("separation_m", 5.0), f"{where}.separation_m", 0, MAX_RADIUS_M),
        priority=number(d.get("priority", 1.0), f"{where}.priority"),
        landing_mps=landing,
        waits_airborne=_flag(d.get("waits_airborne", False), f"{where}.waits_airborne"),
    )


def _zero_or_at_least(value: Any, field: str, least: float, most: float) -> float:
    """0 (none: no turn radius, no landing) or a number in [least, most]; InputError otherwise."""
    got = number(value, field, 0, most)
    if 0 < got < least:
        raise InputError(f"{field} must be 0 or at least {least:g}, got {got:g}")
    return got


def _within_a_week(
    start: tuple[float, float, float],
    goal: tuple[float, float, float],
    speed_mps: float,
    landing_mps: float,
    where: str,
) -> None:
    """The straight flight from start to goal, and the landing, take at most MAX_DURATION_S: a
    plan is sampled in time, and a slower one is no mission (it would fill the memory first)."""
    flight_s = math.dist(start, goal) / speed_mps
    if flight_s > MAX_DURATION_S:
        raise InputError(
            f"{where}.speed_mps {speed_mps:g} m/s takes {flight_s / 86_400:.3g} days from start to goal"
            f" (at most {MAX_DURATION_S / 86_400:g})"
        )
    if landing_mps and max(goal[2], 0.0) / landing_mps > MAX_DURATION_S:
        raise InputError(
            f"{where}.landing_mps {landing_mps:g} m/s takes over {MAX_DURATION_S / 86_400:g} days to land"
            f" from {goal[2]:g} m"
        )


def _geodetic_ends(d: dict[str, Any], where: str, origin: Origin) -> dict[str, list[float]]:
    """start / goal in local metres from start_lla / goal_lla = [lat_deg, lon_deg, alt_m AMSL]."""
    out = {}
    for end in ("start", "goal"):
        value = d.get(f"{end}_lla")
        if value is None:
            continue
        field = f"{where}.{end}_lla"
        if end in d:
            raise InputError(f"{where}: give {end} or {end}_lla, not both")
        if not (isinstance(value, list) and len(value) == 3):
            raise InputError(f"{field} must be [lat_deg, lon_deg, alt_m AMSL], got {_short(value)}")
        lat = number(value[0], f"{field} lat", -90.0, 90.0)
        lon = number(value[1], f"{field} lon", -180.0, 180.0)
        alt = number(value[2], f"{field} alt", MIN_ALT_M, MAX_ALT_M)
        out[end] = [float(v) for v in geodetic_to_enu(lat, lon, alt, origin)]
    return out


def _flag(value: Any, field: str) -> bool:
    if not isinstance(value, bool):
        raise InputError(f"{field} must be true or false, got {value!r}")
    return value


def _cylinder(c: dict[str, Any], where: str) -> Cylinder:
    known_keys(c, ("x", "y", "radius_m", "z_min_m", "z_max_m", "buffer_m"), where)
    z_min = number(c.get("z_min_m", 0.0), f"{where}.z_min_m", MIN_ALT_M, MAX_ALT_M)
    z_max = number(c.get("z_max_m", math.inf), f"{where}.z_max_m", z_min, finite=False)
    return Cylinder(
        x=number(c.get("x"), f"{where}.x", -MAX_RANGE_M, MAX_RANGE_M),
        y=number(c.get("y"), f"{where}.y", -MAX_RANGE_M, MAX_RANGE_M),
        radius_m=number(c.get("radius_m"), f"{where}.radius_m", 0, MAX_RADIUS_M, lo_open=True),
        z_max_m=z_max,
        z_min_m=z_min,
        buffer_m=number(c.get("buffer_m", 0.0), f"{where}.buffer_m", 0, MAX_RADIUS_M),
    )


def _hemisphere(h: dict[str, Any], where: str) -> Hemisphere:
    known_keys(h, ("x", "y", "radius_m", "z"), where)
    return Hemisphere(
        x=number(h.get("x"), f"{where}.x", -MAX_RANGE_M, MAX_RANGE_M),
        y=number(h.get("y"), f"{where}.y", -MAX_RANGE_M, MAX_RANGE_M),
        radius_m=number(h.get("radius_m"), f"{where}.radius_m", 0, MAX_RADIUS_M, lo_open=True),
        z=number(h.get("z", 0.0), f"{where}.z", MIN_ALT_M, MAX_ALT_M),
    )


def _start(value: Any, field: str) -> tuple[float, float, float]:
    """A start point: as _point, and not more than MAX_START_BELOW_M below the origin's ground."""
    x, y, z = _point(value, field)
    if z < -MAX_START_BELOW_M:
        raise InputError(f"{field} z = {z:g} m is over {MAX_START_BELOW_M:g} m below the origin: underground")
    return x, y, z


def _point(value: Any, field: str) -> tuple[float, float, float]:
    """[x, y, z] in local ENU metres within MAX_RANGE_M of the origin and the altitude limits."""
    if not (isinstance(value, list) and len(value) == 3):
        raise InputError(f"{field} must be [x, y, z] in metres, got {_short(value)}")
    x = number(value[0], f"{field} x", -MAX_RANGE_M, MAX_RANGE_M)
    y = number(value[1], f"{field} y", -MAX_RANGE_M, MAX_RANGE_M)
    return x, y, number(value[2], f"{field} z", MIN_ALT_M, MAX_ALT_M)
