"""Writes the bundled site missions/site_valley/: a GeoTIFF DEM and a GeoJSON of its features.

The valley is made up but shaped like a real one (a valley floor at 488 m AMSL along a stream,
a 70 m hill north-east of the launch point, a ridge to the south, a gentle eastward rise) on a
1/3 arc-second grid (about 10 m, the resolution of national lidar DEMs resampled), as float32
with zlib compression. Features: the operating area, a school (no-fly at any height), a
substation (no-fly up to 40 m above the valley floor: it may be overflown), a helicopter
approach corridor (no-fly from 100 m above the valley floor up: it may be underflown) and a
60 m mast. Run: python benchmarks/make_site_valley.py
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import tifffile

from gcs_planner.core.geo import Origin, enu_to_geodetic, geodetic_to_enu

OUT = Path(__file__).resolve().parents[1] / "missions" / "site_valley"
ORIGIN = Origin(47.397742, 8.545594, 488.0)
STEP_DEG = 1.0 / 3 / 3600  # 1/3 arc-second
FLOOR_M = 488.0


def ground_amsl(east: np.ndarray, north: np.ndarray) -> np.ndarray:
    """The made-up valley's ground [m AMSL] at local (east, north) [m]."""
    hill = 70.0 * np.exp(-(((east - 620.0) / 170.0) ** 2) - ((north - 380.0) / 140.0) ** 2)
    ridge = 30.0 * np.exp(-(((north + 330.0) / 110.0) ** 2))
    stream = -6.0 * np.exp(-(((north - 60.0 - 0.05 * east) / 50.0) ** 2))
    return FLOOR_M + hill + ridge + stream + 0.008 * np.maximum(east, 0.0)


def write_dem(path: Path) -> None:
    """The GeoTIFF: PixelIsArea, EPSG:4326, north-up, GDAL_NODATA -9999."""
    (lat_s, lon_w, _), (lat_n, lon_e, _) = (
        enu_to_geodetic(-400.0, -600.0, 0.0, ORIGIN),
        enu_to_geodetic(1500.0, 900.0, 0.0, ORIGIN),
    )
    lon0 = np.floor(lon_w / STEP_DEG) * STEP_DEG
    lat_top = np.ceil(lat_n / STEP_DEG) * STEP_DEG
    nx = int(np.ceil((lon_e - lon0) / STEP_DEG))
    ny = int(np.ceil((lat_top - lat_s) / STEP_DEG))
    lon = lon0 + (np.arange(nx) + 0.5) * STEP_DEG
    lat = lat_top - (np.arange(ny) + 0.5) * STEP_DEG
    glon, glat = np.meshgrid(lon, lat)
    east, north, _ = geodetic_to_enu(glat, glon, 0.0, ORIGIN)
    heights = np.round(ground_amsl(east, north), 1).astype(np.float32)
    keys = [1, 1, 0, 4, 1024, 0, 1, 2, 1025, 0, 1, 1, 2048, 0, 1, 4326, 2054, 0, 1, 9102]
    tifffile.imwrite(
        path,
        heights,
        compression="zlib",
        extratags=[
            (33550, "d", 3, (STEP_DEG, STEP_DEG, 0.0), False),
            (33922, "d", 6, (0.0, 0.0, 0.0, lon0, lat_top, 0.0), False),
            (34735, "H", len(keys), keys, False),
            (42113, "s", 0, "-9999", False),
        ],
    )


def ring(points_enu: list[tuple[float, float]]) -> list[list[float]]:
    """Local (east, north) vertices -> a closed GeoJSON ring of [lon, lat]."""
    e, n = np.array(points_enu, dtype=float).T
    lat, lon, _ = enu_to_geodetic(e, n, 0.0, ORIGIN)
    out = [[round(float(a), 7), round(float(b), 7)] for a, b in zip(lon, lat, strict=True)]
    return out + out[:1]


def polygon(props: dict, points: list[tuple[float, float]]) -> dict:
    return {
        "type": "Feature",
        "properties": props,
        "geometry": {"type": "Polygon", "coordinates": [ring(points)]},
    }


def features() -> dict:
    mast_lat, mast_lon, _ = enu_to_geodetic(480.0, -120.0, 0.0, ORIGIN)
    return {
        "type": "FeatureCollection",
        "features": [
            polygon(
                {"kind": "area", "name": "valley operating area"},
                [(-120, -260), (500, -300), (1120, -200), (1160, 640), (560, 700), (-140, 560)],
            ),
            polygon(
                {"kind": "no_fly", "name": "school"},
                [(300, 40), (400, 20), (430, 110), (360, 170), (290, 130)],
            ),
            polygon(
                {"kind": "no_fly", "name": "substation", "ceiling_m": FLOOR_M + 40.0},
                [(760, -60), (860, -60), (860, 30), (760, 30)],
            ),
            polygon(
                {"kind": "no_fly", "name": "helicopter approach", "floor_m": FLOOR_M + 100.0},
                [(150, 380), (420, 380), (420, 520), (150, 520)],
            ),
            {
                "type": "Feature",
                "properties": {
                    "kind": "obstacle",
                    "name": "mast",
                    "radius_m": 8.0,
                    "height_m": 60.0,
                    "buffer_m": 5.0,
                },
                "geometry": {"type": "Point", "coordinates": [round(mast_lon, 7), round(mast_lat, 7)]},
            },
        ],
    }


def main() -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    write_dem(OUT / "valley_dem.tif")
    (OUT / "valley.geojson").write_text(json.dumps(features(), indent=1) + "\n")
    print(f"wrote {OUT}/valley_dem.tif ({(OUT / 'valley_dem.tif').stat().st_size} B) and valley.geojson")


if __name__ == "__main__":
    main()
