"""The content of a mission file, independent of its format (.plan JSON or QGC WPL 110 text).

A file holds a mission without its home item plus the planned home, and optionally fence and
rally lists. ``MissionFile.items(autopilot)`` gives the list to upload: ArduPilot's with the home
item at seq 0, PX4's without. ``MissionFile.from_items`` does the reverse.

Frames: MISSION_ITEM_INT lists use the *_INT frame numbers (GLOBAL_RELATIVE_ALT_INT 6,
GLOBAL_TERRAIN_ALT_INT 11); QGroundControl and Mission Planner files use the float numbers
(GLOBAL_RELATIVE_ALT 3, GLOBAL_TERRAIN_ALT 10), so writers map 6 -> 3, 11 -> 10, 5 -> 0 and readers
map 3 -> 6, 10 -> 11. MAV_FRAME_GLOBAL (0) stays 0: it is valid in MISSION_ITEM_INT and is what
ArduPilot uses for home, so items written and read back are equal field for field.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs_planner.errors import UserError
from gcs_planner.mavlink.items import deg_to_e7
from gcs_planner.mavlink.types import MissionItem, MissionType
from gcs_planner.plan import Plan, VehiclePlan

__all__ = [
    "MissionFile",
    "MissionFileError",
    "file_frame",
    "item_frame",
    "load_mission_file",
    "load_plan_json",
    "mission_input",
    "mission_type_of",
    "plan_mission_file",
    "save_mission_file",
    "select_vehicles",
    "wpl_rows",
]

_TO_FILE = {
    mavlink.MAV_FRAME_GLOBAL_INT: mavlink.MAV_FRAME_GLOBAL,
    mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT: mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT,
    mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT: mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT,
}
_FROM_FILE = {
    mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT: mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
    mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT: mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT,
}
FENCE_COMMANDS = frozenset(range(5000, 5005))
RALLY_COMMANDS = frozenset({mavlink.MAV_CMD_NAV_RALLY_POINT})


class MissionFileError(UserError, ValueError):
    """A mission file cannot be read; the message names the file, the place and the value."""


def file_frame(frame: int) -> int:
    """MISSION_ITEM_INT frame -> the frame number files store."""
    return _TO_FILE.get(frame, frame)


def item_frame(frame: int) -> int:
    """A file's frame number -> the MISSION_ITEM_INT frame."""
    return _FROM_FILE.get(frame, frame)


@dataclass
class MissionFile:
    """Mission (no home item), planned home (lat [deg], lon [deg], alt [m AMSL]), fence and rally."""

    mission: list[MissionItem] = field(default_factory=list)
    home: tuple[float, float, float] | None = None
    fence: list[MissionItem] = field(default_factory=list)
    rally: list[MissionItem] = field(default_factory=list)
    firmware_type: int = mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA
    vehicle_type: int = mavlink.MAV_TYPE_QUADROTOR
    cruise_speed_mps: float = 15.0
    hover_speed_mps: float = 5.0
    home_item: MissionItem | None = None  # a WPL file's row 0 as written (frame, params), if any

    def items(self, autopilot: str = "ardupilot") -> list[MissionItem]:
        """The mission to upload: home at seq 0 for ArduPilot (needs ``home``), none for PX4."""
        body = [replace(item, current=0) for item in self.mission]
        if autopilot == "ardupilot":
            if self.home is None:
                raise MissionFileError(
                    "the file has no planned home position, which ArduPilot needs at seq 0"
                )
            lat, lon, alt = self.home
            home = self.home_item or MissionItem(0, mavlink.MAV_FRAME_GLOBAL, mavlink.MAV_CMD_NAV_WAYPOINT)
            home = replace(home, x=int(deg_to_e7(lat)), y=int(deg_to_e7(lon)), z=float(alt))
            body.insert(0, home)
        elif autopilot != "px4":
            raise MissionFileError(f"autopilot must be 'ardupilot' or 'px4', got {autopilot!r}")
        return [replace(item, seq=i, current=int(i == 0)) for i, item in enumerate(body)]

    @classmethod
    def from_items(
        cls,
        items: list[MissionItem],
        autopilot: str = "ardupilot",
        home: tuple[float, float, float] | None = None,
        fence: list[MissionItem] | None = None,
        rally: list[MissionItem] | None = None,
        **kwargs,
    ) -> MissionFile:
        """Split an uploadable list: ArduPilot's seq 0 becomes ``home`` unless one is given."""
        mission = list(items)
        if autopilot == "ardupilot" and mission:
            first, mission = mission[0], mission[1:]
            kwargs.setdefault("home_item", first)
            if home is None:
                home = (first.x / 1e7, first.y / 1e7, float(first.z))
        mission = [replace(item, seq=i) for i, item in enumerate(mission)]
        firmware = (
            mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA if autopilot == "ardupilot" else mavlink.MAV_AUTOPILOT_PX4
        )
        kwargs.setdefault("firmware_type", firmware)
        return cls(mission=mission, home=home, fence=list(fence or []), rally=list(rally or []), **kwargs)


