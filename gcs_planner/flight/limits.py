"""A vehicle's speed limits, read from its autopilot, against what a flight asks of it.

ArduPlane refuses a DO_CHANGE_SPEED airspeed outside [AIRSPEED_MIN, AIRSPEED_MAX] and keeps the
speed it had (commands_logic.cpp ``Plane::do_change_speed``), so a plan beyond that range is flown
at the wrong speed without a word; and it banks at most ROLL_LIMIT_DEG, so a tighter planned turn
is flown wide. A multirotor in a mission climbs and descends at most at its autopilot's waypoint
climb and descent speeds (ArduCopter AC_WPNav WP_SPD_UP / WP_SPD_DN, stock 2.5 / 1.5 m/s; PX4
MPC_Z_V_AUTO_UP / _DN, 3 / 1.5 m/s) and slows along a steeper leg to keep them: on ArduCopter
SITL with stock parameters, swarm_small's 20-degree legs at 10 m/s were flown at 5.4 m/s and four
of five vehicles ended 18-31 s late (docs/real-autopilots.md). A flight therefore reads those
parameters before anything is uploaded, refuses a plan outside them in one line, and clips
schedule keeping to a plane's range (timekeeping.ScheduleKeeper).
"""

from __future__ import annotations

import asyncio
import logging
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from gcs_planner.autopilots import AutopilotQuirks
from gcs_planner.core.errors import UserError
from gcs_planner.mavlink.link import MavlinkLink
from gcs_planner.mavlink.params import read_param
from gcs_planner.model.plan import VehiclePlan

__all__ = [
    "FlightLimits", "VerticalLimits", "check_limits", "check_vertical", "planned_vertical_mps",
    "read_l1_params", "read_limits", "read_ramps", "read_vertical",
]  # fmt: skip

log = logging.getLogger(__name__)

G_MPS2 = 9.80665
MOVING_MPS = 0.5  # a path step slower than this over ground is a take-off or a landing, not a leg
MIN_STEP_S = 0.05  # shorter path steps are left out: plan.json's rounding (0.1 mm) is noise over them


@dataclass(frozen=True)
class FlightLimits:
    names: tuple[str, str, str]  # the parameters the values came from
    min_mps: float
    max_mps: float
    roll_deg: float


@dataclass(frozen=True)
class VerticalLimits:
    names: tuple[str, str]  # the parameters the values came from
    climb_mps: float
    descent_mps: float


async def _read_each(
    link: MavlinkLink, sysids: Sequence[int], names_of: Callable[[int], Sequence[str] | None]
) -> dict[int, tuple[float | None, ...]]:
    """Each vehicle's values of the parameters ``names_of(sysid)``, in order (None: no answer), for
    those it names any for; every read at once."""
    asked = [s for s in sysids if names_of(s)]
    found = await asyncio.gather(
        *(asyncio.gather(*(read_param(link, s, n) for n in names_of(s))) for s in asked)
    )
    return {s: tuple(values) for s, values in zip(asked, found, strict=True)}


def _all_answered(sysid: int, names: Sequence[str], values: Sequence[float | None], unchecked: str) -> bool:
    """Whether every parameter answered; if not, say which did not (another firmware generation)."""
    missing = [n for n, v in zip(names, values, strict=True) if v is None]
    if missing:
        log.warning("sysid %d: no value for %s; its %s not checked", sysid, missing, unchecked)
    return not missing


async def read_limits(
    link: MavlinkLink, sysids: Sequence[int], quirks: dict[int, AutopilotQuirks]
) -> dict[int, FlightLimits]:
    """Each vehicle's limits, where its autopilot has them; a vehicle that does not answer for one
    of the parameters is logged and left unchecked."""
    found = await _read_each(link, sysids, lambda s: quirks[s].flight_limits)
    return {
        s: FlightLimits(quirks[s].flight_limits, *values)
        for s, values in found.items()
        if _all_answered(s, quirks[s].flight_limits, values, "speed range is")
    }


async def read_l1_params(
    link: MavlinkLink, sysids: Sequence[int], quirks: dict[int, AutopilotQuirks]
) -> dict[int, tuple[float, float]]:
    """The period [s] of each plane's L1 waypoint guidance and its roll controller's time constant
    [s] (``AutopilotQuirks.l1_params``), for the vehicles whose autopilot has them and answers
    with a positive period."""
    found = await _read_each(link, sysids, lambda s: quirks[s].l1_params)
    return {
        s: (float(period), float(tau or 0.0))
        for s, (period, tau) in found.items()
        if period is not None and period > 0.0
    }


async def read_ramps(
    link: MavlinkLink, sysids: Sequence[int], quirks: dict[int, AutopilotQuirks]
) -> dict[int, tuple[float, float]]:
    """Each vehicle's waypoint acceleration [m/s^2] and jerk [m/s^3] limits
    (``AutopilotQuirks.ramp_params``), for those whose autopilot has them and answers both."""
    found = await _read_each(link, sysids, lambda s: quirks[s].ramp_params and quirks[s].ramp_params[:2])
    return {
        s: (accel * quirks[s].ramp_params[2], jerk * quirks[s].ramp_params[2])
        for s, (accel, jerk) in found.items()
        if accel and jerk and accel > 0 and jerk > 0
    }


async def read_vertical(
    link: MavlinkLink, sysids: Sequence[int], quirks: dict[int, AutopilotQuirks]
) -> dict[int, VerticalLimits]:
    """Each vehicle's mission climb and descent speeds (``AutopilotQuirks.vertical_params``), for
    those whose autopilot has them and answers both (else logged and left unchecked)."""
    found = await _read_each(link, sysids, lambda s: quirks[s].vertical_params)
    return {
        s: VerticalLimits(quirks[s].vertical_params, *values)
        for s, values in found.items()
        if _all_answered(s, quirks[s].vertical_params, values, "climb and descent are")
    }


def planned_vertical_mps(vp: VehiclePlan) -> tuple[float, float]:
    """The steepest planned climb and descent rates [m/s, both >= 0] along the route: dz / dt
    between path samples where the vehicle also moves over ground (its take-off and landing are
    flown at the autopilot's own rates) and that last at least MIN_STEP_S."""
    step = np.diff(vp.path, axis=0)
    dt = np.diff(vp.path_times_s)
    moving = (dt >= MIN_STEP_S) & (np.hypot(step[:, 0], step[:, 1]) > MOVING_MPS * dt)
    vz = step[moving, 2] / dt[moving]
    return max(float(vz.max(initial=0.0)), 0.0), max(-float(vz.min(initial=0.0)), 0.0)


def check_vertical(plans: Sequence[VehiclePlan], limits: dict[int, VerticalLimits], factor: float) -> None:
    """UserError naming the parameter and its value when a multirotor's plan climbs or descends
    faster (x ``factor``: legs flown faster to be on time) than its autopilot will in a mission."""
    for vp in plans:
        lim = limits.get(vp.sysid)
        if lim is None or vp.vehicle_type != "multirotor":
            continue
        climb, descent = (factor * v for v in planned_vertical_mps(vp))
        for name, limit, need, verb in zip(
            lim.names, (lim.climb_mps, lim.descent_mps), (climb, descent), ("climbs", "descends"), strict=True
        ):
            if need > limit + 1e-3:
                raise UserError(
                    f"vehicle {vp.vehicle_id} (sysid {vp.sysid}): {name} is {limit:g} m/s, but the plan"
                    f" {verb} at up to {need:.2f} m/s; raise it (gcs-planner params set) or plan gentler legs"
                )


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
