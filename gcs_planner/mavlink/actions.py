"""Flight actions done the way each autopilot takes them: take-off, mission start, speed, safe end.

Each function leaves what differs to the vehicle's autopilot family (gcs_planner.autopilots) instead
of assuming one autopilot; the flight runner and its strategies call these, never the raw commands.
"""

from __future__ import annotations

import asyncio
import logging

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs_planner.autopilots import AutopilotQuirks
from gcs_planner.core.errors import UserError
from gcs_planner.mavlink.command import CommandClient
from gcs_planner.mavlink.errors import MavlinkError
from gcs_planner.mavlink.link import MavlinkLink
from gcs_planner.mavlink.mission import MissionClient
from gcs_planner.mavlink.params import set_param
from gcs_planner.mavlink.preflight import arm_when_ready
from gcs_planner.mavlink.vehicle_status import VehicleStatus

__all__ = [
    "ON_GROUND_M", "change_speed", "safe_end", "start_mission_at", "take_off",
]  # fmt: skip

log = logging.getLogger(__name__)

ON_GROUND_M = 1.0  # a vehicle this close to its home altitude counts as on the ground [m]


class _Port:
    """One vehicle as an autopilot family's methods drive it (autopilots.VehiclePort)."""

    def __init__(
        self,
        link: MavlinkLink,
        status: VehicleStatus | None,
        sysid: int,
        arm_timeout_s: float,
        time_scale: float,
        waiting,
    ) -> None:
        self.link, self.status, self.sysid = link, status, sysid
        self.command = CommandClient(link, sysid)
        self.arm_timeout_s, self.time_scale, self.waiting = arm_timeout_s, time_scale, waiting

    async def set_param(self, name: str, value: float) -> float:
        return await set_param(self.link, self.sysid, name, value)

    async def set_mode(self, mode: str) -> None:
        await self.command.set_mode(mode)

    async def arm_when_ready(self) -> None:
        await arm_when_ready(
            self.link, self.status, self.sysid, self.arm_timeout_s, self.time_scale, self.waiting
        )

    async def takeoff(self, param7: float) -> None:
        await self.command.takeoff(param7)

    def home_amsl_m(self) -> float:
        home = self.status.tracks[self.sysid].home_amsl_m
        if home is None:
            raise UserError(f"vehicle {self.sysid}: no home altitude known yet (no GLOBAL_POSITION_INT)")
        return home

    async def mission_start(self, first: int, last: int) -> None:
        await self.command.mission_start(first, last)

    async def set_current(self, seq: int) -> None:
        await MissionClient(self.link, self.sysid).set_current(seq)


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
    """Arm (once the vehicle is ready) and climb to ``alt_m`` above home, as its family takes off.
    A plane climbing in TAKEOFF mode goes ``climb_past_m`` higher and ``takeoff_dist_m`` far
    before it may turn (autopilots/arduplane.py)."""
    port = _Port(link, status, sysid, arm_timeout_s, time_scale, waiting)
    await quirks.take_off(port, alt_m, climb_past_m, takeoff_dist_m)


async def start_mission_at(
    link: MavlinkLink, sysid: int, quirks: AutopilotQuirks, first: int, last: int
) -> None:
    """Run the mission from item ``first`` to ``last``, as the vehicle's family starts one."""
    await quirks.start_mission(_Port(link, None, sysid, 0.0, 1.0, None), first, last)


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
