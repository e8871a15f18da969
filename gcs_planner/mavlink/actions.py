"""Flight actions done the way each autopilot takes them: take-off, mission start, speed, safe end.

Each function reads the vehicle's ``AutopilotQuirks`` (autopilots.py) instead of assuming one
autopilot; fly.py and the coalition HIL call these, never the raw commands.
"""

from __future__ import annotations

import asyncio
import logging

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs_planner.core.errors import UserError
from gcs_planner.mavlink.autopilots import AutopilotQuirks, Takeoff
from gcs_planner.mavlink.command import CommandClient
from gcs_planner.mavlink.errors import MavlinkError
from gcs_planner.mavlink.link import MavlinkLink
from gcs_planner.mavlink.mission import MissionClient
from gcs_planner.mavlink.params import set_param
from gcs_planner.mavlink.preflight import arm_when_ready
from gcs_planner.mavlink.vehicle_status import VehicleStatus

__all__ = [
    "ON_GROUND_M", "TAKEOFF_MODE_LEVEL_OFF_M", "change_speed", "safe_end", "start_mission_at", "take_off",
]  # fmt: skip

log = logging.getLogger(__name__)

ON_GROUND_M = 1.0  # a vehicle this close to its home altitude counts as on the ground [m]
TAKEOFF_ALT_PARAM = "TKOFF_ALT"  # ArduPlane: TAKEOFF mode's target altitude above home [m]
TAKEOFF_DIST_PARAM = "TKOFF_DIST"  # ArduPlane: TAKEOFF mode ends this far from its start [m]
TAKEOFF_MODE_LEVEL_OFF_M = 2.0  # ArduPlane's TAKEOFF mode is done this far below TKOFF_ALT [m]


async def take_off(
    link: MavlinkLink,
    status: VehicleStatus,
    sysid: int,
    quirks: AutopilotQuirks,
    alt_m: float,
    arm_timeout_s: float,
    time_scale: float = 1.0,
    waiting=None,
    climb_past_m: float = 0.0,
    takeoff_dist_m: float = 0.0,
) -> None:
    """Arm (once the vehicle is ready) and climb to ``alt_m`` above home, as the autopilot takes it.
    A TAKEOFF-mode plane gets TKOFF_ALT ``alt_m`` + ``climb_past_m`` and TKOFF_DIST
    ``takeoff_dist_m``, so that it climbs straight along its launch heading until it is up
    (ArduPlane's ModeTakeoff::update ends the straight climb 2 m below TKOFF_ALT or TKOFF_DIST from
    its start, default 200 m, and climbs on circling: SITL planes began their routes 44-80 m off the
    line; a coalition plane climbing to 300-500 m would circle most of its climb)."""
    command = CommandClient(link, sysid)
    if quirks.takeoff is Takeoff.TAKEOFF_MODE:
        value = await set_param(link, sysid, TAKEOFF_ALT_PARAM, alt_m + climb_past_m)
        log.info("vehicle %d: %s set to %.1f m for the take-off", sysid, TAKEOFF_ALT_PARAM, value)
        if takeoff_dist_m > 0:
            await set_param(link, sysid, TAKEOFF_DIST_PARAM, takeoff_dist_m)
    if quirks.arm_mode is not None:
        await command.set_mode(quirks.arm_mode)
    await arm_when_ready(link, status, sysid, arm_timeout_s, time_scale, waiting)
    if quirks.takeoff is Takeoff.TAKEOFF_MODE:
        return  # ArduPlane's TAKEOFF mode climbs once armed
    param7 = alt_m
    if quirks.takeoff is Takeoff.COMMAND_AMSL:
        home = status.tracks[sysid].home_amsl_m
        if home is None:
            raise UserError(f"vehicle {sysid}: no home altitude known yet (no GLOBAL_POSITION_INT)")
        param7 = home + alt_m
    await command.takeoff(param7)


async def start_mission_at(
    link: MavlinkLink, sysid: int, quirks: AutopilotQuirks, first: int, last: int
) -> None:
    """Run the mission from item ``first`` to ``last``: MISSION_START(first, last) where the
    autopilot takes a range, else DO_SET_MISSION_CURRENT(first) and MISSION_START(0, 0) (ArduPilot
    denies any other range and resumes at the current item)."""
    command = CommandClient(link, sysid)
    if quirks.start_with_range:
        await command.mission_start(first, last)
        return
    await MissionClient(link, sysid).set_current(first)
    await command.mission_start(0, 0)


def change_speed(link: MavlinkLink, sysid: int, quirks: AutopilotQuirks, speed_mps: float) -> None:
    """DO_CHANGE_SPEED, fire and forget (schedule keeping resends): airspeed for planes, whose
    autopilot reads a ground-speed change as a minimum ground speed, ground speed for the rest."""
    link.send(
        mavlink.MAVLink_command_long_message(
            sysid, 1, mavlink.MAV_CMD_DO_CHANGE_SPEED, 0, quirks.speed_type, speed_mps, -1, 0, 0, 0, 0
        )
    )


async def safe_end(
    link: MavlinkLink, status: VehicleStatus, quirks: dict[int, AutopilotQuirks]
) -> dict[int, str]:
    """Bring every vehicle to a safe state; returns sysid -> what was done, in words.

    Disarmed: nothing to do. Armed on the ground: disarm. Airborne: the autopilot's return mode
    (RTL), else its land mode; a vehicle that takes neither is reported as still flying.
    """

    async def one(sysid: int) -> str:
        info = link.vehicles.get(sysid)
        if info is None or not info.armed:
            return "landed (disarmed)"
        command = CommandClient(link, sysid)
        q = quirks[sysid]
        alt = status.tracks[sysid].rel_alt_m
        try:
            if alt is not None and alt < ON_GROUND_M:
                await command.disarm()
                return "disarmed on the ground"
        except MavlinkError as exc:
            log.warning("vehicle %d: disarm refused: %s", sysid, exc)
        errors = []
        for mode, words in ((q.return_mode, "returning (RTL)"), (q.land_mode, "landing (LAND)")):
            if mode is None:
                continue
            try:
                await command.set_mode(mode)
                return words
            except (MavlinkError, UserError) as exc:
                errors.append(f"{mode}: {exc}")
        return f"STILL FLYING ({'; '.join(errors) or 'no return or land mode'})"

    sysids = sorted(quirks)
    done = await asyncio.gather(*(one(s) for s in sysids))
    return dict(zip(sysids, done, strict=True))
