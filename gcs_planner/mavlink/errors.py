"""Typed errors of the MAVLink services: one class per MAV_MISSION_RESULT, plus timeout, busy,
protocol violations, read-back mismatch, duplicate system id and command failures.

All subclass :class:`gcs_planner.errors.UserError` so the CLI prints them as one line. The one table
:data:`RESULT_ERRORS` maps every non-ACCEPTED MissionResult to its class (a test checks it covers the
whole pymavlink enum); :func:`error_for_result` is the only place a MISSION_ACK becomes an exception.
"""

from __future__ import annotations

from gcs_planner.errors import UserError
from gcs_planner.mavlink.enums import CommandResult, MissionResult

__all__ = [
    "BusyError",
    "CommandError",
    "CommandTimeoutError",
    "DeniedError",
    "DuplicateSysidError",
    "GenericMissionError",
    "InvalidItemError",
    "InvalidParam1Error",
    "InvalidParam2Error",
    "InvalidParam3Error",
    "InvalidParam4Error",
    "InvalidParam5XError",
    "InvalidParam6YError",
    "InvalidParam7Error",
    "InvalidParamError",
    "InvalidSequenceError",
    "MavlinkError",
    "MissionError",
    "MissionInputError",
    "MissionProtocolError",
    "MissionRejectedError",
    "MissionTimeoutError",
    "NoSpaceError",
    "OperationCancelledError",
    "RESULT_ERRORS",
    "UnsupportedCommandError",
    "UnsupportedFrameError",
    "VerifyError",
    "command_error",
    "error_for_result",
    "mission_type_name",
]


class MavlinkError(UserError):
    """Something a vehicle (or the link to it) did that stops an operation."""


class MissionError(MavlinkError):
    """A mission-protocol transfer failed. ``result`` is the vehicle's MAV_MISSION_RESULT, if any."""

    result: MissionResult | None = None

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
        if result is not None:
            self.result = MissionResult(result) if result in MissionResult._value2member_map_ else None


class GenericMissionError(MissionError):
    """MAV_MISSION_ERROR: the vehicle refused without saying why (e.g. clear while in AUTO)."""


class UnsupportedFrameError(MissionError):
    """MAV_MISSION_UNSUPPORTED_FRAME: an item's coordinate frame is not supported."""


class UnsupportedCommandError(MissionError):
    """MAV_MISSION_UNSUPPORTED: an item's command, or the request (a partial write), is not supported."""


class NoSpaceError(MissionError):
    """MAV_MISSION_NO_SPACE: more items than the vehicle can store."""


class InvalidItemError(MissionError):
    """MAV_MISSION_INVALID: an item parameter is invalid."""


class InvalidParamError(InvalidItemError):
    """MAV_MISSION_INVALID_PARAMn: parameter ``param_index`` (1..7; 5 = x/lat, 6 = y/lon, 7 = z) invalid."""

    param_index = 0


class InvalidParam1Error(InvalidParamError):
    """MAV_MISSION_INVALID_PARAM1."""

    param_index = 1


class InvalidParam2Error(InvalidParamError):
    """MAV_MISSION_INVALID_PARAM2."""

    param_index = 2


class InvalidParam3Error(InvalidParamError):
    """MAV_MISSION_INVALID_PARAM3."""

    param_index = 3


class InvalidParam4Error(InvalidParamError):
    """MAV_MISSION_INVALID_PARAM4."""

    param_index = 4


class InvalidParam5XError(InvalidParamError):
    """MAV_MISSION_INVALID_PARAM5_X (latitude / x)."""

    param_index = 5


class InvalidParam6YError(InvalidParamError):
    """MAV_MISSION_INVALID_PARAM6_Y (longitude / y)."""

    param_index = 6


class InvalidParam7Error(InvalidParamError):
    """MAV_MISSION_INVALID_PARAM7 (altitude / z)."""

    param_index = 7


class InvalidSequenceError(MissionError):
    """MAV_MISSION_INVALID_SEQUENCE as a final answer (mid-upload it is recoverable and not raised)."""


class DeniedError(MissionError):
    """MAV_MISSION_DENIED: the vehicle does not accept this partner now (another GCS is uploading)."""


class OperationCancelledError(MissionError):
    """MAV_MISSION_OPERATION_CANCELLED: the transfer was cancelled (by the vehicle's timeout or by us)."""


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


RESULT_ERRORS: dict[MissionResult, type[MissionError]] = {
    MissionResult.ERROR: GenericMissionError,
    MissionResult.UNSUPPORTED_FRAME: UnsupportedFrameError,
    MissionResult.UNSUPPORTED: UnsupportedCommandError,
    MissionResult.NO_SPACE: NoSpaceError,
    MissionResult.INVALID: InvalidItemError,
    MissionResult.INVALID_PARAM1: InvalidParam1Error,
    MissionResult.INVALID_PARAM2: InvalidParam2Error,
    MissionResult.INVALID_PARAM3: InvalidParam3Error,
    MissionResult.INVALID_PARAM4: InvalidParam4Error,
    MissionResult.INVALID_PARAM5_X: InvalidParam5XError,
    MissionResult.INVALID_PARAM6_Y: InvalidParam6YError,
    MissionResult.INVALID_PARAM7: InvalidParam7Error,
    MissionResult.INVALID_SEQUENCE: InvalidSequenceError,
    MissionResult.DENIED: DeniedError,
    MissionResult.OPERATION_CANCELLED: OperationCancelledError,
}

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
    cls = RESULT_ERRORS.get(member, MissionError)
    doc = (cls.__doc__ or "").split(":", 1)[-1].strip().rstrip(".")
    return cls(f"{what}: {member.name} ({doc})", sysid=sysid, mission_type=mission_type, result=member)


def command_error(sysid: int, command: int, result: int, command_name: str) -> CommandError:
    """COMMAND_ACK result -> CommandError with the names spelled out."""
    name = CommandResult(result).name if result in CommandResult._value2member_map_ else f"result {result}"
    return CommandError(
        f"vehicle {sysid} answered {command_name} with {name}", sysid=sysid, command=command, result=result
    )
