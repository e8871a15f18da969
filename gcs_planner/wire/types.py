"""Typed MAVLink values shared by the client, the mock autopilot and the file formats."""

from __future__ import annotations

from dataclasses import dataclass, replace
from enum import IntEnum

__all__ = ["GLOBAL_FRAMES", "MissionItem", "MissionType"]

GLOBAL_FRAMES = frozenset({0, 3, 5, 6, 10, 11})  # MAV_FRAMEs whose x, y are latitude, longitude
INT32_MAX = 2**31 - 1


class MissionType(IntEnum):
    """MAV_MISSION_TYPE: which of a vehicle's three lists a transfer is about."""

    MISSION = 0
    FENCE = 1
    RALLY = 2
    ALL = 255  # only valid in MISSION_CLEAR_ALL


@dataclass(frozen=True)
class MissionItem:
    """One MISSION_ITEM_INT, field for field.

    x, y: latitude, longitude [degE7] for global frames (local frames: metres x 1e4).
    z: altitude [m] in the item's frame (GLOBAL_RELATIVE_ALT_INT: above home).
    param1..param4: command parameters as MAV_CMD defines them.
    """

    seq: int
    frame: int
    command: int
    current: int = 0
    autocontinue: int = 1
    param1: float = 0.0
    param2: float = 0.0
    param3: float = 0.0
    param4: float = 0.0
    x: int = 0
    y: int = 0
    z: float = 0.0
    mission_type: int = MissionType.MISSION

    @property
    def lat_deg(self) -> float:
        return self.x / 1e7

    @property
    def lon_deg(self) -> float:
        return self.y / 1e7

    @classmethod
    def from_message(cls, msg, mission_type: int | None = None) -> MissionItem:
        """From a received MISSION_ITEM_INT, or a legacy float MISSION_ITEM (degrees -> degE7,
        local metres -> x 1e4); ``mission_type`` overrides the message's. ValueError naming the
        item for a legacy x or y that MISSION_ITEM_INT's int32 cannot hold (NaN, inf, too large)."""
        x, y = msg.x, msg.y
        if msg.get_type() == "MISSION_ITEM":
            scale = 1e7 if msg.frame in GLOBAL_FRAMES else 1e4
            for name, value in (("x", x), ("y", y)):
                if not abs(value * scale) <= INT32_MAX:  # also NaN
                    raise ValueError(
                        f"item {msg.seq}: {name} = {value} in a float MISSION_ITEM does not fit"
                        f" MISSION_ITEM_INT's int32 ({name} x {scale:g})"
                    )
            x, y = round(x * scale), round(y * scale)
        return cls(
            msg.seq, msg.frame, msg.command, msg.current, msg.autocontinue,
            msg.param1, msg.param2, msg.param3, msg.param4, int(x), int(y), msg.z,
            msg.mission_type if mission_type is None else mission_type,
        )  # fmt: skip

    def fields(self) -> tuple:
        """seq .. mission_type in MISSION_ITEM_INT's argument order (after the two targets).

        Spelled out: dataclasses.astuple deep-copies every field and cost ~130 us per item, the
        largest share of an upload's CPU time."""
        return (
            self.seq, self.frame, self.command, self.current, self.autocontinue,
            self.param1, self.param2, self.param3, self.param4, self.x, self.y, self.z, self.mission_type,
        )  # fmt: skip

    def with_seq(self, seq: int) -> MissionItem:
        return replace(self, seq=seq)