def mission_type_of(commands: list[int]) -> MissionType:
    """Guess a list's mission type from its commands (WPL files do not say)."""
    if commands and all(c in FENCE_COMMANDS for c in commands):
        return MissionType.FENCE
    if commands and all(c in RALLY_COMMANDS for c in commands):
        return MissionType.RALLY
    return MissionType.MISSION


def load_mission_file(path: str | Path, autopilot: str = "ardupilot") -> MissionFile:
    """Read a .plan (QGroundControl) or .waypoints / .txt / .wpl (QGC WPL 110) file."""
    from gcs_planner.mavlink import planfile, wpl

    path = Path(path)
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise MissionFileError(f"{path}: no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise MissionFileError(f"{path}: cannot read: {exc}") from None
    if text.lstrip().startswith("{"):
        return planfile.loads_plan(text, where=str(path))
    if text.lstrip().startswith("QGC WPL"):
        return wpl.loads_wpl(text, autopilot=autopilot, where=str(path))
    raise MissionFileError(f"{path}: neither a QGroundControl .plan (JSON) nor a 'QGC WPL 110' file")


def save_mission_file(path: str | Path, mission_file: MissionFile, autopilot: str = "ardupilot") -> None:
    """Write ``.plan`` as QGroundControl JSON, anything else as QGC WPL 110 (mission list only)."""
    from gcs_planner.mavlink import planfile, wpl

    path = Path(path)
    if path.suffix.lower() == ".plan":
        path.write_text(planfile.dumps_plan(mission_file))
    else:
        path.write_text(wpl.dumps_wpl(wpl_rows(mission_file)))


def wpl_rows(mission_file: MissionFile) -> list[MissionItem]:
    """The rows of a WPL file: home at row 0 (zeros when the file has none, as QGroundControl)."""
    if mission_file.home is None:
        mission_file = replace(mission_file, home=(0.0, 0.0, 0.0))
    return mission_file.items("ardupilot")


def plan_mission_file(vehicle_plan: VehiclePlan, origin, autopilot: str = "ardupilot") -> MissionFile:
    """One vehicle of a Plan -> MissionFile (mission items from plan_to_items, home = plan origin)."""
    from gcs_planner.mavlink.items import plan_to_items

    items = plan_to_items(vehicle_plan, origin, autopilot)
    fixed_wing = vehicle_plan.vehicle_type == "fixed_wing"
    speeds = vehicle_plan.speeds_mps[1:] if len(vehicle_plan.speeds_mps) > 1 else [15.0]
    cruise = float(max(speeds))
    return MissionFile.from_items(
        items,
        autopilot,
        home=(origin.lat_deg, origin.lon_deg, origin.alt_m),
        vehicle_type=mavlink.MAV_TYPE_FIXED_WING if fixed_wing else mavlink.MAV_TYPE_QUADROTOR,
        cruise_speed_mps=cruise,
        hover_speed_mps=cruise,
    )


def load_plan_json(path: str | Path) -> Plan:
    """plan.json (from `gcs-planner plan`) -> Plan, with one-line errors."""
    try:
        return Plan.load(path)
    except FileNotFoundError:
        raise MissionFileError(f"{path}: no such file") from None
    except (ValueError, KeyError, TypeError) as exc:
        raise MissionFileError(f"{path}: not a valid plan.json: {exc!s}") from None


def select_vehicles(
    plan: Plan, vehicle_ids: list[str] | None = None, sysid: int | None = None
) -> list[VehiclePlan]:
    """The plan's vehicles named in ``vehicle_ids`` (all if None), or the one with ``sysid``."""
    if vehicle_ids:
        known = {v.vehicle_id: v for v in plan.vehicles}
        missing = [v for v in vehicle_ids if v not in known]
        if missing:
            raise MissionFileError(f"vehicle {missing[0]!r} is not in the plan (it has {sorted(known)})")
        return [known[v] for v in vehicle_ids]
    if sysid is not None:
        matches = [v for v in plan.vehicles if v.sysid == sysid]
        if not matches:
            raise MissionFileError(
                f"no vehicle with sysid {sysid} in the plan (it has {[v.sysid for v in plan.vehicles]})"
            )
        return matches[:1]
    return list(plan.vehicles)


def mission_input(
    path: str | Path, autopilot: str = "ardupilot", vehicle: str | None = None, sysid: int | None = None
) -> MissionFile:
    """A .plan, a WPL file, or plan.json (+ vehicle id, else the vehicle with ``sysid``) -> MissionFile."""
    path = Path(path)
    if path.suffix.lower() == ".json":
        plan = load_plan_json(path)
        (vp,) = select_vehicles(plan, [vehicle] if vehicle else None, sysid=sysid if not vehicle else None)[
            :1
        ]
        return plan_mission_file(vp, plan.origin, autopilot)
    return load_mission_file(path, autopilot=autopilot)
