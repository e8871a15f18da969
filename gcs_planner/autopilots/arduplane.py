"""ArduPlane (and QuadPlanes): TAKEOFF mode, airspeed limits, L1 guidance."""

from __future__ import annotations

import logging
from dataclasses import dataclass

from gcs_planner.autopilots.ardupilot import PLANE_TYPES, SIGNING_NOTE, ArduPilot
from gcs_planner.autopilots.base import Conventions, VehiclePort
from gcs_planner.wire.enums import ARDUPLANE_MODES, Autopilot
from gcs_planner.wire.units import SPEED_AIRSPEED

__all__ = ["FAMILY"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ArduPlane(ArduPilot):
    def matches(self, autopilot: int | None, mav_type: int | None) -> bool:
        return autopilot == Autopilot.ARDUPILOTMEGA and mav_type in PLANE_TYPES

    async def take_off(
        self, port: VehiclePort, alt_m: float, climb_past_m: float, takeoff_dist_m: float
    ) -> None:
        """TAKEOFF mode climbs once armed, to TKOFF_ALT, straight along the launch heading until
        2 m below it or TKOFF_DIST from the start (ModeTakeoff::update), then circles: the tool
        sets TKOFF_ALT ``alt_m`` + ``climb_past_m`` and TKOFF_DIST so the climb stays straight."""
        value = await port.set_param("TKOFF_ALT", alt_m + climb_past_m)
        log.info("%s set to %.1f m for the take-off", "TKOFF_ALT", value)
        if takeoff_dist_m > 0:
            await port.set_param("TKOFF_DIST", takeoff_dist_m)
        await self.arm(port)


FAMILY = ArduPlane(
    name="ArduPlane",
    conventions=Conventions.ARDUPILOT,
    pipelined=True,
    modes=ARDUPLANE_MODES,
    arm_mode="TAKEOFF",
    start_arm_mode=None,
    speed_type=SPEED_AIRSPEED,  # a ground-speed change is read as a minimum ground speed
    clear_all_at_once=False,
    streams_by_request=True,
    return_mode="RTL",
    land_mode=None,
    stack="ArduPilot",
    signing_note=SIGNING_NOTE,
    fence_alt_param="FENCE_ALT_MAX",  # AC_Fence
    readback="ARDUPLANE",
    stores_as_received=frozenset({0, 2}),  # MissionItemProtocol_Waypoints / _Rally replace_item
    # refuses a DO_CHANGE_SPEED airspeed outside [AIRSPEED_MIN, AIRSPEED_MAX] (commands_logic.cpp
    # Plane::do_change_speed) and banks at most ROLL_LIMIT_DEG
    flight_limits=("AIRSPEED_MIN", "AIRSPEED_MAX", "ROLL_LIMIT_DEG"),
    l1_params=("NAVL1_PERIOD", "RLL2SRV_TCONST"),  # AP_L1_Control, AP_RollController
    takeoff_level_off_m=2.0,  # ModeTakeoff is done 2 m below TKOFF_ALT
)
