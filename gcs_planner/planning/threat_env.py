"""Threat environment for 3-D track planning: terrain, radar hemispheres, cylinder obstacles.

Used by the ACMPSO planner (seed 001) for its fitness and by the dense-resample validator that
checks a finished track. All lengths are in one unit (metres in scenarios; ``scaled`` converts
the whole environment, e.g. to km for the paper's fitness). Arrays are vectorised: point sets are
(..., 3) and evaluations return matching leading shapes.

Terrain sources behind one interface (``elevation(x, y)`` and ``scaled(factor)``):
- :class:`PeaksTerrain`: the paper's eq. 1, Z = sum_i h_i exp(-((x - x_oi)/x_si)^2 - ((y - y_oi)/y_si)^2);
- :class:`GridTerrain` (gcs_planner.model.terrain): a gridded elevation model, bilinear between cell
  centres (also what a ``[site]`` DEM becomes in local metres).

Scenario sections: radars are ``[[obstacles.hemispheres]]``, obstacles ``[[obstacles.cylinders]]``
(z_min_m..z_max_m, radius_m + buffer_m), terrain ``[terrain]`` with ``type = "peaks"`` and
``[[terrain.peaks]] h_m, x_m, y_m, sx_m, sy_m`` or ``type = "grid"``, ``file = "dem.npz"`` (keys
``elevation_m`` (ny, nx) and ``geotransform`` (6,), path relative to the scenario file); no
``[terrain]`` means flat ground at z = 0. A scenario's ``[site]`` DEM (gcs_planner.model.sites) is used
in place of ``[terrain]``.

Altitude repair (paper, sec. 2.1): a node lower than terrain + h_safe is lifted to exactly that
height; it is a repair of the track, not a penalty.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from gcs_planner.model.scenario import Scenario, ScenarioError
from gcs_planner.model.terrain import GridTerrain

__all__ = [
    "FlatTerrain",
    "GridTerrain",
    "PeaksTerrain",
    "Terrain",
    "ThreatEnv",
    "ValidationReport",
    "Violation",
    "resample_path",
    "terrain_from_config",
    "validate_path",
]


class Terrain(Protocol):
    def elevation(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Ground height at (x, y); same units as the inputs; broadcasts like numpy."""

    def scaled(self, factor: float) -> Terrain:
        """The same terrain with all lengths multiplied by ``factor``."""


