"""Check a mission item list before anything is sent: a bad list never leaves the ground station.

Rules (each failure names the item's seq and the field):
- at most 65535 items (MISSION_COUNT.count is uint16) and at most the vehicle's ``capacity``;
- ``seq`` equals the item's index (0..n-1) and every item has the list's ``mission_type``;
- exactly one item has ``current = 1`` in a MISSION list (MAVSDK enforces this as well); fence and
  rally lists may have none, never two;
- a MISSION list holds no fence vertex / circle or rally point (5000-5004, 5100): a vehicle would
  store one as a mission item;
- ``frame`` is a known MAV_FRAME; ``command`` is any uint16: a command the pinned dialect lacks
  may be one the vehicle has (ArduPilot's 116, 219), so files pass it through with a note
  (files.unknown_command_notes); ``current`` and ``autocontinue`` are 0 or 1;
- ``z`` and ``param1..4`` fit a MAVLink float32 (|v| <= 3.4e38, else the pack fails mid-upload);
  ``z`` of a positioned item in a global frame is an altitude in [MIN_ALT_M, MAX_ALT_M]
  (gcs_planner.core.validation, docs/input-validation.md);
- physical limits of the commands that carry them: DO_CHANGE_SPEED speed (param2) in
  [0, MAX_SPEED_MPS] or -1 / -2 (no change / default), a waypoint's acceptance radius (param2) in
  [0, MAX_RADIUS_M], a fence circle's radius (param1) in (0, MAX_RADIUS_M], a loiter radius
  (signed: the sign is the direction) within MAX_RADIUS_M;
- ``z`` is finite; ``param1..4`` are finite, or NaN where the command gives NaN a meaning: the
  dialect's description of that param says NaN (QGroundControl's NaN yaw, stored as null in .plan
  files) or the param is Empty / Reserved. A NaN speed, radius, time or count has no meaning (a
  vehicle stores it half: DO_CHANGE_SPEED NaN) and is refused; unknown commands pass; infinity is
  never meaningful;
- ``z`` of a positioned item is within +-MAX_REL_ALT_M (10 km) in a relative or terrain frame: a
  take-off to 99,999 m above home is a typo, not a mission;
- in global frames, ``x``/``y`` are integers with latitude in [-90, 90] deg and longitude in
  [-180, 180] deg (degE7), except for commands that carry no position (dialect.has_position), whose
  x/y must still fit int32.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from numbers import Integral, Real

from gcs_planner.core.errors import UserError
from gcs_planner.core.validation import FLOAT32_MAX, MAX_ALT_M, MAX_RADIUS_M, MAX_SPEED_MPS, MIN_ALT_M
from gcs_planner.wire.dialect import KNOWN_FRAMES, has_position, nan_has_meaning
from gcs_planner.wire.types import GLOBAL_FRAMES, MissionItem, MissionType

__all__ = ["MAX_MISSION_COUNT", "MAX_REL_ALT_M", "MissionValidationError", "validate_items"]

MAX_MISSION_COUNT = 65535  # MISSION_COUNT.count and seq are uint16
INT32_MIN, INT32_MAX = -(2**31), 2**31 - 1
DO_CHANGE_SPEED, NAV_WAYPOINT = 178, 16
MAX_REL_ALT_M = 10_000.0  # |z| in relative / terrain frames: higher than any UAV flies above home
# MAV_FRAME_GLOBAL_RELATIVE_ALT (3), _TERRAIN_ALT (10) and their _INT forms (6, 11)
RELATIVE_FRAMES = frozenset({3, 6, 10, 11})
FENCE_AND_RALLY = frozenset({5000, 5001, 5002, 5003, 5004, 5100})  # NAV_FENCE_* and NAV_RALLY_POINT
FENCE_CIRCLES = (5003, 5004)  # MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION / _EXCLUSION: param1 = radius
LOITER_RADIUS = {17: "param3", 18: "param3", 19: "param3", 31: "param2"}  # UNLIM, TURNS, TIME, TO_ALT


class MissionValidationError(UserError, ValueError):
    """A mission item list is invalid; ``seq`` and ``field`` say where (None for list-wide faults)."""

    def __init__(self, message: str, seq: int | None = None, field: str | None = None):
        super().__init__(message)
        self.seq = seq
        self.field = field


def validate_items(
    items: Sequence[MissionItem],
    capacity: int | None = None,
    mission_type: int | None = None,
) -> None:
    """Raise MissionValidationError for the first problem in ``items``; return None if they are fine.

    mission_type: the list's type; default: that of item 0 (MISSION for an empty list).
    capacity: the vehicle's maximum item count, if known.
    """
    n = len(items)
    if n > MAX_MISSION_COUNT:
        raise MissionValidationError(
            f"{n} items: count exceeds the MAVLink limit of {MAX_MISSION_COUNT}", field="count"
        )
    if capacity is not None and n > capacity:
        raise MissionValidationError(
            f"{n} items: count exceeds the vehicle's capacity {capacity}", field="count"
        )
    if mission_type is None:
        mission_type = items[0].mission_type if n else MissionType.MISSION
    currents = []
    for index, item in enumerate(items):
        _check_item(item, index, mission_type)
        if item.current == 1:
            currents.append(index)
    if len(currents) > 1:
        raise MissionValidationError(
            f"item {currents[1]}: field current = 1 but item {currents[0]} is already current",
            seq=currents[1],
            field="current",
        )
    if mission_type == MissionType.MISSION and n and not currents:
        raise MissionValidationError(
            "no item has current = 1; exactly one item must be current", field="current"
        )


def _check_item(item: MissionItem, index: int, mission_type: int) -> None:
    def fail(field: str, problem: str) -> MissionValidationError:
        value = getattr(item, field)
        return MissionValidationError(
            f"item {index}: field {field} = {value!r} {problem}", seq=index, field=field
        )

    if item.seq != index:
        raise fail("seq", f"but the item is at index {index}; seq must run 0..n-1")
    if item.mission_type != mission_type:
        raise fail("mission_type", f"differs from the list's mission_type {int(mission_type)}")
    if mission_type == MissionType.MISSION and item.command in FENCE_AND_RALLY:
        raise fail("command", "is a fence / rally point, not a mission item: put it in its own list")
    if item.frame not in KNOWN_FRAMES:
        raise fail("frame", "is not a known MAV_FRAME")
    if not _is_integer(item.command) or not 0 <= item.command <= 65535:
        raise fail("command", "must be a MAV_CMD id 0..65535")
    for field in ("current", "autocontinue"):
        if getattr(item, field) not in (0, 1):
            raise fail(field, "must be 0 or 1")
    for field in ("param1", "param2", "param3", "param4"):
        value = getattr(item, field)
        if not _is_real(value) or math.isinf(value) or abs(value) > FLOAT32_MAX:
            raise fail(field, "must be a finite float32 number (or NaN for 'default')")
        if math.isnan(value) and not nan_has_meaning(item.command, int(field[-1])):
            raise fail(field, f"is NaN, which command {item.command} gives no meaning in this param")
    if not _is_real(item.z) or not math.isfinite(item.z) or abs(item.z) > FLOAT32_MAX:
        raise fail("z", "must be a finite float32 altitude [m]")
    _check_physical(item, fail)
    for field in ("x", "y"):
        value = getattr(item, field)
        if not _is_integer(value) or not INT32_MIN <= value <= INT32_MAX:
            raise fail(field, "must be an int32 (degE7 in global frames)")
    if item.frame in GLOBAL_FRAMES and has_position(item.command):
        if not -900_000_000 <= item.x <= 900_000_000:
            raise fail("x", f"(latitude {item.x / 1e7:.7f} deg) is outside [-90, 90] deg")
        if not -1_800_000_000 <= item.y <= 1_800_000_000:
            raise fail("y", f"(longitude {item.y / 1e7:.7f} deg) is outside [-180, 180] deg")


def _check_physical(item: MissionItem, fail) -> None:
    """Altitude, speed and radius limits of the commands that carry them (module docstring)."""
    if item.frame in GLOBAL_FRAMES and has_position(item.command) and not MIN_ALT_M <= item.z <= MAX_ALT_M:
        raise fail("z", f"is outside the altitude limits [{MIN_ALT_M:g}, {MAX_ALT_M:g}] m")
    if item.frame in RELATIVE_FRAMES and has_position(item.command) and abs(item.z) > MAX_REL_ALT_M:
        raise fail("z", f"is more than {MAX_REL_ALT_M:g} m above or below home / terrain")
    if item.command == DO_CHANGE_SPEED:
        speed = item.param2
        if not (math.isnan(speed) or speed in (-1.0, -2.0) or 0.0 <= speed <= MAX_SPEED_MPS):
            raise fail("param2", f"(speed) must be in [0, {MAX_SPEED_MPS:g}] m/s, or -1 / -2")
    elif item.command == NAV_WAYPOINT:
        if not (math.isnan(item.param2) or 0.0 <= item.param2 <= MAX_RADIUS_M):
            raise fail("param2", f"(acceptance radius) must be in [0, {MAX_RADIUS_M:g}] m")
    elif item.command in FENCE_CIRCLES:
        if not 0.0 < item.param1 <= MAX_RADIUS_M:
            raise fail("param1", f"(circle radius) must be in (0, {MAX_RADIUS_M:g}] m")
    elif item.command in LOITER_RADIUS:
        field = LOITER_RADIUS[item.command]
        if abs(getattr(item, field)) > MAX_RADIUS_M:
            raise fail(field, f"(loiter radius) must be within +-{MAX_RADIUS_M:g} m")


def _is_real(value: object) -> bool:
    """int or float (numpy scalars too), not bool; the plain types first because abc checks are slow."""
    return type(value) in (float, int) or (not isinstance(value, bool) and isinstance(value, Real))


def _is_integer(value: object) -> bool:
    return type(value) is int or (not isinstance(value, bool) and isinstance(value, Integral))
