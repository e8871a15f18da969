"""The content of a mission file, independent of its format (.plan JSON or QGC WPL 110 text).

A MissionFile holds what a file holds, field for field: the mission without its home item, the
planned home, fence and rally lists, WPL comments, and which lists the file defines. Frames are
the file's own numbers (QGC and Mission Planner write 0 / 3 / 10; a file saying 5 or 6 keeps it);
only lists that come from the wire or the planner (``from_items``, ``plan_mission_file``) have
their MISSION_ITEM_INT aliases 5 / 6 / 11 written as 0 / 3 / 10, the numbers files use.

DO_JUMP param1 counts as a WPL file and ArduPilot do: the home is item 0, so ``mission[i]`` is
item i + 1 (= QGroundControl's doJumpId). ``items("px4")`` drops the home and subtracts one.

What a format cannot carry is reported by its writer as ``Loss`` lines, never changed silently;
what a reader had to interpret is in ``MissionFile.notes``. Details: docs/mission-files.md.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs_planner.autopilots import Conventions
from gcs_planner.core.errors import UserError
from gcs_planner.wire.dialect import KNOWN_COMMANDS, has_position
from gcs_planner.wire.types import MissionItem, MissionType
from gcs_planner.wire.units import e7

__all__ = [
    "DO_JUMP",
    "FENCE_COMMANDS",
    "LIST_NAMES",
    "RALLY_COMMANDS",
    "Loss",
    "MissionFile",
    "MissionFileError",
    "default_home_item",
    "file_frame",
    "in_file_frames",
    "mission_type_of",
    "ranges",
    "unknown_command_notes",
]

_TO_FILE = {
    mavlink.MAV_FRAME_GLOBAL_INT: mavlink.MAV_FRAME_GLOBAL,
    mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT: mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT,
    mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT: mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT,
}
# 5000-5004 (common.xml) and ArduPilot's NAV_FENCE_HOME_CIRCLE_INCLUSION (5005)
FENCE_COMMANDS = frozenset(range(5000, 5006))
RALLY_COMMANDS = frozenset({mavlink.MAV_CMD_NAV_RALLY_POINT})
DO_JUMP = mavlink.MAV_CMD_DO_JUMP
LIST_NAMES = {MissionType.MISSION: "mission", MissionType.FENCE: "fence", MissionType.RALLY: "rally"}


class MissionFileError(UserError, ValueError):
    """A mission file cannot be read; the message names the file, the place and the value."""


@dataclass(frozen=True)
class Loss:
    """What a format cannot carry: ``fields`` of items ``indexes`` of list ``part`` and why.

    part: "mission", "home", "fence", "rally", "comments" or "settings" (firmware, vehicle, speeds).
    """

    part: str
    fields: tuple[str, ...]
    indexes: tuple[int, ...]
    reason: str

    def __str__(self) -> str:
        where = f"{self.part} item{'s' if len(self.indexes) > 1 else ''} {ranges(self.indexes)}"
        return f"{where if self.indexes else self.part}: {', '.join(self.fields)} {self.reason}"


def ranges(indexes: tuple[int, ...]) -> str:
    """(0, 1, 2, 5) -> '0-2, 5'."""
    out: list[str] = []
    for i in sorted(indexes):
        if out and i == int(out[-1].split("-")[-1]) + 1:
            out[-1] = f"{out[-1].split('-')[0]}-{i}"
        else:
            out.append(str(i))
    return ", ".join(out)


def file_frame(frame: int) -> int:
    """A MISSION_ITEM_INT alias frame (5, 6, 11) -> the number files use (0, 3, 10)."""
    return _TO_FILE.get(frame, frame)


def in_file_frames(items: list[MissionItem]) -> list[MissionItem]:
    """Items from the wire or the planner with the frame numbers QGC and Mission Planner write."""
    return [replace(item, frame=file_frame(item.frame)) for item in items]


def default_home_item() -> MissionItem:
    """Row 0 as Mission Planner writes it: NAV_WAYPOINT in MAV_FRAME_GLOBAL, current 1."""
    return MissionItem(0, mavlink.MAV_FRAME_GLOBAL, mavlink.MAV_CMD_NAV_WAYPOINT, current=1)


@dataclass
class MissionFile:
    """Mission (no home item), planned home (lat [deg], lon [deg], alt [m AMSL]), fence, rally.

    home_item: a WPL file's row 0 as written (frame, command, params), if any.
    comments: a WPL file's ``#`` lines as (data rows before it, line).
    lists: the lists the file defines (a .plan all three, a WPL file one); upload sends these.
    notes: what the reader interpreted (null params, unknown commands), one line each.
    """

    mission: list[MissionItem] = field(default_factory=list)
    home: tuple[float, float, float] | None = None
    fence: list[MissionItem] = field(default_factory=list)
    rally: list[MissionItem] = field(default_factory=list)
    firmware_type: int = mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA
    vehicle_type: int = mavlink.MAV_TYPE_QUADROTOR
    cruise_speed_mps: float = 15.0
    hover_speed_mps: float = 5.0
    home_item: MissionItem | None = None
    comments: list[tuple[int, str]] = field(default_factory=list)
    lists: frozenset[MissionType] = frozenset(LIST_NAMES)
    notes: list[str] = field(default_factory=list)

    def items(self, autopilot: str = Conventions.ARDUPILOT) -> list[MissionItem]:
        """The mission to upload. ArduPilot: the home item at seq 0 (row 0 as written, at the
        planned home if there is one; ArduPilot replaces it with its own home). PX4: no home item,
        DO_JUMP targets one lower, positionless commands in MAV_FRAME_MISSION (PX4 refuses them
        in a global frame: mavlink_mission.cpp parse_mavlink_mission_item)."""
        body = [replace(item, current=0) for item in self.mission]
        if autopilot == Conventions.ARDUPILOT:
            home = self.home_item or default_home_item()
            if self.home is not None:
                lat, lon, alt = self.home
                home = replace(home, x=e7(lat), y=e7(lon), z=float(alt))
            body.insert(0, home)
        elif autopilot == Conventions.PX4:
            body = [_for_px4(item) for item in body]
        else:
            raise MissionFileError(
                f"autopilot must be one of {[str(c) for c in Conventions]}, got {autopilot!r}"
            )
        return [replace(item, seq=i, current=int(i == 0)) for i, item in enumerate(body)]

    def list_items(
        self, mission_type: MissionType, autopilot: str = Conventions.ARDUPILOT
    ) -> list[MissionItem]:
        """The items of one list as uploaded (the mission via ``items``)."""
        if mission_type == MissionType.MISSION:
            return self.items(autopilot)
        return list(self.fence if mission_type == MissionType.FENCE else self.rally)

    @classmethod
    def from_items(
        cls,
        items: list[MissionItem],
        autopilot: str = Conventions.ARDUPILOT,
        home: tuple[float, float, float] | None = None,
        fence: list[MissionItem] | None = None,
        rally: list[MissionItem] | None = None,
        **kwargs,
    ) -> MissionFile:
        """An uploadable list -> MissionFile: ArduPilot's seq 0 becomes the home (unless ``home``
        is given; a seq 0 at 0, 0 is no home), PX4's DO_JUMP targets one higher. Frames are kept."""
        mission = list(items)
        if autopilot == Conventions.ARDUPILOT and mission:
            first, mission = mission[0], mission[1:]
            kwargs.setdefault("home_item", first)
            if home is None and (first.x, first.y) != (0, 0):
                home = (first.x / 1e7, first.y / 1e7, float(first.z))
        elif autopilot == Conventions.PX4:
            mission = [_jump_shifted(item, +1) for item in mission]
        mission = [replace(item, seq=i, current=0) for i, item in enumerate(mission)]
        firmware = (
            mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA
            if autopilot == Conventions.ARDUPILOT
            else mavlink.MAV_AUTOPILOT_PX4
        )
        kwargs.setdefault("firmware_type", firmware)
        return cls(
            mission=mission,
            home=home,
            fence=list(fence or []),
            rally=list(rally or []),
            **kwargs,
        )


