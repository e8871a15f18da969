"""What every ArduPilot vehicle does alike (ArduCopter and ArduPlane build on it)."""

from __future__ import annotations

from dataclasses import dataclass

from gcs_planner.autopilots.base import AutopilotQuirks, VehiclePort

__all__ = ["PLANE_TYPES", "SIGNING_NOTE", "ArduPilot"]

# GCS_Signing.cpp accept_unsigned_callback: ArduPilot takes every unsigned frame on MAVLINK_COMM_0
SIGNING_NOTE = (
    "ArduPilot still accepts unsigned messages on its first serial port (SERIAL0, usually USB) by"
    " design; signing protects its other links (telemetry radios, networks)"
)
# MAV_TYPE values ArduPlane reports: FIXED_WING 1 and the VTOL types 19..25 (QuadPlanes)
PLANE_TYPES = frozenset({1, *range(19, 26)})


@dataclass(frozen=True)
class ArduPilot(AutopilotQuirks):
    async def start_mission(self, port: VehiclePort, first: int, last: int) -> None:
        """DO_SET_MISSION_CURRENT(first), then MISSION_START(0, 0): ArduPilot denies any other
        range and resumes at the current item."""
        await port.set_current(first)
        await port.mission_start(0, 0)
