"""A gridded elevation model in local metres, shared by the planners' threat environment
(gcs_planner.planning.threat_env, ``[terrain] type = "grid"``) and sites (gcs_planner.model.sites, a DEM
resampled into the local frame).

Heights ``elevation_grid`` (ny, nx) with a GDAL-style geotransform ``(x0, dx, 0, y0, 0, dy)``: the
cell centre of ``elev[r, c]`` is at ``(x0 + (c + 0.5) dx, y0 + (r + 0.5) dy)``, dy usually
negative as in north-up rasters; bilinear between cell centres; outside the grid the edge value is
held (a DEM clipped to the mission area should still answer).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["GridTerrain"]


@dataclass(frozen=True)
class GridTerrain:
    """Gridded elevation model with a GDAL-style geotransform (see the module docstring)."""

    elevation_grid: np.ndarray
    geotransform: tuple[float, float, float, float, float, float]

    def __post_init__(self) -> None:
        grid = np.asarray(self.elevation_grid, dtype=float)
        if grid.ndim != 2 or min(grid.shape) < 2 or not np.all(np.isfinite(grid)):
            raise ValueError(
                f"GridTerrain: elevation must be a finite (ny, nx) array, ny, nx >= 2, got {grid.shape}"
            )
        gt = tuple(float(v) for v in self.geotransform)
        if len(gt) != 6 or gt[2] != 0.0 or gt[4] != 0.0 or gt[1] == 0.0 or gt[5] == 0.0:
            raise ValueError(
                f"GridTerrain: geotransform must be (x0, dx, 0, y0, 0, dy), dx, dy != 0, got {gt}"
            )
        object.__setattr__(self, "elevation_grid", grid)
        object.__setattr__(self, "geotransform", gt)

    def elevation(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        x0, dx, _, y0, _, dy = self.geotransform
        ny, nx = self.elevation_grid.shape
        col = np.clip((np.asarray(x, dtype=float) - x0) / dx - 0.5, 0.0, nx - 1.0)
        row = np.clip((np.asarray(y, dtype=float) - y0) / dy - 0.5, 0.0, ny - 1.0)
        c0 = np.minimum(col.astype(int), nx - 2)
        r0 = np.minimum(row.astype(int), ny - 2)
        fc, fr = col - c0, row - r0
        g = self.elevation_grid
        top = g[r0, c0] * (1 - fc) + g[r0, c0 + 1] * fc
        bottom = g[r0 + 1, c0] * (1 - fc) + g[r0 + 1, c0 + 1] * fc
        return top * (1 - fr) + bottom * fr

    def scaled(self, factor: float) -> GridTerrain:
        return GridTerrain(self.elevation_grid * factor, tuple(v * factor for v in self.geotransform))
