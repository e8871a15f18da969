"""A site turned into the scenario's local world: ENU polygons, cylinders and a terrain grid.

``[site]`` in a scenario names the map files; :func:`read_site` reads them into what the planners
already understand (bounds, cylinders: gcs_planner.model.scenario adds them to the scenario) and the
exact geometry the fence and the plan checker use (``Scenario.site``):

- the area polygon -> ``[bounds]`` x / y (its bounding box) and ``Site.area``, the inclusion fence;
- each no-fly zone -> a cylinder around it (its minimum bounding circle grown by ``margin_m``,
  between floor - margin and ceiling + margin, tagged ``zone``) that every planner keeping out of
  cylinders avoids, and ``Site.zones``, the exact polygons fenced and checked;
- each obstacle -> a cylinder from the ground at its place to ground + ``height_m``;
- the DEM -> a GridTerrain in local metres (heights above the origin, the planners' z),
  resampled every ``dem_spacing_m`` over the site's box; every node must fall on the DEM.

Frames: lat/lon are WGS84; feature and DEM heights are AMSL; local z is metres above the origin,
as everywhere else (gcs_planner.core.geo).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import shapely

from gcs_planner.core.geo import Origin, enu_to_geodetic, geodetic_to_enu
from gcs_planner.core.validation import (
    MAX_ALT_M,
    MAX_RADIUS_M,
    MIN_ALT_M,
    InputError,
    items_of,
    number,
)
from gcs_planner.model.sites.dem import Dem, read_dem
from gcs_planner.model.sites.features import Feature
from gcs_planner.model.sites.geojson import read_geojson
from gcs_planner.model.sites.kml import read_kml
from gcs_planner.model.terrain import GridTerrain

__all__ = ["NoFlyZone", "Site", "read_site"]

READERS = {".geojson": read_geojson, ".json": read_geojson, ".kml": read_kml, ".kmz": read_kml}
MAX_GRID_NODES = 4_000_000  # local terrain grid nodes (2000 x 2000)


@dataclass(frozen=True)
class NoFlyZone:
    """A polygon (ENU [m]) closed between floor_m and ceiling_m [m above the origin]."""

    name: str
    polygon: shapely.Polygon
    floor_m: float = -math.inf
    ceiling_m: float = math.inf


@dataclass(frozen=True)
class Site:
    """The exact site geometry in local metres: the area, the no-fly zones, the terrain, and the
    clearance every path keeps above the terrain; ``margin_m`` is the planners' extra room."""

    area: shapely.Polygon | None
    zones: tuple[NoFlyZone, ...]
    terrain: GridTerrain | None
    clearance_m: float
    margin_m: float
    bounds: dict[str, tuple[float, float]] = field(default_factory=dict)  # x / y: the area's box
    cylinders: tuple[dict[str, Any], ...] = ()  # scenario Cylinder fields: zones and obstacles
    inner_area: shapely.Polygon | None = None  # the area less the margin (prepared): planners' room

    def ground(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Ground height [m above the origin] at (x, y); 0 without a DEM."""
        if self.terrain is None:
            return np.zeros(np.broadcast_shapes(np.shape(x), np.shape(y)))
        return self.terrain.elevation(x, y)

    def violations(self, points: np.ndarray) -> np.ndarray:
        """Per point (..., 3) [m]: how far it is below terrain + clearance + margin, or 1.0 when
        it is outside the area shrunk by the margin (0: fine). The planners' cost term."""
        pts = np.asarray(points, dtype=float)
        depth = np.zeros(pts.shape[:-1])
        if self.terrain is not None:
            floor = self.terrain.elevation(pts[..., 0], pts[..., 1]) + self.clearance_m + self.margin_m
            depth = np.maximum(depth, floor - pts[..., 2])
        if self.inner_area is not None:
            outside = ~shapely.contains_xy(self.inner_area, pts[..., 0], pts[..., 1])
            depth = np.where(outside, np.maximum(depth, 1.0), depth)
        return depth


def read_site(
    cfg: dict[str, Any],
    origin: Origin,
    base_dir: Path,
    ends: list[tuple[float, float]],
    bounds: dict[str, tuple[float, float]],
    has_terrain: bool,
) -> Site:
    """The ``[site]`` table ``cfg`` read into local metres (module docstring). ``ends``: the
    vehicles' start and goal (x, y) [m]; ``bounds``: the scenario's [bounds]; ``has_terrain``:
    whether it has a [terrain] table. InputError on bad input."""
    files = items_of(cfg.get("features", []), "site.features", str)
    clearance = number(cfg.get("terrain_clearance_m", 20.0), "site.terrain_clearance_m", 0.0, MAX_RADIUS_M)
    spacing = number(cfg.get("dem_spacing_m", 10.0), "site.dem_spacing_m", 1.0, 1000.0)
    margin = number(cfg.get("margin_m", 5.0), "site.margin_m", 0.0, MAX_RADIUS_M)
    if "dem" in cfg and not isinstance(cfg["dem"], str):
        raise InputError(f"site.dem must be a path to a .hgt or GeoTIFF file, got {cfg['dem']!r}")
    features: list[Feature] = []
    for k, file in enumerate(files):
        path = base_dir / file
        reader = READERS.get(path.suffix.lower())
        if reader is None:
            raise InputError(f"site.features[{k}] {file!r}: read are .geojson, .json, .kml and .kmz files")
        features += reader(path)
    polygons = [(f, _polygon(f, origin)) for f in features if not f.is_point]
    areas = [p for f, p in polygons if f.kind == "area"]
    if len(areas) > 1:
        raise InputError(f"site.features: {len(areas)} features of kind 'area'; a site has at most one")
    area = areas[0] if areas else None
    box = dict(bounds)
    if area is not None:
        if "x" in bounds or "y" in bounds:
            raise InputError("[bounds] x / y and a site area both bound the world; give one of them")
        x0, y0, x1, y1 = area.bounds
        box.update(x=(x0, x1), y=(y0, y1))
    terrain = None
    if "dem" in cfg:
        if has_terrain:
            raise InputError("[terrain] and site.dem both give the ground; give one of them")
        dem = read_dem(base_dir / cfg["dem"], "site.dem")
        terrain = _local_terrain(dem, origin, _site_box(ends, features, box, origin), spacing)
    inner = None
    if area is not None:
        inner = area.buffer(-margin)
        shapely.prepare(inner)
    site = Site(
        area, (), terrain, clearance, margin, {k: v for k, v in box.items() if k in "xy"}, inner_area=inner
    )
    zones, cylinders = [], []
    for f, poly in polygons:
        if f.kind == "no_fly":
            zone = NoFlyZone(f.name, poly, f.floor_m - origin.alt_m, f.ceiling_m - origin.alt_m)
            zones.append(zone)
            cylinders.append(_zone_cylinder(zone, margin))
        elif f.kind == "obstacle":
            cylinders.append(_obstacle_cylinder(f, poly, site))
    for f in features:
        if f.is_point:
            east, north, _ = geodetic_to_enu(f.rings[0][0, 1], f.rings[0][0, 0], 0.0, origin)
            cylinders.append(_obstacle_cylinder(f, shapely.Point(east, north).buffer(f.radius_m, 64), site))
    return replace(site, zones=tuple(zones), cylinders=tuple(cylinders))


def _polygon(f: Feature, origin: Origin) -> shapely.Polygon:
    """The feature's rings projected to ENU [m], checked to be a valid polygon."""
    rings = []
    for ring in f.rings:
        east, north, _ = geodetic_to_enu(ring[:, 1], ring[:, 0], 0.0, origin)
        rings.append(np.column_stack([east, north]))
    poly = shapely.Polygon(rings[0], rings[1:])
    if not poly.is_valid:
        raise InputError(f"site feature {f.name!r} is not a valid polygon: {shapely.is_valid_reason(poly)}")
    return shapely.orient_polygons(poly)


def _circle(poly: shapely.Geometry) -> tuple[float, float, float]:
    """(x, y, r): a circle holding the whole geometry (its minimum bounding circle, made sure)."""
    centre = shapely.minimum_bounding_circle(poly).centroid
    pts = shapely.get_coordinates(poly)
    r = float(np.hypot(pts[:, 0] - centre.x, pts[:, 1] - centre.y).max())
    return centre.x, centre.y, r * (1 + 1e-9) + 1e-6


def _zone_cylinder(zone: NoFlyZone, margin: float) -> dict[str, Any]:
    x, y, r = _circle(zone.polygon)
    return dict(
        x=x,
        y=y,
        radius_m=r + margin,
        z_min_m=zone.floor_m - margin if math.isfinite(zone.floor_m) else MIN_ALT_M,
        z_max_m=zone.ceiling_m + margin,
        zone=zone.name,
    )


def _obstacle_cylinder(f: Feature, footprint: shapely.Geometry, site: Site) -> dict[str, Any]:
    """A cylinder around the footprint from the lowest ground under it to the highest + height."""
    x, y, r = _circle(footprint)
    pts = np.vstack([shapely.get_coordinates(footprint), [[x, y]]])
    ground = site.ground(pts[:, 0], pts[:, 1])
    return dict(
        x=x,
        y=y,
        radius_m=r,
        z_min_m=float(ground.min()),
        z_max_m=float(ground.max()) + f.height_m,
        buffer_m=f.buffer_m,
        zone="",
    )


def _site_box(
    ends: list[tuple[float, float]], features: list[Feature], bounds: dict, origin: Origin
) -> tuple[float, ...]:
    """(x0, x1, y0, y1) [m]: the bounds, else the box of every vehicle end and feature, padded 50 m."""
    if "x" in bounds and "y" in bounds:
        return (*bounds["x"], *bounds["y"])
    pts = [np.array(e, dtype=float) for e in ends]
    for f in features:
        for ring in f.rings:
            east, north, _ = geodetic_to_enu(ring[:, 1], ring[:, 0], 0.0, origin)
            pts += list(np.column_stack([east, north]))
    xy = np.array(pts)
    lo, hi = xy.min(axis=0) - 50.0, xy.max(axis=0) + 50.0
    return lo[0], hi[0], lo[1], hi[1]


def _local_terrain(dem: Dem, origin: Origin, box: tuple[float, ...], spacing: float) -> GridTerrain:
    """The DEM resampled onto a north-up local grid over ``box`` (+ one node each side)."""
    x0, x1, y0, y1 = box
    xs = np.arange(x0 - spacing, x1 + 2 * spacing, spacing)
    ys = np.arange(y1 + spacing, y0 - 2 * spacing, -spacing)
    if len(xs) * len(ys) > MAX_GRID_NODES:
        raise InputError(
            f"site.dem_spacing_m {spacing:g} makes a {len(ys)} x {len(xs)} terrain grid; at most"
            f" {MAX_GRID_NODES} nodes: raise the spacing"
        )
    gx, gy = np.meshgrid(xs, ys)
    lat, lon, _ = enu_to_geodetic(gx, gy, 0.0, origin)
    heights = dem.sample(lat, lon)
    if np.isnan(heights).any():
        lat_min, lat_max, lon_min, lon_max = dem.extent()
        bad = np.isnan(heights)
        raise InputError(
            f"site.dem {dem.source!r} does not cover the site (or has voids there): it needs lat"
            f" {lat[bad].min():.5f}..{lat[bad].max():.5f}, lon {lon[bad].min():.5f}..{lon[bad].max():.5f};"
            f" the DEM covers lat {lat_min:.5f}..{lat_max:.5f}, lon {lon_min:.5f}..{lon_max:.5f}"
        )
    local = heights - origin.alt_m
    if not (np.all(local >= MIN_ALT_M) and np.all(local <= MAX_ALT_M)):
        raise InputError(f"site.dem {dem.source!r}: heights outside [{MIN_ALT_M:g}, {MAX_ALT_M:g}] m")
    return GridTerrain(local, (xs[0] - spacing / 2, spacing, 0.0, ys[0] + spacing / 2, 0.0, -spacing))
