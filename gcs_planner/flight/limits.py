"""A plane's airspeed range and bank limit, read from its autopilot, against what a flight asks of it.

ArduPlane refuses a DO_CHANGE_SPEED airspeed outside [AIRSPEED_MIN, AIRSPEED_MAX] and keeps the
speed it had (commands_logic.cpp ``Plane::do_change_speed``), so a plan beyond that range is flown
at the wrong speed without a word; and it banks at most ROLL_LIMIT_DEG, so a tighter planned turn
is flown wide. A flight therefore reads those parameters before anything is uploaded, refuses a
plan outside them in one line, and clips schedule keeping to the range (timekeeping.ScheduleKeeper).
"""

from __future__ import annotations

import asyncio
import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass

from gcs_planner.autopilots import AutopilotQuirks
from gcs_planner.core.errors import UserError
from gcs_planner.mavlink.link import MavlinkLink
from gcs_planner.mavlink.params import read_param
from gcs_planner.model.plan import VehiclePlan

__all__ = ["FlightLimits", "check_limits", "read_l1_params", "read_limits", "read_ramps"]

log = logging.getLogger(__name__)

G_MPS2 = 9.80665


@dataclass(frozen=True)
class FlightLimits:
    names: tuple[str, str, str]  # the parameters the values came from
    min_mps: float
    max_mps: float
    roll_deg: float


async def read_limits(
    link: MavlinkLink, sysids: Sequence[int], quirks: dict[int, AutopilotQuirks]
) -> dict[int, FlightLimits]:
    """Each vehicle's limits, where its autopilot has them; a vehicle that does not answer for one
    of the parameters (another firmware generation) is logged and left unchecked."""

    async def one(sysid: int) -> FlightLimits | None:
        names = quirks[sysid].flight_limits
        values = await asyncio.gather(*(read_param(link, sysid, n) for n in names))
        if None in values:
            missing = [n for n, v in zip(names, values, strict=True) if v is None]
            log.warning("sysid %d: no value for %s; its speed range is not checked", sysid, missing)
            return None
        return FlightLimits(names, *values)

    asked = [s for s in sysids if quirks[s].flight_limits is not None]
    found = await asyncio.gather(*(one(s) for s in asked))
    return {s: lim for s, lim in zip(asked, found, strict=True) if lim is not None}


async def read_l1_params(
    link: MavlinkLink, sysids: Sequence[int], quirks: dict[int, AutopilotQuirks]
) -> dict[int, tuple[float, float]]:
    """The period [s] of each plane's L1 waypoint guidance and its roll controller's time constant
    [s] (``AutopilotQuirks.l1_params``), for the vehicles whose autopilot has them and answers
    with a positive period."""

    async def one(sysid: int) -> tuple[float | None, ...]:
        return tuple(await asyncio.gather(*(read_param(link, sysid, n) for n in quirks[sysid].l1_params)))

    asked = [s for s in sysids if quirks[s].l1_params is not None]
    found = await asyncio.gather(*(one(s) for s in asked))
    return {
        s: (float(period), float(tau or 0.0))
        for s, (period, tau) in zip(asked, found, strict=True)
        if period is not None and period > 0.0
    }


async def read_ramps(
    link: MavlinkLink, sysids: Sequence[int], quirks: dict[int, AutopilotQuirks]
) -> dict[int, tuple[float, float]]:
    """Each vehicle's waypoint acceleration [m/s^2] and jerk [m/s^3] limits
    (``AutopilotQuirks.ramp_params``), for those whose autopilot has them and answers both."""

    async def one(sysid: int) -> tuple[float | None, ...]:
        accel, jerk, _ = quirks[sysid].ramp_params
        return tuple(await asyncio.gather(read_param(link, sysid, accel), read_param(link, sysid, jerk)))

    asked = [s for s in sysids if quirks[s].ramp_params is not None]
    found = await asyncio.gather(*(one(s) for s in asked))
    return {
        s: (accel * quirks[s].ramp_params[2], jerk * quirks[s].ramp_params[2])
        for s, (accel, jerk) in zip(asked, found, strict=True)
        if accel and jerk and accel > 0 and jerk > 0
    }


def check_limits(plans: Sequence[VehiclePlan], limits: dict[int, FlightLimits], top_factor: float) -> None:
    """UserError naming the parameter and its value when a plan asks a vehicle for a speed outside
    its range (up to ``top_factor`` x the planned top speed: legs flown faster to be on time) or
    a bank beyond its limit for the planned turn radius at that speed."""
    for vp in plans:
        lim = limits.get(vp.sysid)
        flying = [float(v) for v in vp.speeds_mps if v > 0.0]
        if lim is None or not flying:
            continue
        lo, hi = min(flying), max(flying) * top_factor
        name_min, name_max, name_roll = lim.names
        who = f"vehicle {vp.vehicle_id} (sysid {vp.sysid})"
        if hi > lim.max_mps + 1e-6:
            raise UserError(
                f"{who}: {name_max} is {lim.max_mps:g} m/s, but the flight needs up to {hi:g} m/s"
                f" ({max(flying):g} m/s planned x {top_factor:g}); raise it or fly slower vehicles"
            )
        if lo < lim.min_mps - 1e-6:
            raise UserError(f"{who}: {name_min} is {lim.min_mps:g} m/s, but the plan flies {lo:g} m/s")
        if vp.turn_radius_m > 0.0:
            bank = math.degrees(math.atan(hi**2 / (G_MPS2 * vp.turn_radius_m)))
            if bank > lim.roll_deg + 1e-6:
                raise UserError(
                    f"{who}: {name_roll} is {lim.roll_deg:g} deg, but turns of {vp.turn_radius_m:g} m at"
                    f" {hi:g} m/s need {bank:.1f} deg"
                )
