"""COMMAND_LONG client with retries and COMMAND_ACK matching: arm, mode, mission start, takeoff, RTL,
message intervals.

Choices:
- COMMAND_LONG is resent every COMMAND_RETRY_S = 1.5 s (COMMAND_RETRIES = 3 times), with
  ``confirmation`` counting the resends as the spec asks; the matcher (COMMAND_ACK from the target
  for this command, addressed to us or broadcast) is subscribed before the first send.
  IN_PROGRESS acks extend the wait, for at most IN_PROGRESS_MAX_S in all (none of these commands
  runs for long; a vehicle that says IN_PROGRESS for ever would hold the tool for ever); any other
  result ends it.
- Mode names are turned into numbers with the autopilot's own table, picked from the vehicle's
  HEARTBEAT (autopilots.quirks_for: autopilot, and MAV_TYPE for ArduPlane vs ArduCopter). DO_SET_MODE carries
  MAV_MODE_FLAG_CUSTOM_MODE_ENABLED in param1 and, for ArduPilot, custom_mode in param2; for PX4
  main mode in param2 and sub mode in param3.
"""

from __future__ import annotations

import asyncio
import math

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs_planner.autopilots import quirks_for
from gcs_planner.core.errors import UserError
from gcs_planner.mavlink.errors import CommandTimeoutError, command_error
from gcs_planner.mavlink.link import MavlinkLink
from gcs_planner.wire.enums import CommandResult

__all__ = ["COMMAND_RETRIES", "COMMAND_RETRY_S", "IN_PROGRESS_MAX_S", "CommandClient", "mode_table"]

COMMAND_RETRY_S = 1.5  # wait for COMMAND_ACK before resending [s]
COMMAND_RETRIES = 3  # resends after the first COMMAND_LONG
IN_PROGRESS_MAX_S = 30.0  # the longest a command waits on IN_PROGRESS acks, all tries together [s]
FORCE_DISARM_MAGIC = 21196.0  # MAV_CMD_COMPONENT_ARM_DISARM param2 that forces (ArduPilot, PX4)


def mode_table(autopilot: int | None, mav_type: int | None) -> dict[str, int]:
    """Mode name -> custom_mode for a vehicle, from its HEARTBEAT fields."""
    modes = quirks_for(autopilot, mav_type).modes
    if modes is None:
        raise UserError(f"cannot set modes by name on autopilot type {autopilot} (only ArduPilot and PX4)")
    return modes


