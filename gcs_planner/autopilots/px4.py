"""PX4: take-off altitude AMSL, mission start with a range, a verdict after the ACK."""

from __future__ import annotations

from dataclasses import dataclass

from gcs_planner.autopilots.base import AutopilotQuirks, Conventions, VehiclePort
from gcs_planner.wire.enums import PX4_MODES, Autopilot
from gcs_planner.wire.units import SPEED_GROUNDSPEED

__all__ = ["FAMILY"]


@dataclass(frozen=True)
class Px4(AutopilotQuirks):
    def matches(self, autopilot: int | None, mav_type: int | None) -> bool:
        return autopilot == Autopilot.PX4

    def mode_command_params(self, custom_mode: int) -> tuple[float, ...]:
        """Main mode and sub mode: bytes 2 and 3 of custom_mode (px4_custom_mode.h)."""
        return float((custom_mode >> 16) & 0xFF), float((custom_mode >> 24) & 0xFF)

    async def take_off(
        self, port: VehiclePort, alt_m: float, climb_past_m: float, takeoff_dist_m: float
    ) -> None:
        """MAV_CMD_NAV_TAKEOFF with param7 AMSL (the navigator's take-off altitude)."""
        await self.arm(port)
        await port.takeoff(port.home_amsl_m() + alt_m)


FAMILY = Px4(
    name="PX4",
    conventions=Conventions.PX4,
    pipelined=True,
    modes=PX4_MODES,
    arm_mode=None,
    start_arm_mode=None,
    speed_type=SPEED_GROUNDSPEED,
    clear_all_at_once=True,
    streams_by_request=False,
    return_mode="RTL",
    land_mode="LAND",
    readback="PX4",
    stores_as_received=frozenset(),  # switches lists on completion only
    # the navigator runs its FeasibilityChecker on the stored mission after the transfer and says
    # "Mission rejected: ..." (e.g. "takeoff not first waypoint item")
    verdict_after_ack_s=1.0,
    rejection_texts=("mission rejected", "mission invalid"),
    ramp_params=("MPC_ACC_HOR", "MPC_JERK_AUTO", 1.0),  # mc_pos_control / FlightTaskAuto
    vertical_params=("MPC_Z_V_AUTO_UP", "MPC_Z_V_AUTO_DN"),  # mc_pos_control, in missions
    # SIH v1.15.4 multicopters pass 1 and 5 m/s 0.4-1.0 s after the MPC_ACC_HOR / MPC_JERK_AUTO
    # S-curve from MISSION_START would, and cruise ~1 s further behind it: the route start lead
    # left them 1.0-1.4 s late 8-12 s into the route at 0.7 s (two four-vehicle flights,
    # docs/real-autopilots.md)
    start_latency_s=1.7,
    params_bytewise=True,  # MAVLinkParameters: integers memcpy'd into param_value
    stack="PX4",
    fence_alt_param="GF_MAX_VER_DIST",  # geofence: max vertical distance from home
)
