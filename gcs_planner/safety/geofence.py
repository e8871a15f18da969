"""The geofence a vehicle gets: what its own plan keeps out of, so that a fenced vehicle flying its
plan never breaches.

A MAVLink fence is 2-D (inclusion / exclusion polygons and circles; the altitude limit is a
parameter: ``ceiling_m``, the scenario's top bound above the vehicle's home, which upload sets as
the autopilot's fence altitude parameter), so an obstacle with a top cannot be fenced above it.
A planner may fly over a tower (the demo's uav1 passes a 60 m tower at 64.8 m, 20 m from its
axis): fenced for every vehicle at its footprint, that vehicle breached and returned home. Each
vehicle's fence therefore holds the scenario's bounds and an exclusion circle for each obstacle
whose footprint its path (route and land approach) stays out of; the obstacles it overflies are
left out of its fence, said by ``overflown``, and kept clear by the plan's own 3-D check
(safety/separation.py). ``breaches``
is the check that the fence and the plan agree: empty for a fence built here, and what export /
upload refuse on for a fence built otherwise.

On a scenario with a ``[site]`` (gcs_planner.model.sites) the inclusion polygon is the site's area and
each no-fly zone is an exclusion polygon (its exact outline, not the planners' circle round it);
a zone with a floor or ceiling that a vehicle's path passes under or over is left out of that
vehicle's fence, as an overflown tower is.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from gcs_planner.core.errors import UserError
from gcs_planner.model.plan import VehiclePlan, land_point
from gcs_planner.model.scenario import Scenario

__all__ = [
    "Exclusion",
    "ExclusionPolygon",
    "Geofence",
    "breaches",
    "check_fence",
    "overflown",
    "vehicle_geofence",
]


@dataclass(frozen=True)
class Exclusion:
    """A circle the vehicle must stay out of (ENU [m]); ``name`` says which obstacle it is."""

    x: float
    y: float
    radius_m: float
    name: str


@dataclass(frozen=True)
class ExclusionPolygon:
    """A polygon the vehicle must stay out of: (N, 2) ENU [m] vertices, counter-clockwise."""

    vertices: np.ndarray
    name: str


@dataclass(frozen=True)
class Geofence:
    """An inclusion polygon ((N, 2) ENU [m] vertices, counter-clockwise; None: none), exclusion
    circles and polygons, and the ceiling [m above the vehicle's home, at ``home_z_m`` above the
    origin] (None: none)."""

    inclusion: np.ndarray | None
    exclusions: list[Exclusion] = field(default_factory=list)
    exclusion_polygons: list[ExclusionPolygon] = field(default_factory=list)
    ceiling_m: float | None = None
    home_z_m: float = 0.0


def _obstacles(scenario: Scenario) -> list[Exclusion]:
    """Every obstacle's footprint: a cylinder with its buffer, a radar dome's base circle (a site's
    no-fly zones are fenced as their polygons, not as their cylinders)."""
    out = [
        Exclusion(c.x, c.y, c.radius_m + c.buffer_m, f"cylinder {k}")
        for k, c in enumerate(scenario.cylinders)
        if not c.zone
    ]
    return out + [Exclusion(h.x, h.y, h.radius_m, f"dome {k}") for k, h in enumerate(scenario.hemispheres)]


def flown_outline(vp: VehiclePlan) -> np.ndarray:
    """The ground track (N, 2) a vehicle flying its plan covers: its route, then its land point."""
    return np.vstack([vp.path[:, :2], land_point(vp)[None, :2]])


def _segment_distances(points: np.ndarray, x: float, y: float) -> float:
    """Smallest distance [m] from (x, y) to the polyline ``points``."""
    a, b = points[:-1], points[1:]
    if not len(a):
        return float(np.hypot(*(points[0] - (x, y))))
    ab = b - a
    t = np.clip(((np.array([x, y]) - a) * ab).sum(axis=1) / np.maximum((ab**2).sum(axis=1), 1e-12), 0.0, 1.0)
    return float(np.hypot(*(a + t[:, None] * ab - (x, y)).T).min())


def vehicle_geofence(scenario: Scenario, vp: VehiclePlan | None = None) -> Geofence:
    """The scenario's bounds and obstacles; for a vehicle (``vp``), only the obstacles its flown
    outline keeps out of (module docstring)."""
    bounds, site = scenario.bounds, scenario.site
    inclusion = None
    if site is not None and site.area is not None:
        inclusion = _ring(site.area)
    elif "x" in bounds and "y" in bounds:
        (x0, x1), (y0, y1) = bounds["x"], bounds["y"]
        inclusion = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])  # counter-clockwise
    circles = _obstacles(scenario)
    polygons = _zones(scenario)
    home_z = _home_z(scenario, vp) if vp is not None else 0.0
    ceiling = bounds["z"][1] - home_z if "z" in bounds else None
    if vp is not None:
        outline = flown_outline(vp)
        circles = [c for c in circles if _segment_distances(outline, c.x, c.y) > c.radius_m]
        polygons = [z for z in polygons if not _crosses(outline, z.vertices)]
    return Geofence(inclusion, circles, polygons, ceiling, home_z)


def _home_z(scenario: Scenario, vp: VehiclePlan) -> float:
    """The vehicle's home altitude [m above the origin]: the ground at its start (the origin's
    ground off a site)."""
    if scenario.site is None:
        return 0.0
    x, y = vp.path[0, :2]
    return float(scenario.site.ground(np.array([x]), np.array([y]))[0])


def _zones(scenario: Scenario) -> list[ExclusionPolygon]:
    """A site's no-fly zones as exclusion polygons (their outer rings)."""
    if scenario.site is None:
        return []
    return [ExclusionPolygon(_ring(z.polygon), f"no-fly zone {z.name!r}") for z in scenario.site.zones]


