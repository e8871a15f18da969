"""What the pinned MAVLink dialect (pymavlink's ardupilotmega, which includes common.xml) says
about mission commands and frames: which ids it knows and which commands carry a position."""

from __future__ import annotations

import functools

from pymavlink.dialects.v20 import ardupilotmega as mavlink

__all__ = ["KNOWN_COMMANDS", "KNOWN_FRAMES", "POSITIONAL_COMMANDS", "has_position", "nan_has_meaning"]

KNOWN_COMMANDS = frozenset(k for k, v in mavlink.enums["MAV_CMD"].items() if not v.name.endswith("ENUM_END"))
KNOWN_FRAMES = frozenset(k for k, v in mavlink.enums["MAV_FRAME"].items() if not v.name.endswith("ENUM_END"))

# MAV_CMDs with hasLocation="true" in MAVLink common.xml (param5/6 latitude/longitude or x/y);
# every other known command carries params 5/6 as plain numbers (x, y of MISSION_ITEM_INT unscaled)
POSITIONAL_COMMANDS = frozenset(
    {16, 17, 18, 19, 21, 22, 23, 24, 25, 31, 34, 35, 36, 80, 81, 82, 84, 85, 94, 179, 188, 189, 192, 195}
    | {201, 252, 611, 4001, 4501, 5100, 30001, 43003}
    | set(range(5000, 5005))
    | set(range(31000, 31010))
)


def has_position(command: int) -> bool:
    """x/y are a position: hasLocation in MAVLink, or a command the pinned dialect does not know
    (MISSION_ITEM_INT's default meaning of x/y; ArduPilot's CONDITION_LOCATION 116 is one)."""
    return command in POSITIONAL_COMMANDS or command not in KNOWN_COMMANDS


_UNUSED = ("", "empty", "reserved", "unused")


@functools.lru_cache(maxsize=4096)
def nan_has_meaning(command: int, param: int) -> bool:
    """NaN in param ``param`` (1..4) of ``command`` means something: its description mentions NaN,
    the param is Empty / Reserved, or the dialect does not know the command (it may be the vehicle's)."""
    entry = mavlink.enums["MAV_CMD"].get(command)
    if entry is None or command not in KNOWN_COMMANDS:
        return True
    text = (getattr(entry, "param", {}) or {}).get(param, "").strip()
    return "nan" in text.lower() or text.lower().rstrip(".").split(" (")[0] in _UNUSED
