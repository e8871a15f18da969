"""Typed errors of the MAVLink services: one MissionError carrying the vehicle's MAV_MISSION_RESULT,
plus timeout, busy, protocol violations, read-back mismatch, duplicate system id and command failures.

All subclass :class:`gcs_planner.core.errors.UserError` so the CLI prints them as one line.
:func:`error_for_result` is the only place a MISSION_ACK becomes an exception; ``RESULT_TEXT``
says what each result means (a test checks it covers the whole enum).
"""

from __future__ import annotations

from gcs_planner.core.errors import UserError
from gcs_planner.wire.enums import CommandResult, MissionResult

__all__ = [
    "RESULT_TEXT",
    "BusyError",
    "CommandError",
    "CommandTimeoutError",
    "DuplicateSysidError",
    "MavlinkError",
    "MissionError",
    "MissionInputError",
    "MissionProtocolError",
    "MissionRejectedError",
    "MissionTimeoutError",
    "VerifyError",
    "command_error",
    "error_for_result",
    "mission_type_name",
]

# what each refusal means, in the words of the MAVLink spec (common.xml MAV_MISSION_RESULT)
RESULT_TEXT: dict[MissionResult, str] = {
    MissionResult.ERROR: "the vehicle refused without saying why (e.g. clear while in AUTO)",
    MissionResult.UNSUPPORTED_FRAME: "an item's coordinate frame is not supported",
    MissionResult.UNSUPPORTED: "an item's command, or the request (a partial write), is not supported",
    MissionResult.NO_SPACE: "more items than the vehicle can store",
    MissionResult.INVALID: "an item parameter is invalid",
    MissionResult.INVALID_PARAM1: "param1 is invalid",
    MissionResult.INVALID_PARAM2: "param2 is invalid",
    MissionResult.INVALID_PARAM3: "param3 is invalid",
    MissionResult.INVALID_PARAM4: "param4 is invalid",
    MissionResult.INVALID_PARAM5_X: "x / latitude is invalid",
    MissionResult.INVALID_PARAM6_Y: "y / longitude is invalid",
    MissionResult.INVALID_PARAM7: "z / altitude is invalid",
    MissionResult.INVALID_SEQUENCE: "an item came out of sequence",
    MissionResult.DENIED: "the vehicle does not accept this partner now (another GCS is uploading)",
    MissionResult.OPERATION_CANCELLED: "the transfer was cancelled (by the vehicle's timeout or by us)",
}


class MavlinkError(UserError):
    """Something a vehicle (or the link to it) did that stops an operation."""


class MissionError(MavlinkError):
    """A mission-protocol transfer failed. ``result``: the vehicle's MAV_MISSION_RESULT when it
    refused (or OPERATION_CANCELLED when we cancelled), else None; the subclasses below are the
    failures without one."""

    def __init__(
        self,
        message: str,
        *,
        sysid: int | None = None,
        mission_type: int | None = None,
        result: int | None = None,
    ) -> None:
        super().__init__(message)
        self.sysid = sysid
        self.mission_type = mission_type
        known = result is not None and result in MissionResult._value2member_map_
        self.result: MissionResult | None = MissionResult(result) if known else None


class MissionTimeoutError(MissionError):
    """No answer from the vehicle within the configured timeout and retries."""


class BusyError(MissionError):
    """A transfer of the same mission type to the same vehicle is already running on this link."""


class MissionProtocolError(MissionError):
    """The vehicle broke the protocol (e.g. requested an item outside the list)."""


class MissionInputError(MissionError):
    """The items given to a transfer are malformed (seq not 0..n-1, mixed mission types, too many)."""


class VerifyError(MissionError):
    """Read-back after upload differs from what was uploaded (beyond the rounding tolerance)."""


class MissionRejectedError(MissionError):
    """The vehicle ACKed the list, then its own check refused to fly it (PX4's feasibility check):
    it holds the list but will not start it. The message carries the autopilot's words."""


class DuplicateSysidError(MavlinkError):
    """Two endpoints answer with the same system id: the target is ambiguous and is refused."""

    def __init__(self, sysid: int, addresses: list[tuple[str, int]]) -> None:
        where = ", ".join(f"{host}:{port}" for host, port in addresses)
        super().__init__(
            f"system id {sysid} is used by {len(addresses)} vehicles ({where}); refusing to send"
        )
        self.sysid = sysid
        self.addresses = addresses


class CommandError(MavlinkError):
    """COMMAND_ACK with a result other than ACCEPTED."""

    def __init__(self, message: str, *, sysid: int, command: int, result: int) -> None:
        super().__init__(message)
        self.sysid = sysid
        self.command = command
        self.result = result


class CommandTimeoutError(MavlinkError):
    """No COMMAND_ACK after all retries."""


_MISSION_TYPE_NAMES = {0: "mission", 1: "fence", 2: "rally", 255: "all lists"}


def mission_type_name(mission_type: int) -> str:
    return _MISSION_TYPE_NAMES.get(mission_type, f"mission_type {mission_type}")


def error_for_result(result: int, *, sysid: int, mission_type: int, operation: str) -> MissionError:
    """The exception for a MISSION_ACK result; ``operation`` is e.g. "upload" or "download"."""
    what = f"vehicle {sysid} refused the {mission_type_name(mission_type)} {operation}"
    if result not in MissionResult._value2member_map_:
        return MissionError(
            f"{what}: unknown MAV_MISSION_RESULT {result}", sysid=sysid, mission_type=mission_type
        )
    member = MissionResult(result)
    text = f"{member.name} ({RESULT_TEXT[member]})" if member in RESULT_TEXT else member.name
    return MissionError(f"{what}: {text}", sysid=sysid, mission_type=mission_type, result=member)


def command_error(sysid: int, command: int, result: int, command_name: str) -> CommandError:
    """COMMAND_ACK result -> CommandError with the names spelled out."""
    name = CommandResult(result).name if result in CommandResult._value2member_map_ else f"result {result}"
    return CommandError(
        f"vehicle {sysid} answered {command_name} with {name}", sysid=sysid, command=command, result=result
    )
