"""KML and KMZ site features, read with the standard library (ElementTree, zipfile).

A Placemark is one feature: its ``<name>``, and the site keys of gcs_planner.model.sites.features
(``kind``, ``floor_m``, ...) as ``<ExtendedData>`` ``<Data name="..."><value>`` or
``<SchemaData><SimpleData name="...">`` (what Google Earth and QGIS write). Geometries: Point,
Polygon (outerBoundaryIs / innerBoundaryIs LinearRings) and MultiGeometry of those; a
``<coordinates>`` list is ``lon,lat[,alt]`` tuples separated by whitespace. A KMZ is a zip
archive whose first ``.kml`` member (``doc.kml`` by convention) is read.

Why not fastkml: it pulls in pygeoif and arrow for what is a few dozen lines over ElementTree.
Expat >= 2.4.1 (Python's own) refuses entity-expansion bombs; member sizes are capped.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path
from typing import Any

from gcs_planner.core.validation import MAX_INPUT_BYTES, InputError, read_text
from gcs_planner.model.sites.features import Feature, feature

__all__ = ["read_kml"]


def read_kml(path: Path) -> list[Feature]:
    """The Placemarks of a .kml or .kmz file as features; errors name the file and the placemark."""
    where = str(path)
    text = _kmz_text(path) if path.suffix.lower() == ".kmz" else read_text(path, "site file")
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise InputError(f"{where}: not valid KML (XML): {exc}") from None
    if _local(root.tag) != "kml":
        raise InputError(f"{where}: not KML: the root element is <{_local(root.tag)}>, not <kml>")
    out: list[Feature] = []
    for i, mark in enumerate(root.iterfind(".//{*}Placemark")):
        out += _placemark(mark, f"{where}: Placemark[{i}]")
    return out


def _kmz_text(path: Path) -> str:
    where = str(path)
    try:
        with zipfile.ZipFile(path) as kmz:
            members = sorted(
                (m for m in kmz.infolist() if m.filename.lower().endswith(".kml")),
                key=lambda m: (m.filename != "doc.kml", m.filename),
            )
            if not members:
                raise InputError(f"{where}: the KMZ archive holds no .kml file")
            if members[0].file_size > MAX_INPUT_BYTES:
                raise InputError(
                    f"{where}: {members[0].filename} is larger than {MAX_INPUT_BYTES // 2**20} MiB"
                )
            data = kmz.read(members[0])
    except FileNotFoundError:
        raise InputError(f"site file {where!r}: no such file") from None
    except (zipfile.BadZipFile, OSError) as exc:
        raise InputError(f"{where}: not a KMZ (zip) archive: {exc}") from None
    try:
        return data.decode("utf-8").removeprefix("\ufeff")
    except UnicodeDecodeError as exc:
        raise InputError(f"{where}: {members[0].filename} is not UTF-8 (byte {exc.start})") from None


def _placemark(mark: ET.Element, where: str) -> list[Feature]:
    props: dict[str, Any] = {}
    name = mark.find("{*}name")
    if name is not None and (name.text or "").strip():
        props["name"] = name.text.strip()
    for data in mark.iterfind(".//{*}Data"):
        value = data.find("{*}value")
        props[data.get("name", "")] = _value(value.text if value is not None else "")
    for data in mark.iterfind(".//{*}SimpleData"):
        props[data.get("name", "")] = _value(data.text or "")
    geometries = [g for g in mark.iter() if _local(g.tag) in ("Point", "Polygon")]
    if not geometries:
        raise InputError(f"{where}: no Point or Polygon geometry")
    out = []
    for k, geom in enumerate(geometries):
        here = where if len(geometries) == 1 else f"{where}.geometry[{k}]"
        p = props if len(geometries) == 1 else {**props, "name": f"{props.get('name', where)}[{k}]"}
        if _local(geom.tag) == "Point":
            coords = _coordinates(geom, here)
            out.append(feature(p, "Point", coords[0] if len(coords) == 1 else coords, here))
        else:
            rings = [geom.find("{*}outerBoundaryIs/{*}LinearRing")]
            rings += geom.findall("{*}innerBoundaryIs/{*}LinearRing")
            if rings[0] is None:
                raise InputError(f"{here}: a Polygon needs an outerBoundaryIs LinearRing")
            out.append(feature(p, "Polygon", [_coordinates(r, here) for r in rings], here))
    return out


def _coordinates(element: ET.Element, where: str) -> list[list[float]]:
    """The element's <coordinates> as [[lon, lat(, alt)], ...]."""
    node = element.find("{*}coordinates")
    if node is None:
        raise InputError(f"{where}: no <coordinates>")
    out = []
    for token in (node.text or "").split():
        try:
            out.append([float(v) for v in token.split(",")])
        except ValueError:
            raise InputError(f"{where}: coordinate {token[:40]!r} is not lon,lat[,alt]") from None
    return out


def _value(text: str) -> Any:
    """ExtendedData text as a number where it is one (floor_m = "120"), else the stripped string."""
    text = (text or "").strip()
    try:
        return float(text)
    except ValueError:
        return text


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]
