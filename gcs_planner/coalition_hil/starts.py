"""Where a connected plane (real or SITL) starts, so that its take-off ends where its first mission begins.

A plane takes off in ArduPlane's TAKEOFF mode, climbing on its launch heading, and its first
mission is a straight lead-in (missions.first_mission). Its home is therefore on that line, one
climb run before the lead-in start, facing along it: SITL takes it as ``--home lat,lon,alt,hdg``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from gcs_planner.geo import Origin, enu_to_geodetic
from gcs_planner.plan import VehiclePlan

__all__ = ["CLIMB_RUN_PER_M", "Start", "format_homes", "starts"]

# ground run per metre of climb: ArduPlane's TAKEOFF mode climbs at TECS_CLMB_MAX (5 m/s) at
# about its cruise airspeed (22 m/s in SITL's plane model)
CLIMB_RUN_PER_M = 22.0 / 5.0


@dataclass(frozen=True)
class Start:
    sysid: int
    vehicle_id: str
    home: Origin  # on the ground
    heading_deg: float  # launch heading, compass


def starts(plans: list[VehiclePlan], origin: Origin) -> list[Start]:
    """Each plan's start: one climb run before its first waypoint, facing its first leg."""
    out = []
    for vp in plans:
        (x0, y0, z0), (x1, y1, _) = vp.waypoints[0], vp.waypoints[1]
        d = math.hypot(x1 - x0, y1 - y0)
        ux, uy = (x1 - x0) / d, (y1 - y0) / d
        run = z0 * CLIMB_RUN_PER_M
        lat, lon, alt = enu_to_geodetic(x0 - run * ux, y0 - run * uy, 0.0, origin)
        heading = math.degrees(math.atan2(ux, uy)) % 360.0
        out.append(Start(vp.sysid, vp.vehicle_id, Origin(float(lat), float(lon), float(alt)), heading))
    return out


def format_homes(found: list[Start], sysids: frozenset[int] | None) -> str:
    """One line per start (of ``sysids``; None: all) with its SITL ``--home`` and system id parameter."""
    return "\n".join(
        f"sysid {s.sysid} ({s.vehicle_id}): --home {s.home.lat_deg:.7f},{s.home.lon_deg:.7f},"
        f"{s.home.alt_m:.1f},{s.heading_deg:.0f}  (MAV_SYSID {s.sysid}; SYSID_THISMAV before ArduPilot 4.7)"
        for s in found
        if sysids is None or s.sysid in sysids
    )
