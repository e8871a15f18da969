"""The autopilot families the tool flies, one module each, chosen from the HEARTBEAT.

As in Skybrush server's autopilot registry, a vehicle's family comes from its HEARTBEAT fields
(MAV_AUTOPILOT, MAV_TYPE): each family's ``matches`` is asked in ``FAMILIES`` order, the generic
one last; a command-line flag only decides for a vehicle that has not said what it is. A family is
a module here with ``FAMILY`` (base.py says what it holds) and its place in ``FAMILIES``;
docs/autopilots.md shows how to add one. What each autopilot stores of an item is readback.py.
"""

from __future__ import annotations

from gcs_planner.autopilots.arducopter import FAMILY as ARDUCOPTER
from gcs_planner.autopilots.arduplane import FAMILY as ARDUPLANE
from gcs_planner.autopilots.base import AutopilotQuirks, Conventions, VehiclePort
from gcs_planner.autopilots.generic import FAMILY as GENERIC
from gcs_planner.autopilots.px4 import FAMILY as PX4

__all__ = [
    "ARDUCOPTER", "ARDUPLANE", "FAMILIES", "GENERIC", "PX4", "AutopilotQuirks", "Conventions", "VehiclePort",
    "mode_of", "quirks_for", "quirks_named",
]  # fmt: skip

# asked in this order: a family that would also match another's HEARTBEAT comes before it
FAMILIES: tuple[AutopilotQuirks, ...] = (ARDUCOPTER, ARDUPLANE, PX4, GENERIC)


def quirks_for(autopilot: int | None, mav_type: int | None = None) -> AutopilotQuirks:
    """The family of a vehicle whose HEARTBEAT says ``autopilot`` (MAV_AUTOPILOT) and ``mav_type``."""
    return next(f for f in FAMILIES if f.matches(autopilot, mav_type))


def quirks_named(conventions: str, fixed_wing: bool = False) -> AutopilotQuirks:
    """The family of a vehicle not heard yet, from a flag (its item conventions) and its airframe."""
    if conventions == Conventions.ARDUPILOT:
        return ARDUPLANE if fixed_wing else ARDUCOPTER
    return PX4


def mode_of(info) -> str | None:
    """The mode name of a vehicle's last HEARTBEAT (``VehicleInfo``), None when unknown."""
    modes = quirks_for(info.autopilot, info.mav_type).modes or {}
    return next((name for name, number in modes.items() if number == info.custom_mode), None)
