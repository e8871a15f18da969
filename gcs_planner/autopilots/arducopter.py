"""ArduCopter (and the other ArduPilot vehicles that are not planes): armed in GUIDED, take-off by command."""

from __future__ import annotations

from dataclasses import dataclass

from gcs_planner.autopilots.ardupilot import PLANE_TYPES, SIGNING_NOTE, ArduPilot
from gcs_planner.autopilots.base import Conventions
from gcs_planner.wire.enums import ARDUCOPTER_MODES, Autopilot
from gcs_planner.wire.units import SPEED_GROUNDSPEED

__all__ = ["FAMILY"]


@dataclass(frozen=True)
class ArduCopter(ArduPilot):
    def matches(self, autopilot: int | None, mav_type: int | None) -> bool:
        return autopilot == Autopilot.ARDUPILOTMEGA and mav_type not in PLANE_TYPES


FAMILY = ArduCopter(
    name="ArduCopter",
    conventions=Conventions.ARDUPILOT,
    pipelined=True,
    modes=ARDUCOPTER_MODES,
    arm_mode="GUIDED",
    start_arm_mode="GUIDED",  # refuses to arm in AUTO
    speed_type=SPEED_GROUNDSPEED,
    clear_all_at_once=False,
    streams_by_request=True,  # stock SRn_* = 0
    return_mode="RTL",
    land_mode="LAND",
    stack="ArduPilot",
    signing_note=SIGNING_NOTE,
    fence_alt_param="FENCE_ALT_MAX",  # AC_Fence
    readback="ARDUCOPTER",
    stores_as_received=frozenset({0, 2}),  # MissionItemProtocol_Waypoints / _Rally replace_item
    ramp_params=("WP_ACC", "WP_JERK", 1.0),  # AC_WPNav (4.7+; WPNAV_ACCEL [cm/s^2] before)
    vertical_params=("WP_SPD_UP", "WP_SPD_DN"),  # AC_WPNav (4.7+; WPNAV_SPEED_UP / _DN [cm/s] before)
    waypoint_nav_params=("WP_ACC_Z", "WP_RADIUS_M", "WP_ACC_CNR", "ATC_INPUT_TC"),  # AC_WPNav, AC_Attitude
    start_latency_s=1.0,  # SITL copters move ~0.5-1 s after MISSION_START (docs/real-autopilots.md)
)