def _ring(polygon) -> np.ndarray:
    """A shapely polygon's outer ring, counter-clockwise, without the closing repeat."""
    import shapely

    return shapely.get_coordinates(shapely.orient_polygons(polygon).exterior)[:-1]


def _crosses(outline: np.ndarray, vertices: np.ndarray) -> bool:
    """Whether the ground track ``outline`` touches the polygon."""
    import shapely

    track = shapely.LineString(outline) if len(outline) > 1 else shapely.Point(outline[0])
    return bool(shapely.intersects(track, shapely.Polygon(vertices)))


def overflown(scenario: Scenario, vp: VehiclePlan) -> list[str]:
    """The obstacles and no-fly zones whose footprint the vehicle's plan passes over or under
    (left out of its fence)."""
    fence = vehicle_geofence(scenario, vp)
    kept = {c.name for c in fence.exclusions} | {z.name for z in fence.exclusion_polygons}
    every = [c.name for c in _obstacles(scenario)] + [z.name for z in _zones(scenario)]
    return [name for name in every if name not in kept]


def breaches(fence: Geofence, vp: VehiclePlan) -> list[str]:
    """Where the vehicle's flown outline leaves the fence's inclusion rectangle or enters one of
    its exclusion circles, one phrase each; empty when the plan keeps to the fence."""
    outline = flown_outline(vp)
    found = []
    if fence.inclusion is not None:
        import shapely

        track = shapely.LineString(outline) if len(outline) > 1 else shapely.Point(outline[0])
        out = track.difference(shapely.Polygon(fence.inclusion))
        if not out.is_empty:
            x, y = shapely.get_coordinates(out)[0]
            found.append(f"leaves the inclusion fence at ({x:.0f}, {y:.0f}) m")
    for c in fence.exclusions:
        d = _segment_distances(outline, c.x, c.y)
        if d <= c.radius_m:
            found.append(
                f"enters the exclusion circle of {c.name} ({d:.1f} m from its centre, r {c.radius_m:g} m)"
            )
    found += [
        f"enters the exclusion polygon of {z.name}"
        for z in fence.exclusion_polygons
        if _crosses(outline, z.vertices)
    ]
    if fence.ceiling_m is not None and (top := float(vp.path[:, 2].max()) - fence.home_z_m) > fence.ceiling_m:
        found.append(f"climbs to {top:.1f} m above home, over the fence ceiling {fence.ceiling_m:.1f} m")
    return found


def check_fence(scenario: Scenario, vp: VehiclePlan) -> None:
    """Refuse (UserError, one line) a plan that would breach its own fence: a path out of the
    scenario's bounds (its exclusions are built from the path, so they always agree)."""
    found = breaches(vehicle_geofence(scenario, vp), vp)
    if found:
        raise UserError(f"{vp.vehicle_id} (sysid {vp.sysid}) {found[0]}: a fenced vehicle would stop there;"
                        " widen the scenario's [bounds] or re-plan")  # fmt: skip
