"""GeoJSON (RFC 7946) site features: a FeatureCollection or one Feature, read with the stdlib.

Each Feature's ``properties`` carry the site keys of gcs_planner.model.sites.features; geometries are
Point, Polygon and MultiPolygon (each of its polygons becomes one feature, named ``name[k]``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from gcs_planner.core.validation import InputError, load_json, read_text
from gcs_planner.model.sites.features import Feature, feature

__all__ = ["read_geojson"]


def read_geojson(path: Path) -> list[Feature]:
    """The features of a GeoJSON file; errors name the file and the feature."""
    where = str(path)
    doc = load_json(read_text(path, "site file"), where)
    if not isinstance(doc, dict) or doc.get("type") not in ("FeatureCollection", "Feature"):
        got = doc.get("type") if isinstance(doc, dict) else type(doc).__name__
        raise InputError(f"{where}: not GeoJSON: type must be FeatureCollection or Feature, got {got!r}")
    rows = doc.get("features") if doc["type"] == "FeatureCollection" else [doc]
    if not isinstance(rows, list):
        raise InputError(f"{where}: features must be a list, got {type(rows).__name__}")
    out: list[Feature] = []
    for i, row in enumerate(rows):
        out += _features(row, f"{where}: features[{i}]")
    return out


def _features(row: Any, where: str) -> list[Feature]:
    if not isinstance(row, dict) or row.get("type") != "Feature":
        raise InputError(f"{where} must be a GeoJSON Feature object")
    props = row.get("properties") or {}
    geometry = row.get("geometry")
    if not isinstance(props, dict):
        raise InputError(f"{where}.properties must be an object, got {type(props).__name__}")
    if not isinstance(geometry, dict):
        raise InputError(f"{where}.geometry must be an object, got {geometry!r}")
    kind, coords = geometry.get("type"), geometry.get("coordinates")
    if kind != "MultiPolygon":
        return [feature(props, kind, coords, where)]
    if not isinstance(coords, list) or not coords:
        raise InputError(f"{where}.geometry.coordinates must be a non-empty list of polygons")
    name = props.get("name", where)
    return [
        feature({**props, "name": f"{name}[{k}]"}, "Polygon", polygon, f"{where}.coordinates[{k}]")
        for k, polygon in enumerate(coords)
    ]