class CommandClient:
    """Commands to one vehicle (``sysid``/``compid``) over ``link``."""

    def __init__(
        self,
        link: MavlinkLink,
        sysid: int,
        compid: int = 1,
        *,
        retry_s: float = COMMAND_RETRY_S,
        retries: int = COMMAND_RETRIES,
        in_progress_max_s: float = IN_PROGRESS_MAX_S,
    ) -> None:
        self.link = link
        self.sysid = sysid
        self.compid = compid
        self.retry_s = retry_s
        self.retries = retries
        self.in_progress_max_s = in_progress_max_s

    async def command_long(self, command: int, *params: float) -> CommandResult:
        """Send COMMAND_LONG until COMMAND_ACK: ACCEPTED, or CommandError / CommandTimeoutError."""
        if len(params) > 7:
            raise ValueError(f"COMMAND_LONG takes 7 params, got {len(params)}")
        values = [float(p) for p in params] + [0.0] * (7 - len(params))
        name = _command_name(command)
        self.link.check_target(self.sysid)
        loop = asyncio.get_running_loop()
        acks: asyncio.Queue = asyncio.Queue()

        def on_frame(msg, raw: bytes, t_s: float) -> None:
            if (
                msg.get_type() == "COMMAND_ACK"
                and msg.command == command
                and msg.get_srcSystem() == self.sysid
                and msg.get_srcComponent() == self.compid
                and msg.target_system in (0, self.link.sysid)
            ):
                acks.put_nowait(msg)

        unsubscribe = self.link.subscribe(on_frame, self.sysid)
        give_up = loop.time() + self.in_progress_max_s
        try:
            for confirmation in range(self.retries + 1):
                self.link.send(
                    mavlink.MAVLink_command_long_message(
                        self.sysid, self.compid, command, confirmation, *values
                    )
                )
                deadline = loop.time() + self.retry_s
                while (remaining := deadline - loop.time()) > 0:
                    try:
                        ack = await asyncio.wait_for(acks.get(), remaining)
                    except TimeoutError:
                        break
                    if ack.result == CommandResult.IN_PROGRESS:
                        if loop.time() >= give_up:
                            raise CommandTimeoutError(
                                f"vehicle {self.sysid}: {name} still IN_PROGRESS after "
                                f"{self.in_progress_max_s:g} s"
                            )
                        deadline = min(loop.time() + self.retry_s, give_up)
                        continue
                    if ack.result == CommandResult.ACCEPTED:
                        return CommandResult.ACCEPTED
                    raise command_error(self.sysid, command, ack.result, name)
        finally:
            unsubscribe()
        raise CommandTimeoutError(
            f"vehicle {self.sysid}: no COMMAND_ACK to {name} after {self.retries + 1} tries"
        )

    async def arm(self) -> None:
        await self.command_long(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1.0)

    async def disarm(self, force: bool = False) -> None:
        await self.command_long(
            mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0.0, FORCE_DISARM_MAGIC if force else 0.0
        )

    async def set_mode(self, name: str) -> None:
        """Switch to mode ``name`` (AUTO, GUIDED, LOITER, RTL, LAND, ...) using the vehicle's mode table."""
        info = self.link.vehicles.get(self.sysid)
        if info is None:
            raise UserError(f"vehicle {self.sysid}: no HEARTBEAT yet, its mode numbers are unknown")
        table = mode_table(info.autopilot, info.mav_type)
        try:
            custom = table[name.upper()]
        except KeyError:
            known = ", ".join(table)
            raise UserError(f"mode {name!r} does not exist on vehicle {self.sysid}; known: {known}") from None
        flag = float(mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED)
        params = quirks_for(info.autopilot, info.mav_type).mode_command_params(custom)
        await self.command_long(mavlink.MAV_CMD_DO_SET_MODE, flag, *params)

    async def mission_start(self, first_seq: int = 0, last_seq: int = 0) -> None:
        """MAV_CMD_MISSION_START (0, 0 = the whole mission)."""
        await self.command_long(mavlink.MAV_CMD_MISSION_START, first_seq, last_seq)

    async def set_mission_current(self, seq: int) -> None:
        """MAV_CMD_DO_SET_MISSION_CURRENT (MissionClient.set_current adds the legacy fallback)."""
        await self.command_long(mavlink.MAV_CMD_DO_SET_MISSION_CURRENT, seq)

    async def takeoff(self, alt_m: float) -> None:
        """MAV_CMD_NAV_TAKEOFF with param7 = ``alt_m``, which ArduCopter reads as metres above home and
        PX4 as metres AMSL (autopilots/px4.py); the vehicle must be armed, in a mode that allows it."""
        if not math.isfinite(alt_m) or alt_m <= 0:
            raise UserError(f"takeoff altitude must be a positive number of metres, got {alt_m!r}")
        await self.command_long(mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, alt_m)

    async def set_message_interval(self, message_id: int, rate_hz: float) -> None:
        """MAV_CMD_SET_MESSAGE_INTERVAL: stream ``message_id`` at ``rate_hz`` (0: stop it)."""
        interval_us = 1e6 / rate_hz if rate_hz > 0 else -1.0
        await self.command_long(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, message_id, interval_us)

    async def rtl(self) -> None:
        await self.command_long(mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH)

    async def land(self) -> None:
        await self.command_long(mavlink.MAV_CMD_NAV_LAND)


def _command_name(command: int) -> str:
    entry = mavlink.enums["MAV_CMD"].get(command)
    return entry.name if entry else f"MAV_CMD {command}"
