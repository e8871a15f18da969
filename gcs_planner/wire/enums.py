"""MAVLink enums the mission and command services speak, plus autopilot flight-mode tables.

Values mirror the MAVLink XML (checked against pymavlink's dialect in tests/test_mission_enums.py), so
a value off the wire converts with ``MissionResult(msg.type)``. Flight-mode numbers are the autopilots'
own custom_mode encodings (ArduCopter/ArduPlane ``mode`` numbers; PX4 main/sub mode packed into bits
16-23 / 24-31), the single place the GCS and the mock autopilot take them from.
"""

from __future__ import annotations

from enum import IntEnum

__all__ = [
    "ARDUCOPTER_MODES",
    "ARDUPLANE_MODES",
    "PX4_MODES",
    "Autopilot",
    "CommandResult",
    "MissionResult",
    "MissionState",
    "px4_custom_mode",
]


class MissionResult(IntEnum):
    """MAV_MISSION_RESULT: the type field of MISSION_ACK."""

    ACCEPTED = 0  # mission accepted OK
    ERROR = 1  # generic error / not accepting mission commands at all right now
    UNSUPPORTED_FRAME = 2  # coordinate frame is not supported
    UNSUPPORTED = 3  # command is not supported
    NO_SPACE = 4  # mission items exceed storage space
    INVALID = 5  # one of the parameters has an invalid value
    INVALID_PARAM1 = 6  # param1 has an invalid value
    INVALID_PARAM2 = 7  # param2 has an invalid value
    INVALID_PARAM3 = 8  # param3 has an invalid value
    INVALID_PARAM4 = 9  # param4 has an invalid value
    INVALID_PARAM5_X = 10  # x / param5 has an invalid value
    INVALID_PARAM6_Y = 11  # y / param6 has an invalid value
    INVALID_PARAM7 = 12  # z / param7 has an invalid value
    INVALID_SEQUENCE = 13  # received a mission item out of sequence
    DENIED = 14  # not accepting any mission commands from this communication partner
    OPERATION_CANCELLED = 15  # current mission operation cancelled (e.g. upload, download)


class MissionState(IntEnum):
    """MISSION_STATE, streamed in MISSION_CURRENT.mission_state."""

    UNKNOWN = 0  # the vehicle does not report it
    NO_MISSION = 1  # no mission on the vehicle
    NOT_STARTED = 2  # mission loaded, never started
    ACTIVE = 3  # executing (AUTO)
    PAUSED = 4  # started, vehicle out of AUTO
    COMPLETE = 5  # last item executed


class CommandResult(IntEnum):
    """MAV_RESULT: the result field of COMMAND_ACK."""

    ACCEPTED = 0  # command valid and executed
    TEMPORARILY_REJECTED = 1  # valid, but not now (e.g. arming checks): retry later
    DENIED = 2  # invalid here (e.g. parameters out of range)
    UNSUPPORTED = 3  # command not known
    FAILED = 4  # valid, execution failed
    IN_PROGRESS = 5  # executing; a final ACK follows
    CANCELLED = 6  # cancelled by COMMAND_CANCEL
    COMMAND_LONG_ONLY = 7  # must be sent as COMMAND_LONG
    COMMAND_INT_ONLY = 8  # must be sent as COMMAND_INT
    COMMAND_UNSUPPORTED_MAV_FRAME = 9  # frame not supported


class Autopilot(IntEnum):
    """MAV_AUTOPILOT values of the autopilots we talk to (HEARTBEAT.autopilot)."""

    GENERIC = 0
    ARDUPILOTMEGA = 3
    INVALID = 8  # a GCS or other non-flight-controller component
    PX4 = 12


def px4_custom_mode(main_mode: int, sub_mode: int = 0) -> int:
    """PX4 custom_mode as sent in HEARTBEAT: main mode in bits 16-23, sub mode in bits 24-31."""
    return (main_mode << 16) | (sub_mode << 24)


# Upper-case mode names the CLI and command client accept. ArduCopter numbers from ArduCopter/mode.h.
ARDUCOPTER_MODES: dict[str, int] = {
    "STABILIZE": 0,
    "AUTO": 3,
    "GUIDED": 4,
    "LOITER": 5,
    "RTL": 6,
    "LAND": 9,
}
# ArduPlane (plane/mode.h). Plain fixed wings have no LAND mode: they land through a mission item.
ARDUPLANE_MODES: dict[str, int] = {
    "MANUAL": 0,
    "AUTO": 10,
    "RTL": 11,
    "LOITER": 12,
    "TAKEOFF": 13,
    "GUIDED": 15,
}
# PX4 (px4_custom_mode.h): main 1 MANUAL, 3 POSCTL, 4 AUTO (sub 2 TAKEOFF, 3 LOITER, 4 MISSION, 5 RTL,
# 6 LAND), 6 OFFBOARD. PX4 has no GUIDED: OFFBOARD is its external-setpoint mode.
PX4_MODES: dict[str, int] = {
    "MANUAL": px4_custom_mode(1),
    "POSCTL": px4_custom_mode(3),
    "TAKEOFF": px4_custom_mode(4, 2),
    "LOITER": px4_custom_mode(4, 3),
    "AUTO": px4_custom_mode(4, 4),
    "RTL": px4_custom_mode(4, 5),
    "LAND": px4_custom_mode(4, 6),
    "GUIDED": px4_custom_mode(6),
}
