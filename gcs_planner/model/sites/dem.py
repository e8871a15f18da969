"""Digital elevation models on a WGS84 latitude/longitude grid: SRTM .hgt tiles and GeoTIFFs.

A :class:`Dem` holds heights [m AMSL] at grid nodes ``lat0 + r dlat``, ``lon0 + c dlon`` and
answers bilinearly between them (NaN outside the grid or next to a void). Readers:

- SRTM ``.hgt``: big-endian int16, n x n samples (n = 1201 for 3", 3601 for 1"; any n >= 2 is
  read), the file name (``N47E008.hgt``) gives the south-west corner of the 1 deg tile, row 0 is
  the north edge, samples sit on the tile's edges (node registration), -32768 is a void.
- GeoTIFF through ``tifffile`` (a 240 kB pure-Python wheel: rasterio's wheel carries GDAL and is
  36 MB): one band, georeferenced by ModelPixelScale + ModelTiepoint in geographic WGS84
  (EPSG:4326); PixelIsArea rasters are sampled at cell centres, PixelIsPoint at the nodes; the
  GDAL_NODATA value is a void. Other CRSs are refused with the gdalwarp line that converts them.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gcs_planner.core.validation import MAX_INPUT_BYTES, InputError

__all__ = ["Dem", "read_dem"]

HGT_VOID = -32768
GEO_MODEL, GEO_RASTER, GEO_CRS = 1024, 1025, 2048  # GeoKey ids: model type, raster type, geographic CRS
MODEL_GEOGRAPHIC, PIXEL_IS_POINT, WGS84 = 2, 2, 4326
_HGT_NAME = re.compile(r"^([NS])(\d{2})([EW])(\d{3})$", re.IGNORECASE)


@dataclass(frozen=True)
class Dem:
    """Heights [m AMSL] ``elevation[r, c]`` at (lat0 + r dlat, lon0 + c dlon) [deg]; NaN = void."""

    elevation: np.ndarray
    lat0: float
    lon0: float
    dlat: float
    dlon: float
    source: str

    def extent(self) -> tuple[float, float, float, float]:
        """(lat_min, lat_max, lon_min, lon_max) of the grid's nodes [deg]."""
        ny, nx = self.elevation.shape
        lats = (self.lat0, self.lat0 + (ny - 1) * self.dlat)
        lons = (self.lon0, self.lon0 + (nx - 1) * self.dlon)
        return min(lats), max(lats), min(lons), max(lons)

    def sample(self, lat_deg: np.ndarray, lon_deg: np.ndarray) -> np.ndarray:
        """Bilinear heights [m AMSL] at the points; NaN outside the grid or beside a void."""
        ny, nx = self.elevation.shape
        row = (np.asarray(lat_deg, dtype=float) - self.lat0) / self.dlat
        col = (np.asarray(lon_deg, dtype=float) - self.lon0) / self.dlon
        inside = (row >= 0) & (row <= ny - 1) & (col >= 0) & (col <= nx - 1)
        row, col = np.clip(row, 0, ny - 1), np.clip(col, 0, nx - 1)
        r0 = np.minimum(row.astype(int), ny - 2)
        c0 = np.minimum(col.astype(int), nx - 2)
        fr, fc = row - r0, col - c0
        g = self.elevation
        top = g[r0, c0] * (1 - fc) + g[r0, c0 + 1] * fc
        bottom = g[r0 + 1, c0] * (1 - fc) + g[r0 + 1, c0 + 1] * fc
        return np.where(inside, top * (1 - fr) + bottom * fr, np.nan)


def read_dem(path: Path, field: str) -> Dem:
    """The DEM in ``path`` (.hgt or .tif/.tiff); errors name ``field`` and the file."""
    where = f"{field} {str(path)!r}"
    if not path.is_file():
        raise InputError(f"{where}: no such file")
    if path.stat().st_size > MAX_INPUT_BYTES:
        raise InputError(f"{where}: larger than {MAX_INPUT_BYTES // 2**20} MiB")
    suffix = path.suffix.lower()
    if suffix == ".hgt":
        return _read_hgt(path, where)
    if suffix in (".tif", ".tiff"):
        return _read_geotiff(path, where)
    raise InputError(f"{where}: a DEM must be an SRTM .hgt or a GeoTIFF .tif, got {path.suffix!r}")


