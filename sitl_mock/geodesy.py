"""The mock world's geodesy: WGS84 geodetic <-> local ENU (east, north, up) about a home, with pyproj.

The frame is the one a GCS compares ArduPilot / PX4 SITL worlds against: east/north are the WGS84
azimuthal equidistant projection centred on the home (distance and azimuth from the home are the
geodesic's), and up is altitude above the home (altitudes AMSL). The mock keeps its own copy
rather than import the client's (gcs_planner.core.geo): a simulated autopilot must not share code with
the GCS it tests. That the two agree is checked by a test (tests/test_geodesy_crosscheck.py, to
1 mm over 100 km at any latitude), not assumed.

Any home object with ``lat_deg``, ``lon_deg`` [deg, WGS84] and ``alt_m`` [m AMSL] attributes does:
the mock's own ``Home``, or the origin a GCS passes to its vehicle source.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Protocol

import numpy as np
from pyproj import Transformer

__all__ = ["Home", "HomeLike", "to_enu", "to_geodetic", "wrap_pi"]


class HomeLike(Protocol):
    lat_deg: float
    lon_deg: float
    alt_m: float


@dataclass(frozen=True)
class Home:
    """Where a simulated vehicle stands (or a fleet's frame centre): latitude, longitude [deg,
    WGS84], altitude [m AMSL]."""

    lat_deg: float
    lon_deg: float
    alt_m: float = 0.0

    def __post_init__(self) -> None:
        checks = (
            ("lat_deg", self.lat_deg, -90.0, 90.0),
            ("lon_deg", self.lon_deg, -180.0, 180.0),
            ("alt_m", self.alt_m, -math.inf, math.inf),
        )
        for name, value, lo, hi in checks:
            try:
                ok = math.isfinite(value) and lo <= value <= hi
            except TypeError:
                ok = False
            if not ok:
                span = "be finite" if math.isinf(lo) else f"be in [{lo:g}, {hi:g}]"
                raise ValueError(f"home {name} must {span}, got {value!r}")


@lru_cache(maxsize=128)
def _aeqd(lat_deg: float, lon_deg: float) -> Transformer:
    """(lon, lat) [deg] <-> (east, north) [m]: the azimuthal equidistant projection about a point,
    keyed on its coordinates (not on the home object, so any object with them shares the cache)."""
    pipeline = (
        "+proj=pipeline +step +proj=unitconvert +xy_in=deg +xy_out=rad"
        f" +step +proj=aeqd +lat_0={lat_deg!r} +lon_0={lon_deg!r} +ellps=WGS84"
    )
    return Transformer.from_pipeline(pipeline)


def _projection(home: HomeLike) -> Transformer:
    return _aeqd(float(home.lat_deg), float(home.lon_deg))


def to_enu(lat_deg, lon_deg, alt_m, home: HomeLike):
    """Geodetic [deg, deg, m AMSL] -> ENU [m] about ``home``; floats for scalars, else arrays."""
    lat, lon, alt = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (lat_deg, lon_deg, alt_m)))
    east, north = _projection(home).transform(lon, lat)
    return _shaped(lat_deg, east, north, alt - float(home.alt_m))


def to_geodetic(east_m, north_m, up_m, home: HomeLike):
    """ENU [m] about ``home`` -> geodetic [deg, deg, m AMSL]; floats for scalars, else arrays."""
    east, north, up = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (east_m, north_m, up_m)))
    lon, lat = _projection(home).transform(east, north, direction="INVERSE")
    return _shaped(east_m, lat, lon, up + float(home.alt_m))


def _shaped(first_input, *values):
    """The values as floats when the (first) input was a scalar, as ndarrays otherwise."""
    arrays = [np.asarray(v, dtype=float) for v in values]
    if np.ndim(first_input) == 0 and all(a.ndim == 0 for a in arrays):
        return tuple(float(a) for a in arrays)
    return tuple(arrays)


def wrap_pi(angle_rad):
    """Angles [rad] wrapped into [-pi, pi), elementwise."""
    return (np.asarray(angle_rad) + np.pi) % (2.0 * np.pi) - np.pi