@dataclass(frozen=True)
class PeaksTerrain:
    """Sum of Gaussian peaks (paper eq. 1); each array has one entry per peak.

    The exponential is evaluated in float32 (relative error < 1e-7: under 1 mm on a 10 km peak):
    it is the fitness's hot spot (docs/acmpso.md); everything else is float64.
    """

    h: np.ndarray
    x0: np.ndarray
    y0: np.ndarray
    sx: np.ndarray
    sy: np.ndarray

    def __post_init__(self) -> None:
        arrays = [
            np.atleast_1d(np.asarray(a, dtype=float)) for a in (self.h, self.x0, self.y0, self.sx, self.sy)
        ]
        if len({a.shape for a in arrays}) != 1 or arrays[0].ndim != 1:
            raise ValueError("PeaksTerrain: h, x0, y0, sx, sy must be 1-D arrays of equal length")
        if np.any(arrays[3] <= 0) or np.any(arrays[4] <= 0):
            raise ValueError(f"PeaksTerrain: slopes sx, sy must be > 0, got {arrays[3]} / {arrays[4]}")
        for name, a in zip(("h", "x0", "y0", "sx", "sy"), arrays, strict=True):
            object.__setattr__(self, name, a)

    def elevation(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        x, y = np.broadcast_arrays(np.asarray(x, dtype=float), np.asarray(y, dtype=float))
        z = np.zeros(x.shape)
        a, b = np.empty(x.shape), np.empty(x.shape)
        e = np.empty(x.shape, dtype=np.float32)
        for h, x0, y0, sx, sy in zip(self.h, self.x0, self.y0, self.sx, self.sy, strict=True):
            # loop over the few peaks with in-place ops: no (..., K) temporaries (fitness hot path)
            np.subtract(x, x0, out=a)
            a *= 1.0 / sx
            a *= a
            np.subtract(y, y0, out=b)
            b *= 1.0 / sy
            b *= b
            a += b
            np.negative(a, out=a)
            np.exp(a, out=e, casting="same_kind", dtype=np.float32)  # see class docstring
            np.multiply(e, h, out=a)
            z += a
        return z

    def scaled(self, factor: float) -> PeaksTerrain:
        return PeaksTerrain(*(a * factor for a in (self.h, self.x0, self.y0, self.sx, self.sy)))


@dataclass(frozen=True)
class FlatTerrain:
    """Ground at a constant height (the default when a scenario has no [terrain])."""

    height: float = 0.0

    def elevation(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return np.full(np.broadcast_shapes(np.shape(x), np.shape(y)), self.height)

    def scaled(self, factor: float) -> FlatTerrain:
        return FlatTerrain(self.height * factor)


@dataclass(frozen=True)
class ThreatEnv:
    """Terrain + radar hemispheres + vertical cylinder obstacles + safe height above terrain.

    radar_xyz (R, 3) centres and radar_r (R,) radii; cyl_xy (C, 2), cyl_r (C,) (buffer included),
    cyl_zmin/cyl_zmax (C,); h_safe: minimum height above terrain; lengths in one unit.
    """

    terrain: Terrain
    radar_xyz: np.ndarray = field(default_factory=lambda: np.empty((0, 3)))
    radar_r: np.ndarray = field(default_factory=lambda: np.empty(0))
    cyl_xy: np.ndarray = field(default_factory=lambda: np.empty((0, 2)))
    cyl_r: np.ndarray = field(default_factory=lambda: np.empty(0))
    cyl_zmin: np.ndarray = field(default_factory=lambda: np.empty(0))
    cyl_zmax: np.ndarray = field(default_factory=lambda: np.empty(0))
    h_safe: float = 0.0

    def __post_init__(self) -> None:
        for name, shape in (("radar_xyz", (-1, 3)), ("cyl_xy", (-1, 2))):
            object.__setattr__(self, name, np.asarray(getattr(self, name), dtype=float).reshape(shape))
        for name in ("radar_r", "cyl_r", "cyl_zmin", "cyl_zmax"):
            object.__setattr__(self, name, np.asarray(getattr(self, name), dtype=float).reshape(-1))
        if len(self.radar_r) != len(self.radar_xyz):
            raise ValueError(f"ThreatEnv: {len(self.radar_xyz)} radar centres but {len(self.radar_r)} radii")
        if not len(self.cyl_xy) == len(self.cyl_r) == len(self.cyl_zmin) == len(self.cyl_zmax):
            raise ValueError("ThreatEnv: cylinder arrays cyl_xy, cyl_r, cyl_zmin, cyl_zmax differ in length")

    @classmethod
    def from_scenario(cls, scenario: Scenario, h_safe_m: float) -> ThreatEnv:
        """Environment in metres from a scenario's [terrain] and [obstacles] sections."""
        base = scenario.path.parent if scenario.path is not None else Path(".")
        site = scenario.site
        if site is not None and site.terrain is not None:  # a [site] DEM, in local metres
            terrain = site.terrain
        else:
            terrain = terrain_from_config(scenario.raw.get("terrain"), base, scenario.name)
        hem, cyl = scenario.hemispheres, scenario.cylinders
        return cls(
            terrain=terrain,
            radar_xyz=np.array([[h.x, h.y, h.z] for h in hem]).reshape(-1, 3),
            radar_r=np.array([h.radius_m for h in hem]),
            cyl_xy=np.array([[c.x, c.y] for c in cyl]).reshape(-1, 2),
            cyl_r=np.array([c.radius_m + c.buffer_m for c in cyl]),
            cyl_zmin=np.array([c.z_min_m for c in cyl]),
            cyl_zmax=np.array([c.z_max_m for c in cyl]),
            h_safe=h_safe_m,
        )

    def scaled(self, factor: float) -> ThreatEnv:
        """All lengths multiplied by ``factor`` (1e-3 turns a metre environment into km)."""
        return replace(
            self,
            terrain=self.terrain.scaled(factor),
            radar_xyz=self.radar_xyz * factor,
            radar_r=self.radar_r * factor,
            cyl_xy=self.cyl_xy * factor,
            cyl_r=self.cyl_r * factor,
            cyl_zmin=self.cyl_zmin * factor,
            cyl_zmax=self.cyl_zmax * factor,
            h_safe=self.h_safe * factor,
        )

    def floor(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Lowest allowed altitude: terrain + h_safe."""
        return self.terrain.elevation(x, y) + self.h_safe

    def repair(self, points: np.ndarray) -> np.ndarray:
        """Copy of (..., 3) points with z lifted to at least terrain + h_safe."""
        out = np.array(points, dtype=float)
        out[..., 2] = np.maximum(out[..., 2], self.floor(out[..., 0], out[..., 1]))
        return out

    def push_out(self, points: np.ndarray, margin: float) -> np.ndarray:
        """Copy of (M, 3) points moved out of every dome (radially) and cylinder (horizontally)
        to ``margin`` beyond its surface, then lifted to terrain + h_safe + margin.

        Used to make a flown path clean; two passes settle points near two volumes, and whatever
        remains is left for the validator to report.
        """
        out = np.array(points, dtype=float)
        for _ in range(2):
            for c, r in zip(self.radar_xyz, self.radar_r, strict=True):
                rel = out - c
                d = np.linalg.norm(rel, axis=1)
                hit = (d < r + margin) & (rel[:, 2] >= 0) & (d > 0)
                out[hit] = c + rel[hit] * ((r + margin) / d[hit])[:, None]
            for c, r, z0, z1 in zip(self.cyl_xy, self.cyl_r, self.cyl_zmin, self.cyl_zmax, strict=True):
                rel = out[:, :2] - c
                d = np.linalg.norm(rel, axis=1)
                hit = (d < r + margin) & (out[:, 2] >= z0) & (out[:, 2] <= z1) & (d > 0)
                out[hit, :2] = c + rel[hit] * ((r + margin) / d[hit])[:, None]
            out[:, 2] = np.maximum(out[:, 2], self.floor(out[:, 0], out[:, 1]) + margin)
        return out

    def radar_depth(self, points: np.ndarray) -> np.ndarray:
        """(..., R): how far each point is inside each radar dome (<= 0 outside)."""
        d = np.linalg.norm(points[..., None, :] - self.radar_xyz, axis=-1)
        inside_half = points[..., None, 2] >= self.radar_xyz[:, 2]
        return np.where(inside_half, self.radar_r - d, -np.inf)

    def cylinder_depth(self, points: np.ndarray) -> np.ndarray:
        """(..., C): how far each point is inside each cylinder (<= 0 outside), radially or vertically."""
        d = np.linalg.norm(points[..., None, :2] - self.cyl_xy, axis=-1)
        z = points[..., None, 2]
        vertical = np.minimum(self.cyl_zmax - z, z - self.cyl_zmin)
        return np.minimum(self.cyl_r - d, vertical)


def terrain_from_config(cfg: dict[str, Any] | None, base_dir: Path, where: str) -> Terrain:
    """Terrain from a scenario's [terrain] table (see module docstring); None -> flat at 0."""
    if cfg is None:
        return FlatTerrain()
    kind = cfg.get("type")
    if kind == "peaks":
        peaks = cfg.get("peaks")
        if not isinstance(peaks, list) or not peaks:
            raise ScenarioError(f"{where}: terrain.peaks must be a non-empty list of tables, got {peaks!r}")
        keys = ("h_m", "x_m", "y_m", "sx_m", "sy_m")
        values = []
        for i, p in enumerate(peaks):
            row = []
            for k in keys:
                v = p.get(k) if isinstance(p, dict) else None
                if isinstance(v, bool) or not isinstance(v, int | float):
                    raise ScenarioError(f"{where}: terrain.peaks[{i}].{k} must be a number, got {v!r}")
                if k in ("sx_m", "sy_m") and not v > 0:
                    raise ScenarioError(f"{where}: terrain.peaks[{i}].{k} must be > 0, got {v!r}")
                row.append(float(v))
            values.append(row)
        return PeaksTerrain(*np.array(values).T)
    if kind == "grid":
        file = cfg.get("file")
        if not isinstance(file, str):
            raise ScenarioError(f"{where}: terrain.file must be a path to an .npz file, got {file!r}")
        path = base_dir / file
        try:
            with np.load(path) as data:
                return GridTerrain(data["elevation_m"], tuple(data["geotransform"]))
        except (OSError, KeyError, ValueError) as exc:
            raise ScenarioError(f"{where}: terrain.file {str(path)!r}: {exc}") from None
    raise ScenarioError(f"{where}: terrain.type must be 'peaks' or 'grid', got {kind!r}")


def resample_path(path: np.ndarray, spacing: float) -> np.ndarray:
    """Points along the polyline ``path`` (M, 3) no further apart than ``spacing``, vertices kept."""
    path = np.asarray(path, dtype=float)
    seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
    counts = np.maximum(1, np.ceil(seg / spacing).astype(int))
    frac = np.concatenate([np.arange(n) / n for n in counts])
    leg = np.repeat(np.arange(len(seg)), counts)
    pts = path[leg] + frac[:, None] * (path[leg + 1] - path[leg])
    return np.vstack([pts, path[-1:]])


@dataclass(frozen=True)
class Violation:
    """One contiguous run of dense samples inside a keep-out volume.

    kind: "radar", "obstacle" or "terrain" (below terrain + h_safe); index: radar / obstacle number
    (-1 for terrain); first/last: sample indices; depth: worst penetration (length unit of the path);
    where: the worst sample's position.
    """

    kind: str
    index: int
    first: int
    last: int
    depth: float
    where: tuple[float, float, float]


@dataclass
class ValidationReport:
    samples: int
    spacing: float
    violations: list[Violation]

    @property
    def ok(self) -> bool:
        return not self.violations

    def summary(self) -> dict[str, float]:
        """Count and worst depth per kind, for Plan.cost / notes."""
        out: dict[str, float] = {}
        for kind in ("radar", "obstacle", "terrain"):
            vs = [v for v in self.violations if v.kind == kind]
            out[f"{kind}_violations"] = float(len(vs))
            out[f"{kind}_worst_depth"] = max((v.depth for v in vs), default=0.0)
        return out


def validate_path(env: ThreatEnv, path: np.ndarray, spacing: float, tol: float = 1e-6) -> ValidationReport:
    """Check the polyline ``path`` on a dense resample (spacing <= ``spacing``) against ``env``.

    Violations are reported, never repaired: radar domes and cylinders must not be entered
    (depth > tol) and every sample must be at least h_safe - tol above the terrain.
    """
    pts = resample_path(path, spacing)
    depth_sets = [
        ("radar", env.radar_depth(pts)),
        ("obstacle", env.cylinder_depth(pts)),
        ("terrain", (env.floor(pts[:, 0], pts[:, 1]) - pts[:, 2])[:, None]),
    ]
    violations = []
    for kind, depth in depth_sets:
        for j in range(depth.shape[1]):
            inside = depth[:, j] > tol
            if not inside.any():
                continue
            edges = np.flatnonzero(np.diff(np.concatenate([[0], inside.astype(int), [0]])))
            for a, b in zip(edges[::2], edges[1::2], strict=True):
                k = a + int(np.argmax(depth[a:b, j]))
                index = -1 if kind == "terrain" else j
                violations.append(
                    Violation(kind, index, int(a), int(b - 1), float(depth[k, j]), tuple(pts[k]))
                )
    return ValidationReport(samples=len(pts), spacing=spacing, violations=violations)