def _read_hgt(path: Path, where: str) -> Dem:
    match = _HGT_NAME.match(path.stem)
    if match is None:
        raise InputError(f"{where}: an .hgt file is named after its south-west corner, e.g. N47E008.hgt")
    ns, lat, ew, lon = match.groups()
    lat_sw = int(lat) * (1 if ns.upper() == "N" else -1)
    lon_sw = int(lon) * (1 if ew.upper() == "E" else -1)
    if not (-90 <= lat_sw < 90 and -180 <= lon_sw < 180):
        raise InputError(f"{where}: tile corner lat {lat_sw}, lon {lon_sw} is out of range")
    raw = path.read_bytes()
    n = int(round((len(raw) / 2) ** 0.5))
    if n < 2 or 2 * n * n != len(raw):
        raise InputError(f"{where}: {len(raw)} bytes is not an n x n grid of 16-bit samples")
    grid = np.frombuffer(raw, dtype=">i2").reshape(n, n).astype(float)
    grid[grid == HGT_VOID] = np.nan
    step = 1.0 / (n - 1)
    return Dem(grid, lat_sw + 1.0, float(lon_sw), -step, step, str(path))


def _read_geotiff(path: Path, where: str) -> Dem:
    import tifffile

    try:
        with tifffile.TiffFile(path) as tif:
            page = tif.pages.first
            tags = {t.code: t.value for t in page.tags.values()}
            grid = np.asarray(page.asarray(), dtype=float)
    except (tifffile.TiffFileError, ValueError, OSError, IndexError) as exc:
        raise InputError(f"{where}: not a readable TIFF ({exc})") from None
    if grid.ndim != 2 or min(grid.shape) < 2:
        raise InputError(f"{where}: a DEM needs one band of at least 2 x 2 samples, got shape {grid.shape}")
    if 34264 in tags:
        raise InputError(f"{where}: a rotated raster (ModelTransformation) is not read; warp it north-up")
    scale, tie = tags.get(33550), tags.get(33922)
    if scale is None or tie is None or len(tie) < 6:
        raise InputError(f"{where}: no GeoTIFF georeferencing (ModelPixelScale and ModelTiepoint)")
    keys = _geokeys(tags.get(34735, ()))
    if keys.get(GEO_MODEL) != MODEL_GEOGRAPHIC or keys.get(GEO_CRS, WGS84) != WGS84:
        raise InputError(
            f"{where}: the DEM must be in geographic WGS84 (EPSG:4326), got model type"
            f" {keys.get(GEO_MODEL)} / CRS {keys.get(GEO_CRS)}; convert it with gdalwarp -t_srs EPSG:4326"
        )
    nodata = tags.get(42113)
    if nodata is not None:
        try:
            grid[grid == float(str(nodata).strip("\x00 "))] = np.nan
        except ValueError:
            raise InputError(f"{where}: GDAL_NODATA {nodata!r} is not a number") from None
    grid[~np.isfinite(grid)] = np.nan
    sx, sy = float(scale[0]), float(scale[1])
    if not (sx > 0 and sy > 0):
        raise InputError(f"{where}: ModelPixelScale must be positive, got {tuple(scale[:2])}")
    half = 0.0 if keys.get(GEO_RASTER) == PIXEL_IS_POINT else 0.5
    i, j, x, y = (float(v) for v in (tie[0], tie[1], tie[3], tie[4]))
    return Dem(grid, y - (half - j) * sy, x + (half - i) * sx, -sy, sx, str(path))


def _geokeys(directory) -> dict[int, int]:
    """GeoKey id -> short value from a GeoKeyDirectory (entries stored in other tags are skipped)."""
    d = [int(v) for v in directory]
    out = {}
    for k in range(4, min(len(d), 4 + 4 * d[3] if len(d) >= 4 else 4), 4):
        key, location, _, value = d[k : k + 4]
        if location == 0:
            out[key] = value
    return out
