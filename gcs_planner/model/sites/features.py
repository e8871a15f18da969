"""A site's map features as read from GeoJSON or KML: the operating area, no-fly zones, obstacles.

Both readers produce :class:`Feature` rows through :func:`feature`, which checks every property
and coordinate. A feature's ``kind`` property says what it is:

- ``area``: a Polygon, the operating area (the uploaded inclusion fence; planners stay inside);
- ``no_fly``: a Polygon (or each Polygon of a MultiPolygon) that no path may enter, optionally
  only between ``floor_m`` and ``ceiling_m`` [m AMSL] (a zone with a ceiling may be overflown);
- ``obstacle``: a Point with ``radius_m`` or a Polygon footprint, with ``height_m`` [m above the
  ground at its place] and an optional ``buffer_m`` (the planners' soft keep-out band).

Coordinates are WGS84 longitude, latitude [deg] (a third value, an altitude, is ignored); a
polygon ring needs three distinct vertices, closed or not, and holes are kept.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from gcs_planner.core.validation import MAX_ALT_M, MAX_RADIUS_M, MIN_ALT_M, InputError, number

__all__ = ["KINDS", "Feature", "feature"]

KINDS = ("area", "no_fly", "obstacle")
PROPERTIES = {
    "area": ("kind", "name"),
    "no_fly": ("kind", "name", "floor_m", "ceiling_m"),
    "obstacle": ("kind", "name", "radius_m", "height_m", "buffer_m"),
}


@dataclass(frozen=True)
class Feature:
    """One checked feature: rings (exterior first, then holes) of (N, 2) lon, lat [deg] for a
    polygon, one (1, 2) ring for a point; floor / ceiling [m AMSL], height above ground [m]."""

    kind: str
    name: str
    rings: tuple[np.ndarray, ...]
    is_point: bool = False
    radius_m: float = 0.0
    height_m: float = math.inf
    buffer_m: float = 0.0
    floor_m: float = -math.inf
    ceiling_m: float = math.inf


def feature(props: dict[str, Any], geometry: str, coords: Any, where: str) -> Feature:
    """A Feature from its properties, geometry type ("Point" / "Polygon") and GeoJSON-style
    coordinates; InputError naming ``where`` and the bad value otherwise."""
    kind = props.get("kind")
    if kind not in KINDS:
        raise InputError(f"{where}.kind must be one of {KINDS}, got {kind!r}")
    unknown = sorted(k for k in props if k not in PROPERTIES[kind])
    if unknown:
        raise InputError(f"{where}: unknown property {unknown[0]!r} for a {kind} (known: {PROPERTIES[kind]})")
    name = props.get("name", where)
    if not isinstance(name, str) or not name.strip():
        raise InputError(f"{where}.name must be a non-empty string, got {name!r}")
    if geometry == "Point":
        if kind != "obstacle":
            raise InputError(f"{where}: a {kind} must be a Polygon, got a Point")
        if "radius_m" not in props:
            raise InputError(f"{where}: a Point obstacle needs radius_m")
        rings = (_position(coords, f"{where}.coordinates")[None, :],)
    elif geometry == "Polygon":
        if not isinstance(coords, list) or not coords:
            raise InputError(f"{where}.coordinates must be a list of rings, got {_short(coords)}")
        rings = tuple(_ring(r, f"{where}.coordinates[{k}]") for k, r in enumerate(coords))
    else:
        raise InputError(f"{where}: geometry type {geometry!r} is not read (Point, Polygon, MultiPolygon)")
    floor = number(props.get("floor_m", -math.inf), f"{where}.floor_m", finite=False)
    ceiling = number(props.get("ceiling_m", math.inf), f"{where}.ceiling_m", finite=False)
    for key, value in (("floor_m", floor), ("ceiling_m", ceiling)):
        if math.isfinite(value) and not MIN_ALT_M <= value <= MAX_ALT_M:
            raise InputError(f"{where}.{key} must be within [{MIN_ALT_M:g}, {MAX_ALT_M:g}] m, got {value!r}")
    if not floor < ceiling:
        raise InputError(f"{where}: floor_m {floor:g} must be below ceiling_m {ceiling:g}")
    return Feature(
        kind=kind,
        name=name,
        rings=rings,
        is_point=geometry == "Point",
        radius_m=number(props.get("radius_m", 0.0), f"{where}.radius_m", 0.0, MAX_RADIUS_M, lo_open=True)
        if geometry == "Point"
        else 0.0,
        height_m=number(props.get("height_m", math.inf), f"{where}.height_m", 0.0, MAX_ALT_M, lo_open=True)
        if kind == "obstacle" and "height_m" in props
        else math.inf,
        buffer_m=number(props.get("buffer_m", 0.0), f"{where}.buffer_m", 0.0, MAX_RADIUS_M),
        floor_m=floor,
        ceiling_m=ceiling,
    )


def _position(value: Any, field: str) -> np.ndarray:
    """[lon, lat] or [lon, lat, alt] -> (2,) lon, lat, checked against the WGS84 ranges."""
    if not (isinstance(value, list | tuple) and len(value) in (2, 3)):
        raise InputError(f"{field} must be [lon, lat] or [lon, lat, alt], got {_short(value)}")
    lon = number(value[0], f"{field} lon", -180.0, 180.0)
    lat = number(value[1], f"{field} lat", -90.0, 90.0)
    return np.array([lon, lat])


def _ring(value: Any, field: str) -> np.ndarray:
    """A polygon ring -> (N, 2) distinct lon, lat vertices (the closing repeat dropped), N >= 3."""
    if not isinstance(value, list | tuple):
        raise InputError(f"{field} must be a list of [lon, lat] positions, got {_short(value)}")
    pts = np.array([_position(p, f"{field}[{k}]") for k, p in enumerate(value)]).reshape(-1, 2)
    if len(pts) > 1 and np.array_equal(pts[0], pts[-1]):
        pts = pts[:-1]
    distinct = len(np.unique(pts, axis=0))
    if distinct < 3:
        raise InputError(f"{field}: a polygon ring needs at least 3 distinct vertices, got {distinct}")
    return pts


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."