def _jump_shifted(item: MissionItem, by: int) -> MissionItem:
    if item.command != DO_JUMP:
        return item
    return replace(item, param1=float(item.param1 + by))


def _for_px4(item: MissionItem) -> MissionItem:
    item = _jump_shifted(item, -1)
    if not has_position(item.command) and item.frame != mavlink.MAV_FRAME_MISSION:
        item = replace(item, frame=mavlink.MAV_FRAME_MISSION)
    return item


def mission_type_of(commands: list[int]) -> MissionType:
    """Guess a list's mission type from its commands (WPL files do not say)."""
    if commands and all(c in FENCE_COMMANDS for c in commands):
        return MissionType.FENCE
    if commands and all(c in RALLY_COMMANDS for c in commands):
        return MissionType.RALLY
    return MissionType.MISSION


def unknown_command_notes(items: list[MissionItem], part: str) -> list[str]:
    """One note per command id the pinned MAVLink dialect lacks: kept and sent as written."""
    unknown: dict[int, list[int]] = {}
    for i, item in enumerate(items):
        if item.command not in KNOWN_COMMANDS:
            unknown.setdefault(item.command, []).append(i)
    return [
        f"{part} item{'s' if len(idx) > 1 else ''} {ranges(tuple(idx))}: command {cmd} is not in the MAVLink"
        " dialect gcs-planner knows (pymavlink ardupilotmega); kept and sent as written,"
        " x/y as latitude/longitude"
        for cmd, idx in unknown.items()
    ]
