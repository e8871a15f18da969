"""Mission files on disk: read any format by content, write by suffix, and plans as mission files.

The formats: planfile (QGroundControl .plan JSON), wpl (QGC WPL 110), legacy_files (MAVProxy /
Mission Planner fence and rally lists); what a file holds is a MissionFile (mission_file.py).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs_planner.autopilots import Conventions
from gcs_planner.core.errors import UserError
from gcs_planner.core.validation import MAX_INPUT_BYTES, write_text_atomic
from gcs_planner.missions import legacy_files, planfile, wpl
from gcs_planner.missions.mission_file import (
    FENCE_COMMANDS,
    Loss,
    MissionFile,
    MissionFileError,
    file_frame,
    in_file_frames,
    mission_type_of,
    ranges,
    unknown_command_notes,
)
from gcs_planner.wire.dialect import has_position
from gcs_planner.wire.types import MissionType

if TYPE_CHECKING:  # numpy-backed; imported only by the readers of plan.json
    from gcs_planner.model.plan import Plan, VehiclePlan

__all__ = [
    "FENCE_COMMANDS",
    "Loss",
    "MissionFile",
    "MissionFileError",
    "file_frame",
    "in_file_frames",
    "load_mission_file",
    "load_plan_json",
    "mission_input",
    "mission_type_of",
    "plan_mission_file",
    "ranges",
    "save_mission_file",
    "select_vehicles",
    "unknown_command_notes",
]


def load_mission_file(path: str | Path, autopilot: str = Conventions.ARDUPILOT) -> MissionFile:
    """Read a .plan / .mission (QGroundControl), a QGC WPL 110 file (.waypoints / .txt), or an
    older MAVProxy / Mission Planner fence or rally list (legacy_files), by content."""
    path = Path(path)
    try:
        with open(path, "rb") as f:  # at most one byte over the limit, whatever the file is
            data = f.read(MAX_INPUT_BYTES + 1)
        if len(data) > MAX_INPUT_BYTES:
            raise MissionFileError(f"{path} is over {MAX_INPUT_BYTES // 2**20} MiB, a mission file's limit")
        text = data.decode("utf-8-sig")  # a byte-order mark (Windows editors) is no content
    except FileNotFoundError:
        raise MissionFileError(f"{path}: no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise MissionFileError(f"{path}: cannot read: {exc}") from None
    if text.lstrip().startswith("{"):
        return planfile.loads_plan(text, where=str(path))
    if text.lstrip().startswith("QGC WPL"):
        return wpl.loads_wpl(text, autopilot=autopilot, where=str(path))
    if legacy_files.is_legacy_fence(text):
        return legacy_files.loads_legacy_fence(text, where=str(path))
    if legacy_files.is_legacy_rally(text):
        return legacy_files.loads_legacy_rally(text, where=str(path))
    raise MissionFileError(
        f"{path}: neither a QGroundControl .plan (JSON), a 'QGC WPL 110' file, nor a fence or rally list"
    )


def save_mission_file(path: str | Path, mission_file: MissionFile) -> list[Loss]:
    """Write ``.plan`` as QGroundControl JSON, anything else as QGC WPL 110; return what the
    format could not carry (the caller prints it)."""
    path = Path(path)
    _check_storable(mission_file, path)
    if path.suffix.lower() == ".plan":
        text, losses = planfile.dumps_plan(mission_file), planfile.plan_losses(mission_file)
    else:
        text, losses = wpl.dumps_mission_file(mission_file), wpl.wpl_losses(mission_file)
    write_text_atomic(path, text)  # a failed write leaves no half file
    return losses


def _check_storable(mf: MissionFile, path: Path) -> None:
    """MissionFileError, and no file written, for what a vehicle may hold but no mission file can:
    an infinite value (JSON cannot hold it, a WPL "inf" is refused when read back), a home that is
    not three finite numbers, or a NaN altitude of an item with a position (a .plan's null is
    refused when read back, a WPL writes 0: a waypoint on the ground)."""
    if mf.home is not None and not all(math.isfinite(v) for v in mf.home):
        raise MissionFileError(f"{path}: home {mf.home} cannot be stored in a mission file; nothing written")
    lists = [
        (name, i, it) for name in ("mission", "fence", "rally") for i, it in enumerate(getattr(mf, name))
    ]
    if mf.home_item is not None:
        lists.append(("home", 0, mf.home_item))
    for name, i, it in lists:
        altitude_kept = has_position(it.command) and (
            name != "fence" or it.command == mavlink.MAV_CMD_NAV_FENCE_RETURN_POINT
        )  # a fence vertex or circle is stored without one
        for key in ("param1", "param2", "param3", "param4", "z"):
            value = getattr(it, key)
            if math.isinf(value) or (math.isnan(value) and key == "z" and altitude_kept):
                raise MissionFileError(
                    f"{path}: {name} item {i}: {key} = {value} cannot be stored in a mission file;"
                    " nothing written"
                )


def plan_mission_file(
    vehicle_plan: VehiclePlan, origin, autopilot: str = Conventions.ARDUPILOT
) -> MissionFile:
    """One vehicle of a Plan -> MissionFile (mission items from plan_to_items, home = plan origin)."""
    from gcs_planner.missions.items import plan_to_items

    items = in_file_frames(plan_to_items(vehicle_plan, origin, autopilot))
    fixed_wing = vehicle_plan.vehicle_type == "fixed_wing"
    speeds = vehicle_plan.speeds_mps[1:] if len(vehicle_plan.speeds_mps) > 1 else [15.0]
    cruise = float(max(speeds))
    return MissionFile.from_items(
        items,
        autopilot,
        lists=frozenset({MissionType.MISSION}),
        home=(origin.lat_deg, origin.lon_deg, origin.alt_m),
        vehicle_type=mavlink.MAV_TYPE_FIXED_WING if fixed_wing else mavlink.MAV_TYPE_QUADROTOR,
        cruise_speed_mps=cruise,
        hover_speed_mps=cruise,
    )


def load_plan_json(path: str | Path) -> Plan:
    """plan.json (from `gcs-planner plan`) -> Plan, with one-line errors."""
    from gcs_planner.model.plan import Plan

    try:
        return Plan.load(path)
    except UserError:  # already one line naming the file and the field
        raise
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
    path: str | Path,
    autopilot: str = Conventions.ARDUPILOT,
    vehicle: str | None = None,
    sysid: int | None = None,
) -> MissionFile:
    """A .plan, a WPL file, or plan.json (+ vehicle id, else the vehicle with ``sysid``) -> MissionFile."""
    path = Path(path)
    if path.suffix.lower() == ".json":
        plan = load_plan_json(path)
        return plan_mission_file(_one_vehicle(plan, vehicle, sysid), plan.origin, autopilot)
    return load_mission_file(path, autopilot=autopilot)


def planned_vehicle(path: str | Path, vehicle: str | None = None, sysid: int | None = None):
    """The VehiclePlan ``mission_input`` flies from a plan.json; None for a .plan or WPL file."""
    if Path(path).suffix.lower() != ".json":
        return None
    return _one_vehicle(load_plan_json(path), vehicle, sysid)


def _one_vehicle(plan, vehicle: str | None, sysid: int | None):
    (vp,) = select_vehicles(plan, [vehicle] if vehicle else None, sysid=sysid if not vehicle else None)[:1]
    return vp
