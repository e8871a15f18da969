"""What the plan checker proves on a site: every path stays in the area, out of every no-fly zone
and above the DEM's ground by the terrain clearance.

- Area: the path's ground track (a polyline) is covered by the area polygon (exact, shapely).
- No-fly zones: each straight path segment is intersected with the zone's polygon (exact in
  plan view); altitude is linear along a segment, so the altitudes at the ends of the pieces
  inside bound what the segment flies there, and any overlap with [floor, ceiling] is an entry
  (conservative when one segment enters the same polygon twice).
- Terrain: the path is sampled at a quarter of the terrain grid's spacing and each sample's
  height above the bilinear ground is compared with the clearance; samples on the vertical
  take-off / landing columns over the start and goal are exempt (they begin and end on the ground).
"""

from __future__ import annotations

import numpy as np
import shapely

from gcs_planner.model.sites.world import Site

__all__ = ["area_exit", "terrain_shortfall", "zone_entries"]


def area_exit(site: Site, path: np.ndarray) -> tuple[float, float] | None:
    """The first point [m] where the path's ground track leaves the area; None if it never does."""
    if site.area is None:
        return None
    xy = np.asarray(path, dtype=float)[:, :2]
    track = shapely.LineString(xy) if len(xy) > 1 else shapely.Point(xy[0])
    if site.area.covers(track):
        return None
    outside = shapely.get_coordinates(track.difference(site.area))
    return float(outside[0, 0]), float(outside[0, 1])


def zone_entries(site: Site, path: np.ndarray) -> list[str]:
    """Names of the no-fly zones the path enters (plan view and altitude band)."""
    p = np.asarray(path, dtype=float)
    if len(p) < 2 or not site.zones:
        return []
    a, b = p[:-1], p[1:]
    segments = shapely.linestrings(np.stack([a[:, :2], b[:, :2]], axis=1))
    ab = b[:, :2] - a[:, :2]
    length2 = np.maximum((ab**2).sum(axis=1), 1e-12)
    found = []
    for zone in site.zones:
        inside = shapely.intersection(segments, zone.polygon)
        coords, seg = shapely.get_coordinates(inside, return_index=True)
        if not len(seg):
            continue
        t = np.clip(((coords - a[seg, :2]) * ab[seg]).sum(axis=1) / length2[seg], 0.0, 1.0)
        z = a[seg, 2] + t * (b[seg, 2] - a[seg, 2])
        lo = np.full(len(p) - 1, np.inf)
        hi = np.full(len(p) - 1, -np.inf)
        np.minimum.at(lo, seg, z)
        np.maximum.at(hi, seg, z)
        if np.any((lo <= zone.ceiling_m) & (hi >= zone.floor_m)):
            found.append(zone.name)
    return found


def terrain_shortfall(site: Site, path: np.ndarray, exempt: np.ndarray) -> float:
    """The worst (clearance - height above ground) [m] over the path's non-exempt segments
    (``exempt`` (M-1,) marks the take-off / landing columns); <= 0 when clearance holds."""
    if site.terrain is None:
        return -np.inf
    p = np.asarray(path, dtype=float)
    keep = ~np.asarray(exempt, dtype=bool)
    if len(p) < 2 or not keep.any():
        return -np.inf
    spacing = 0.25 * abs(site.terrain.geotransform[1])
    a, b = p[:-1][keep], p[1:][keep]
    n = np.maximum(1, np.ceil(np.linalg.norm(b[:, :2] - a[:, :2], axis=1) / spacing).astype(int))
    seg = np.repeat(np.arange(len(a)), n + 1)
    frac = np.concatenate([np.arange(k + 1) / k for k in n])
    pts = a[seg] + frac[:, None] * (b[seg] - a[seg])
    height = pts[:, 2] - site.terrain.elevation(pts[:, 0], pts[:, 1])
    return float(site.clearance_m - height.min())
