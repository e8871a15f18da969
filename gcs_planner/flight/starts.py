"""Where a connected vehicle (real or SITL) starts, so that its take-off ends where its mission begins.

A plane takes off in ArduPlane's TAKEOFF mode, climbing on its launch heading, and its mission's
first leg (in a coalition run, a straight lead-in: flight.coalition.missions.first_mission) follows.
Its home is therefore on that line, one climb run before the first waypoint, facing along it; a
multirotor climbs straight up, so its home is under its first waypoint. SITL takes either as
``--home lat,lon,alt,hdg`` (``fly --homes``, ``fly-coalition --homes``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from gcs_planner.core.errors import UserError
from gcs_planner.core.geo import Origin, enu_to_geodetic, geodetic_to_enu
from gcs_planner.model.plan import VehiclePlan

__all__ = [
    "CLIMB_RUN_PER_M", "MULTIROTOR_START_M", "START_FIX_WAIT_S", "Start", "check_starts", "format_homes",
    "starts",
]  # fmt: skip

# how far from its start a vehicle may stand and still fly its plan: a multirotor climbs straight
# up, so a few metres (GPS error and the pad); a plane launches along its climb run, so that run
# (and a margin: TAKEOFF mode's level-off is not exact)
MULTIROTOR_START_M = 5.0
PLANE_START_MARGIN_M = 50.0
START_FIX_WAIT_S = 30.0  # how long a vehicle has to report a position before the check [s wall]
# ground run per metre of climb: ArduPlane's TAKEOFF mode climbs at TECS_CLMB_MAX (5 m/s) at
# about its cruise airspeed (22 m/s in SITL's plane model)
CLIMB_RUN_PER_M = 22.0 / 5.0


@dataclass(frozen=True)
class Start:
    sysid: int
    vehicle_id: str
    home: Origin  # on the ground
    heading_deg: float  # launch heading, compass
    bound_m: float  # the furthest from ``home`` it may stand and fly the plan


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
        bound = run + PLANE_START_MARGIN_M if vp.vehicle_type == "fixed_wing" else MULTIROTOR_START_M
        out.append(Start(vp.sysid, vp.vehicle_id, Origin(float(lat), float(lon), float(alt)), heading, bound))
    return out


def format_homes(found: list[Start], sysids: frozenset[int] | None) -> str:
    """One line per start (of ``sysids``; None: all): ArduPilot SITL's ``--home`` and system id
    parameter, then PX4 SITL's home environment variables and its MAV_SYS_ID. PX4 v1.15's SIH reads
    PX4_HOME_LAT / LON into SIH_LOC_LAT0 / LON0, integers of 1e-7 degrees (a value in degrees puts
    the vehicle near 0 N 0 E), and not PX4_HOME_ALT: those are printed for it too."""
    rows = []
    for s in found:
        if sysids is not None and s.sysid not in sysids:
            continue
        lat, lon, alt = f"{s.home.lat_deg:.7f}", f"{s.home.lon_deg:.7f}", f"{s.home.alt_m:.1f}"
        rows.append(
            f"sysid {s.sysid} ({s.vehicle_id}): --home {lat},{lon},{alt},{s.heading_deg:.0f}  (MAV_SYSID"
            f" {s.sysid}; SYSID_THISMAV before ArduPilot 4.7) | PX4: PX4_HOME_LAT={lat} PX4_HOME_LON={lon}"
            f" PX4_HOME_ALT={alt}, param MAV_SYS_ID {s.sysid} | PX4 SIH:"
            f" PX4_HOME_LAT={round(s.home.lat_deg * 1e7)} PX4_HOME_LON={round(s.home.lon_deg * 1e7)},"
            f" param SIH_LOC_H0 {alt}"
        )
    return "\n".join(rows)


def check_starts(
    found: list[Start], positions: dict[int, tuple[float, float]], hint: str, min_bound_m: float = 0.0
) -> None:
    """Refuse (UserError naming each vehicle) a vehicle whose reported position (lat, lon [deg]) is
    further than its bound from its start, or that reported none: its take-off would not end where
    its mission begins (a SITL started without ``--home`` is at its default home, another
    continent; four mocks on one spot would collide). hint: how to start it. ``min_bound_m``: a
    looser bound for every vehicle."""
    problems = []
    for s in found:
        if s.sysid not in positions:
            problems.append(f"sysid {s.sysid} ({s.vehicle_id}) reports no position: its start is unknown")
            continue
        east, north, _ = geodetic_to_enu(*positions[s.sysid], s.home.alt_m, s.home)
        off = math.hypot(east, north)
        bound = max(s.bound_m, min_bound_m)
        if not off <= bound:
            problems.append(
                f"sysid {s.sysid} ({s.vehicle_id}) is {_distance(off)} from its start "
                f"{s.home.lat_deg:.7f},{s.home.lon_deg:.7f} (bound {bound:.0f} m)"
            )
    if problems:
        raise UserError("; ".join([*problems[:-1], f"{problems[-1]} ({hint})"]))


def _distance(m: float) -> str:
    return f"{m / 1000:,.1f} km" if m >= 1000 else f"{m:.1f} m"
