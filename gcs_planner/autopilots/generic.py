"""Any other MAVLink vehicle (MAVSDK's servers, unknown autopilots): the standard protocol only."""

from __future__ import annotations

from dataclasses import dataclass

from gcs_planner.autopilots.base import AutopilotQuirks, Conventions
from gcs_planner.wire.units import SPEED_GROUNDSPEED

__all__ = ["FAMILY"]


@dataclass(frozen=True)
class Generic(AutopilotQuirks):
    def matches(self, autopilot: int | None, mav_type: int | None) -> bool:
        return True  # asked last (autopilots.FAMILIES)


FAMILY = Generic(
    name="MAVLink",
    conventions=Conventions.PX4,
    pipelined=False,  # MAVSDK's MissionRawServer stores every item it gets, whatever its seq
    modes=None,
    arm_mode=None,
    start_arm_mode=None,
    speed_type=SPEED_GROUNDSPEED,
    clear_all_at_once=True,
    streams_by_request=True,
    return_mode=None,
    land_mode=None,
    readback="GENERIC",  # stores_as_received: unknown, so every list is read back
)
