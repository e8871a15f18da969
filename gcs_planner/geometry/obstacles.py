"""Static obstacles as arrays: vertical cylinders with buffers, domes, altitude bands; batched distances.

Distances are exact for straight segments, vectorised over any leading batch shape (e.g. P
particles x W-1 segments) and over all obstacles at once:

- Cylinder: the horizontal distance from the cylinder axis to the part of the segment whose
  altitude lies in [z_min, z_max] (the segment is clipped to the altitude band first, so a leg
  that passes over a tower is not penalised); inf when no part of the segment is in the band.
- Hemisphere (radar dome): the 3-D distance from the dome centre to the segment, compared with
  the radius (a sphere; the half below ground is never reached by a flight path).

The threat cost follows seed 000 eqs. 5-6 with the infinite term replaced by a large constant plus
the depth of the violation (so an infeasible particle still gets a direction to move):
``E = 0`` if ``d > R + S``, ``(R + S) - d`` inside the buffer, ``HARD + (R - d)`` inside ``R``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from gcs_planner.model.scenario import Cylinder, Hemisphere

__all__ = ["HARD_PENALTY", "Obstacles", "altitude_violation"]

HARD_PENALTY = 1e4  # stands in for the paper's "infinity"; larger than any feasible cost term


@dataclass(frozen=True)
class Obstacles:
    """All static obstacles of a scenario as arrays (Q cylinders, H domes)."""

    cx: np.ndarray
    cy: np.ndarray
    radius_m: np.ndarray
    buffer_m: np.ndarray
    z_min_m: np.ndarray
    z_max_m: np.ndarray
    dome_centre: np.ndarray  # (H, 3)
    dome_radius_m: np.ndarray  # (H,)

    @classmethod
    def from_scenario(
        cls, cylinders: Sequence[Cylinder], hemispheres: Sequence[Hemisphere] = (), inflate_m: float = 0.0
    ) -> Obstacles:
        """Arrays from scenario objects; ``inflate_m`` grows every radius (vehicle size, safety margin)."""
        cyl = list(cylinders)
        dome = list(hemispheres)
        return cls(
            cx=np.array([c.x for c in cyl], dtype=float),
            cy=np.array([c.y for c in cyl], dtype=float),
            radius_m=np.array([c.radius_m + inflate_m for c in cyl], dtype=float),
            buffer_m=np.array([c.buffer_m for c in cyl], dtype=float),
            z_min_m=np.array([c.z_min_m for c in cyl], dtype=float),
            z_max_m=np.array([c.z_max_m for c in cyl], dtype=float),
            dome_centre=np.array([[h.x, h.y, h.z] for h in dome], dtype=float).reshape(-1, 3),
            dome_radius_m=np.array([h.radius_m + inflate_m for h in dome], dtype=float),
        )

    def cylinder_distances(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Horizontal axis distance [m] (..., Q) of segments a -> b (..., 3) within each altitude band."""
        a = np.asarray(a, dtype=float)[..., None, :]
        b = np.asarray(b, dtype=float)[..., None, :]
        return _axis_distance(a, b - a, self.cx, self.cy, self.z_min_m, self.z_max_m)

    def cylinder_distances_pairs(self, a: np.ndarray, b: np.ndarray, j: np.ndarray) -> np.ndarray:
        """``cylinder_distances`` for chosen pairs only: segments a -> b (n, 3) against cylinders j (n,)."""
        return _axis_distance(a, b - a, self.cx[j], self.cy[j], self.z_min_m[j], self.z_max_m[j])

    def dome_distances(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """3-D distance [m] (..., H) from each dome centre to segments a -> b (..., 3)."""
        a = np.asarray(a, dtype=float)[..., None, :]
        d = np.asarray(b, dtype=float)[..., None, :] - a
        rel = self.dome_centre - a
        dd = np.sum(d * d, axis=-1)
        t = np.clip(np.sum(rel * d, axis=-1) / np.where(dd > 1e-18, dd, 1.0), 0.0, 1.0)
        return np.linalg.norm(a + t[..., None] * d - self.dome_centre, axis=-1)

    def threat(self, a: np.ndarray, b: np.ndarray, margin_m: float = 0.0) -> np.ndarray:
        """Seed-000 threat cost (eqs. 5-6) of segments a -> b summed over obstacles: shape (...)."""
        d = self.cylinder_distances(a, b)
        r = self.radius_m + margin_m
        rs = r + self.buffer_m
        cost = np.where(d > rs, 0.0, np.where(d > r, rs - d, HARD_PENALTY + (r - d)))
        total = cost.sum(axis=-1)
        if len(self.dome_radius_m):
            dd = self.dome_distances(a, b)
            rd = self.dome_radius_m + margin_m
            total = total + np.where(dd > rd, 0.0, HARD_PENALTY + (rd - dd)).sum(axis=-1)
        return total

    def clearance(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Smallest distance [m] (...) from segments a -> b to any obstacle surface (< 0 = collision).

        Buffers are not part of the surface: they are soft keep-out bands priced by ``threat``.
        """
        return self.clearances(a, b)[0]

    def clearances(self, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``clearance`` and the smallest distance [m] (...) to any cylinder's buffer edge (< 0 =
        inside a buffer), from one computation of the axis distances."""
        surface = np.full(np.shape(a)[:-1], np.inf)
        buffer = surface
        if len(self.radius_m):
            gap = self.cylinder_distances(a, b) - self.radius_m
            surface = gap.min(axis=-1)
            buffer = (gap - self.buffer_m).min(axis=-1)
        if len(self.dome_radius_m):
            surface = np.minimum(surface, (self.dome_distances(a, b) - self.dome_radius_m).min(axis=-1))
        return surface, buffer

    def contains(self, points: np.ndarray, margin_m: float = 0.0) -> np.ndarray:
        """True (...) where a point (..., 3) is within margin_m of an obstacle (buffers excluded)."""
        p = np.asarray(points, dtype=float)
        return self.clearance(p, p) < margin_m


def _axis_distance(a, d, cx, cy, z_min, z_max) -> np.ndarray:
    """Horizontal distance from axes (cx, cy) to the part of segments a -> a + d in [z_min, z_max];
    inf where no part is in the band. Every argument broadcasts against the others (..., 3) / (...)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        flat = np.abs(d[..., 2]) < 1e-12
        t1 = (z_min - a[..., 2]) / d[..., 2]
        t2 = (z_max - a[..., 2]) / d[..., 2]
        lo = np.where(flat, 0.0, np.maximum(0.0, np.minimum(t1, t2)))
        hi = np.where(flat, 1.0, np.minimum(1.0, np.maximum(t1, t2)))
        inside_flat = (a[..., 2] >= z_min) & (a[..., 2] <= z_max)
        empty = np.where(flat, ~inside_flat, lo > hi)
        dxy2 = d[..., 0] ** 2 + d[..., 1] ** 2
        t = ((cx - a[..., 0]) * d[..., 0] + (cy - a[..., 1]) * d[..., 1]) / dxy2
        t = np.where(dxy2 > 1e-18, t, 0.0)
    t = np.clip(t, lo, np.maximum(lo, hi))
    dist = np.hypot(a[..., 0] + t * d[..., 0] - cx, a[..., 1] + t * d[..., 1] - cy)
    return np.where(empty, np.inf, dist)


def altitude_violation(z_m: np.ndarray, min_alt_m: float, max_alt_m: float) -> np.ndarray:
    """How far [m] each altitude lies outside the band [min_alt_m, max_alt_m] (0 inside)."""
    z = np.asarray(z_m, dtype=float)
    return np.maximum(0.0, np.maximum(min_alt_m - z, z - max_alt_m))
