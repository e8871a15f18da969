"""WGS84 geodetic <-> local ENU (east, north, up) about an origin, with pyproj.

Everything inside the planners is local metres; geodetic coordinates appear only at the MAVLink
and logging edges.

Choice of frame: east/north are an azimuthal equidistant projection of the WGS84 ellipsoid
centred on the origin (distances and bearings from the origin are true; the scale error is
below 5e-5 within 100 km), and up is altitude above the origin. Unlike a true topocentric
frame, up does not tilt away from the local vertical with distance, so a planner's ``z`` is the
altitude an autopilot flies, at any range. The round trip is exact to well under 1 mm.

Altitude datums:
- ``Origin.alt_m`` is the origin's altitude above mean sea level (AMSL), as autopilots report
  home. ENU up is metres above that origin: exactly the "relative to home" altitude of MAVLink
  frame GLOBAL_RELATIVE_ALT_INT used for missions. Geodetic altitudes here are AMSL.
- Telemetry logs state their datum per field (see gcs_planner.telemetry).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from pyproj import Transformer

__all__ = ["Origin", "enu_to_geodetic", "geodetic_to_enu", "wrap_pi"]


@dataclass(frozen=True)
class Origin:
    """Local frame origin: latitude and longitude [deg, WGS84], altitude [m AMSL]."""

    lat_deg: float
    lon_deg: float
    alt_m: float = 0.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.lat_deg) and -90.0 <= self.lat_deg <= 90.0):
            raise ValueError(f"origin lat_deg must be in [-90, 90], got {self.lat_deg!r}")
        if not (np.isfinite(self.lon_deg) and -180.0 <= self.lon_deg <= 180.0):
            raise ValueError(f"origin lon_deg must be in [-180, 180], got {self.lon_deg!r}")
        if not np.isfinite(self.alt_m):
            raise ValueError(f"origin alt_m must be finite, got {self.alt_m!r}")


@lru_cache(maxsize=64)
def _projection(origin: Origin) -> Transformer:
    local = f"+proj=aeqd +lat_0={origin.lat_deg!r} +lon_0={origin.lon_deg!r} +ellps=WGS84 +units=m"
    return Transformer.from_crs("EPSG:4326", local, always_xy=True)


def geodetic_to_enu(lat_deg, lon_deg, alt_m, origin: Origin):
    """Geodetic [deg, deg, m AMSL] -> local ENU [m] about ``origin``; scalars or arrays."""
    lat, lon, alt = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (lat_deg, lon_deg, alt_m)))
    e, n = _projection(origin).transform(lon, lat)
    return _like(e, lat_deg), _like(n, lat_deg), _like(alt - origin.alt_m, lat_deg)


def enu_to_geodetic(east_m, north_m, up_m, origin: Origin):
    """Local ENU [m] about ``origin`` -> geodetic [deg, deg, m AMSL]; scalars or arrays."""
    e, n, u = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (east_m, north_m, up_m)))
    lon, lat = _projection(origin).transform(e, n, direction="INVERSE")
    return _like(lat, east_m), _like(lon, east_m), _like(u + origin.alt_m, east_m)


def _like(values, template):
    """Return a float for scalar input, an ndarray otherwise."""
    arr = np.asarray(values, dtype=float)
    return float(arr) if np.ndim(template) == 0 and arr.ndim == 0 else arr


def wrap_pi(angle_rad):
    """Angles [rad] wrapped into [-pi, pi) (headings, turn angles), elementwise."""
    return (np.asarray(angle_rad) + np.pi) % (2.0 * np.pi) - np.pi
