"""Where a connected vehicle (real or SITL) starts, so that its take-off ends where its mission begins.

A plane takes off in ArduPlane's TAKEOFF mode, climbing on its launch heading, and its mission's
first leg (in a coalition run, a straight lead-in: coalition_hil.missions.first_mission) follows.
Its home is therefore on that line, one climb run before the first waypoint, facing along it; a
multirotor climbs straight up, so its home is under its first waypoint. SITL takes either as
``--home lat,lon,alt,hdg`` (``fly --homes``, ``fly-coalition --homes``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from gcs_planner.errors import UserError
from gcs_planner.geo import Origin, enu_to_geodetic, geodetic_to_enu
from gcs_planner.plan import VehiclePlan

__all__ = ["CLIMB_RUN_PER_M", "MAX_START_OFFSET_M", "Start", "check_starts", "format_homes", "starts"]

MAX_START_OFFSET_M = 1000.0  # a connected vehicle further than this from its start is refused [m]
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
    """Each plan's start, facing its first leg: a plane one climb run before its first waypoint, a
    multirotor under it."""
    out = []
    for vp in plans:
        (x0, y0, z0), (x1, y1, _) = vp.waypoints[0], vp.waypoints[1]
        d = max(math.hypot(x1 - x0, y1 - y0), 1e-9)
        ux, uy = (x1 - x0) / d, (y1 - y0) / d
        run = z0 * CLIMB_RUN_PER_M if vp.vehicle_type == "fixed_wing" else 0.0
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


def check_starts(found: list[Start], positions: dict[int, tuple[float, float]], hint: str) -> None:
    """Refuse (UserError) when a vehicle's reported position (lat, lon [deg]) is more than
    MAX_START_OFFSET_M from its start: its take-off would not end where its mission begins (a SITL
    started without ``--home`` is at its default home, another continent). hint: how to start it."""
    for s in found:
        if s.sysid not in positions:
            continue
        east, north, _ = geodetic_to_enu(*positions[s.sysid], s.home.alt_m, s.home)
        off = math.hypot(east, north)
        if off > MAX_START_OFFSET_M:
            raise UserError(
                f"sysid {s.sysid} ({s.vehicle_id}) is {off / 1000:,.1f} km from its start "
                f"{s.home.lat_deg:.7f},{s.home.lon_deg:.7f} ({hint})"
            )
