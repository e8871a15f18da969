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

ArduCopter also plans each leg's speed from rest over half the leg (geometry/scurve.py): at stock
WP_ACC 2.5 / WP_JERK 1 a leg under ~65 m never reaches 10 m/s, and schedule keeping cannot make it
up (SITL's copter tops out at 10.3 m/s). Its legs are flown in advance on that model, the flown
track judged as conformance judges a real one, and a plan that would end up later than the
schedule bound is refused, with the WP_ACC / WP_JERK that would fly it on time.
"""

from __future__ import annotations

import asyncio
import logging
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from gcs_planner.autopilots import AutopilotQuirks
from gcs_planner.core.errors import UserError
from gcs_planner.geometry.ramp import ramp_loss_s
from gcs_planner.geometry.scurve import WaypointNav, fly_legs
from gcs_planner.mavlink.link import MavlinkLink
from gcs_planner.mavlink.params import read_param
from gcs_planner.missions.items import mission_waypoints
from gcs_planner.model.plan import VehiclePlan
from gcs_planner.safety.conformance import (
    SCHEDULE_STEP_S,
    Track,
    route_acceptance_m,
    route_window,
    schedule_errors_s,
)

__all__ = [
    "FlightLimits", "VerticalLimits", "check_limits", "check_vertical", "check_waypoint_timing",
    "faster_ramp", "planned_vertical_mps", "predicted_errors_s", "read_l1_params", "read_limits",
    "read_ramps", "read_vertical", "read_waypoint_nav",
]  # fmt: skip

log = logging.getLogger(__name__)

G_MPS2 = 9.80665
MOVING_MPS = 0.5  # a path step slower than this over ground is a take-off or a landing, not a leg
MIN_STEP_S = 0.05  # shorter path steps are left out: plan.json's rounding (0.1 mm) is noise over them
TELEMETRY_STEP = 10  # a flown-in-advance track is judged at 10 Hz, as GLOBAL_POSITION_INT comes
RAMP_TRIES = ((3.5, 2.0), (5.0, 3.0), (5.0, 5.0), (6.0, 8.0))  # WP_ACC, WP_JERK offered, in order
NEAR_PATH_M = 15.0  # a flown point this far beyond the acceptance radius still counts as passing
RAMP_MARGIN_S = 0.5  # an offered WP_ACC / WP_JERK keeps the prediction this far inside the bound


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


async def read_waypoint_nav(
    link: MavlinkLink,
    sysids: Sequence[int],
    quirks: dict[int, AutopilotQuirks],
    ramps: dict[int, tuple[float, float]],
    vertical: dict[int, VerticalLimits],
) -> dict[int, WaypointNav]:
    """The leg parameters of each vehicle that flies ArduCopter's S-curve legs and answered for its
    ramp and climb (``ramps``, ``vertical``); one of the others unanswered keeps its stock value."""
    asked = [s for s in sysids if quirks[s].waypoint_nav_params and s in ramps and s in vertical]
    found = await _read_each(link, asked, lambda s: quirks[s].waypoint_nav_params)
    stock = WaypointNav()
    navs = {}
    for s, (accel_z, radius, corner, input_tc) in found.items():
        navs[s] = WaypointNav(
            *ramps[s], vertical[s].climb_mps, vertical[s].descent_mps,
            stock.accel_z_mps2 if accel_z is None else accel_z,
            stock.radius_m if radius is None else radius,
            stock.corner_accel_mps2 if corner is None else corner,
            stock.input_tc_s if input_tc is None else input_tc,
        )  # fmt: skip
    return navs


def predicted_errors_s(vp: VehiclePlan, nav: WaypointNav) -> np.ndarray:
    """The along-track time errors [s, + late] of ``vp``'s mission flown on ArduCopter's S-curve
    legs (geometry.scurve), judged as conformance judges a flown track (schedule_errors_s, one a
    SCHEDULE_STEP_S of route time): started early by its ramp's loss (flight.ops.accel_lead_s),
    reported at 10 Hz."""
    route = mission_waypoints(vp)
    times, positions = fly_legs(route["waypoints"], route["speeds_mps"], nav)
    ramp = (nav.accel_mps2, nav.jerk_mps3)
    track = Track(times[::TELEMETRY_STEP], positions[::TELEMETRY_STEP])
    accept = route_acceptance_m(vp, None)
    window = route_window(track, vp.path, accept)
    route_t0_s = ramp_loss_s(vp.first_leg_speed_mps, *ramp) - float(vp.times_s[0])
    flown = Track(track.times_s[window], track.positions[window])
    return np.nan_to_num(schedule_errors_s(flown, vp, route_t0_s, accept + NEAR_PATH_M, ramp, accept))


def check_waypoint_timing(plans: Sequence[VehiclePlan], navs: dict[int, WaypointNav], bound_s: float) -> None:
    """UserError naming WP_ACC and WP_JERK when a multirotor flying ArduCopter's S-curve legs would
    end up later than ``bound_s`` behind its plan (module docstring), with values that would not."""
    for vp in plans:
        nav = navs.get(vp.sysid)
        if nav is None or vp.vehicle_type != "multirotor":
            continue
        errors = predicted_errors_s(vp, nav)
        if errors.max(initial=0.0) > bound_s:
            over_s = int(np.argmax(errors > bound_s)) * SCHEDULE_STEP_S
            raise UserError(
                f"vehicle {vp.vehicle_id} (sysid {vp.sysid}): with WP_ACC {nav.accel_mps2:g} and WP_JERK"
                f" {nav.jerk_mps3:g} its short legs never reach their speed (ArduCopter plans each from rest"
                f" over half its length): over the {bound_s:g} s bound {over_s:.0f} s into its route, up to"
                f" {errors.max():.1f} s late; {_faster_ramp(vp, nav, bound_s)}"
            )


def faster_ramp(
    plans: Sequence[VehiclePlan], nav: WaypointNav, bound_s: float
) -> tuple[float, float, float] | None:
    """The first of RAMP_TRIES (none below ``nav``'s) that flies every plan within ``bound_s`` less
    RAMP_MARGIN_S: (WP_ACC, WP_JERK, the worst lateness it predicts [s]); None if none does."""
    for accel, jerk in RAMP_TRIES:
        if accel >= nav.accel_mps2 and jerk >= nav.jerk_mps3:
            faster = replace(nav, accel_mps2=accel, jerk_mps3=jerk)
            late_s = max(predicted_errors_s(vp, faster).max(initial=0.0) for vp in plans)
            if late_s <= bound_s - RAMP_MARGIN_S:
                return accel, jerk, late_s
    return None


def _faster_ramp(vp: VehiclePlan, nav: WaypointNav, bound_s: float) -> str:
    """What to do about ``vp``: the ramp that flies it on time (faster_ramp), or plan anew."""
    found = faster_ramp([vp], nav, bound_s)
    if found is None:
        return "plan longer or slower legs"
    accel, jerk, late_s = found
    return f"WP_ACC {accel:g} and WP_JERK {jerk:g} predict {late_s:.1f} s: set them or plan longer legs"
