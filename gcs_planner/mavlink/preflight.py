"""Getting a vehicle ready to fly: telemetry streams, pre-arm readiness, arming.

Choices:
- Streams: every message a run needs is asked for with MAV_CMD_SET_MESSAGE_INTERVAL (as MAVSDK
  does), whatever the autopilot: stock ArduPilot streams only HEARTBEAT and STATUSTEXT (SRn_* = 0)
  until asked, PX4 streams without being asked and accepts the request. A refusal is logged, not
  fatal: the run's own timeouts say what is missing.
- Readiness: while the vehicle reports the SYS_STATUS pre-arm bit (ArduPilot and PX4 both do)
  and it is unhealthy, wait; then arm. An arming refusal (FAILED, TEMPORARILY_REJECTED, DENIED) is
  retried every ``ARM_RETRY_S`` until the deadline (ArduCopter refuses for ~40-45 s after boot,
  "Arm: Need Position Estimate"); the error names the autopilot's own last STATUSTEXT.
- Start: a vehicle that refuses MISSION_START (PX4 with a mission its check rejected) and was armed
  for it is disarmed again, never left armed on the ground; the error carries its own words.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable, Mapping

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs_planner.core.errors import UserError
from gcs_planner.core.lockstep import now_s
from gcs_planner.mavlink.command import COMMAND_RETRIES, COMMAND_RETRY_S, CommandClient
from gcs_planner.mavlink.errors import CommandError, CommandTimeoutError, MavlinkError
from gcs_planner.mavlink.link import MavlinkLink
from gcs_planner.mavlink.vehicle_status import VehicleStatus
from gcs_planner.wire.enums import CommandResult

__all__ = ["ARM_RETRY_S", "FLIGHT_STREAMS", "arm_when_ready", "request_streams", "start_or_disarm"]

log = logging.getLogger(__name__)

STREAM_WAIT_S = 2.0  # how long a refused stream may take to show it flows anyway [s wall]
ARM_RETRY_S = 2.0  # between arming attempts while the vehicle is not ready [s of vehicle time]
_REFUSALS = (CommandResult.FAILED, CommandResult.TEMPORARILY_REJECTED, CommandResult.DENIED)
PREARM_TEXTS = ("PreArm", "Arm", "Preflight")  # how ArduPilot and PX4 word a pre-arm failure
M = mavlink
FLIGHT_STREAMS: dict[int, float] = {  # message id -> rate [Hz] a flight needs
    M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 10.0,
    M.MAVLINK_MSG_ID_ATTITUDE: 5.0,
    M.MAVLINK_MSG_ID_MISSION_CURRENT: 2.0,
    M.MAVLINK_MSG_ID_SYS_STATUS: 2.0,
    M.MAVLINK_MSG_ID_VFR_HUD: 2.0,
    M.MAVLINK_MSG_ID_BATTERY_STATUS: 1.0,
    M.MAVLINK_MSG_ID_HOME_POSITION: 0.5,
}


async def request_streams(
    link: MavlinkLink, sysids: list[int], rates: Mapping[int, float] = FLIGHT_STREAMS
) -> dict[int, list[str]]:
    """Ask every vehicle for every message in ``rates``; returns sysid -> names it refused."""

    heard: dict[int, set[int]] = {s: set() for s in sysids}

    def on_frame(msg, raw: bytes, t_s: float) -> None:
        kinds = heard.get(msg.get_srcSystem())
        if kinds is not None:
            kinds.add(msg.get_msgId())

    async def one(sysid: int) -> list[str]:
        command = CommandClient(link, sysid)
        refused = {}
        for message_id, hz in rates.items():
            try:
                await command.set_message_interval(message_id, hz)
            except CommandTimeoutError as exc:  # deaf to commands: asking for each stream costs the same
                refused.update(dict.fromkeys(set(rates) - set(refused), exc))
                break
            except MavlinkError as exc:
                refused[message_id] = exc
        deadline = now_s() + STREAM_WAIT_S  # streamed anyway (PX4 refuses some it always sends)?
        while set(refused) - heard[sysid] and now_s() < deadline:
            await asyncio.sleep(0.05)
        missing = [m for m in refused if m not in heard[sysid]]
        for message_id in missing:
            name = mavlink.mavlink_map[message_id].msgname
            log.warning("vehicle %d: no %s stream (%s)", sysid, name, refused[message_id])
        return [mavlink.mavlink_map[m].msgname for m in missing]

    unsubscribe = link.subscribe(on_frame)
    try:
        results = await asyncio.gather(*(one(s) for s in sysids))
    finally:
        unsubscribe()
    return dict(zip(sysids, results, strict=True))


async def arm_when_ready(
    link: MavlinkLink,
    status: VehicleStatus,
    sysid: int,
    timeout_s: float,
    time_scale: float = 1.0,
    waiting: Callable[[int, str], None] | None = None,
) -> None:
    """Wait for the vehicle's pre-arm checks, then arm it; UserError with its reason at the deadline.

    ``time_scale``: vehicle seconds per wall second (a mock's speed-up). ``waiting(sysid, reason)``
    is called whenever the vehicle is not ready yet (a progress line).
    """
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout_s / time_scale
    track = status.tracks[sysid]
    command = CommandClient(link, sysid, retry_s=COMMAND_RETRY_S, retries=COMMAND_RETRIES)
    reason = ""
    while True:
        if track.prearm_ok is False:  # the vehicle says it is not ready: do not ask yet
            reason = status.reason(sysid, prefixes=PREARM_TEXTS) or "pre-arm checks not passed"
        else:
            texts_before = track.text_count
            try:
                await command.arm()
                return
            except CommandError as exc:
                if exc.result not in _REFUSALS:
                    raise
                await asyncio.sleep(min(0.3, 3.0 / time_scale))  # the reason follows the ACK
                reason = status.reason(sysid, texts_before) or f"arming {CommandResult(exc.result).name}"
        if loop.time() >= deadline:
            raise UserError(f"vehicle {sysid} could not arm within {timeout_s:.0f} s: {reason}")
        if waiting is not None:
            waiting(sysid, reason)
        await asyncio.sleep(min(ARM_RETRY_S / time_scale, max(0.0, deadline - loop.time())))


async def start_or_disarm(command: CommandClient, status: VehicleStatus, armed_here: bool) -> None:
    """MISSION_START(0, 0); on a refusal, disarm a vehicle armed for it (``armed_here``) and raise
    UserError with the vehicle's own words (module docstring)."""
    sysid = command.sysid
    texts_before = status.tracks[sysid].text_count
    try:
        await command.mission_start(0, 0)
    except UserError as exc:
        reason = status.reason(sysid, texts_before)  # before the disarm: not its "Disarming motors"
        disarmed = ""
        if armed_here:
            await command.disarm()
            disarmed = "; disarmed it again"
        said = f" (it said {reason!r})" if reason else ""
        raise UserError(f"vehicle {sysid} refused the mission start: {exc}{said}{disarmed}") from exc
