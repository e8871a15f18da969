"""What differs between the autopilots the tool flies, in one place, chosen from the HEARTBEAT.

``quirks_for(autopilot, mav_type)`` returns the entry for a vehicle from its HEARTBEAT fields
(MAV_AUTOPILOT, MAV_TYPE), as Skybrush server's autopilot registry does; a command-line flag only
decides for a vehicle that has not said what it is. The read-back model (what a vehicle returns of
an uploaded item) is in readback.py. docs/real-autopilots.md has the table with each behaviour's
source (the autopilot's code or a SITL run).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

from gcs_planner.wire.enums import ARDUCOPTER_MODES, ARDUPLANE_MODES, PX4_MODES, Autopilot
from gcs_planner.wire.units import SPEED_AIRSPEED, SPEED_GROUNDSPEED

__all__ = [
    "ARDUCOPTER",
    "ARDUPLANE",
    "GENERIC",
    "PX4",
    "AutopilotQuirks",
    "Takeoff",
    "mode_of",
    "quirks_for",
    "quirks_named",
]

# MAV_TYPE values ArduPlane reports: FIXED_WING 1 and the VTOL types 19..25 (QuadPlanes)
_PLANE_TYPES = frozenset({1, *range(19, 26)})


class Takeoff(StrEnum):
    """How a vehicle is taken off outside a mission."""

    COMMAND_ABOVE_HOME = "command_above_home"  # MAV_CMD_NAV_TAKEOFF, param7 [m above home] (ArduCopter)
    COMMAND_AMSL = "command_amsl"  # MAV_CMD_NAV_TAKEOFF, param7 [m AMSL] (PX4 navigator)
    TAKEOFF_MODE = "takeoff_mode"  # mode TAKEOFF climbs to parameter TKOFF_ALT (plain ArduPlane)


@dataclass(frozen=True)
class AutopilotQuirks:
    """One autopilot family's conventions; every field is a difference the tool has to act on."""

    name: str
    conventions: str  # mission item conventions: "ardupilot" (home at seq 0) or "px4" (none)
    pipelined: bool  # drops items whose seq it does not wait for: items in flight are safe
    modes: dict[str, int] | None  # mode name -> HEARTBEAT custom_mode (None: no named modes)
    arm_mode: str | None  # mode to arm in before a take-off (None: arm in the current mode)
    start_arm_mode: str | None  # mode to arm in before MISSION_START (ArduCopter refuses to arm in AUTO)
    takeoff: Takeoff
    start_with_range: bool  # MISSION_START(first, last) accepted; else DO_SET_MISSION_CURRENT + (0, 0)
    speed_type: float  # DO_CHANGE_SPEED param1 for schedule keeping
    clear_all_at_once: bool  # MISSION_CLEAR_ALL with mission_type ALL (255) is understood
    streams_by_request: bool  # streams telemetry only when asked (stock ArduPilot SRn_* = 0)
    return_mode: str | None  # the mode that brings a vehicle home (safe end)
    land_mode: str | None  # the mode that lands it where it is (None: no such mode)
    readback: str  # the name of its read-back model in readback.py (loaded when a verify needs it: numpy)
    # parameters of the airspeed range and bank limit, [min m/s, max m/s, roll deg] (None: none):
    # ArduPlane refuses a DO_CHANGE_SPEED airspeed outside [AIRSPEED_MIN, AIRSPEED_MAX]
    # (commands_logic.cpp Plane::do_change_speed) and banks at most ROLL_LIMIT_DEG
    flight_limits: tuple[str, str, str] | None = None
    # parameters of its L1 waypoint guidance's period [s] and its roll controller's time constant [s]
    # (None: no L1 guidance): AP_L1_Control's NAVL1_PERIOD, AP_RollController's RLL2SRV_TCONST
    l1_params: tuple[str, str] | None = None
    # list types (mission_type) written in place as items arrive: a failed upload leaves a mix, so
    # the client reads the list back to say what the vehicle holds (ArduPilot's mission and rally:
    # MissionItemProtocol_Waypoints / _Rally replace_item; PX4 switches lists on completion only)
    stores_as_received: frozenset[int] = frozenset({0, 1, 2})
    # how long after its MISSION_ACK the autopilot may still refuse a mission [s], and the words it
    # refuses with (lower case): PX4's navigator runs its FeasibilityChecker on the stored mission
    # after the transfer and says "Mission rejected: ..." (e.g. "takeoff not first waypoint item")
    verdict_after_ack_s: float = 0.0
    rejection_texts: tuple[str, ...] = ()
    # parameters of its waypoint navigation's acceleration and jerk limits, with their unit scale
    # to m/s^2 and m/s^3 (None: not known): a route starts from the hover on this S-curve ramp
    ramp_params: tuple[str, str, float] | None = None
    start_latency_s: float = 0.0  # from MISSION_START to moving along the route [s] (measured)

    def readback_model(self):
        """What the autopilot returns of an item sent (readback.Model)."""
        from gcs_planner.mavlink import readback

        return getattr(readback, self.readback)

    @property
    def home_at_seq0(self) -> bool:
        return self.conventions == "ardupilot"


ARDUCOPTER = AutopilotQuirks(
    name="ArduCopter",
    conventions="ardupilot",
    pipelined=True,
    modes=ARDUCOPTER_MODES,
    arm_mode="GUIDED",
    start_arm_mode="GUIDED",
    takeoff=Takeoff.COMMAND_ABOVE_HOME,
    start_with_range=False,
    speed_type=SPEED_GROUNDSPEED,
    clear_all_at_once=False,
    streams_by_request=True,
    return_mode="RTL",
    land_mode="LAND",
    readback="ARDUCOPTER",
    stores_as_received=frozenset({0, 2}),
    ramp_params=("WP_ACC", "WP_JERK", 1.0),  # AC_WPNav (4.7+; WPNAV_ACCEL [cm/s^2] before)
    start_latency_s=1.0,  # SITL copters move ~0.5-1 s after MISSION_START (docs/real-autopilots.md)
)
ARDUPLANE = AutopilotQuirks(
    name="ArduPlane",
    conventions="ardupilot",
    pipelined=True,
    modes=ARDUPLANE_MODES,
    arm_mode="TAKEOFF",
    start_arm_mode=None,
    takeoff=Takeoff.TAKEOFF_MODE,
    start_with_range=False,
    speed_type=SPEED_AIRSPEED,
    clear_all_at_once=False,
    streams_by_request=True,
    return_mode="RTL",
    land_mode=None,
    readback="ARDUPLANE",
    stores_as_received=frozenset({0, 2}),
    flight_limits=("AIRSPEED_MIN", "AIRSPEED_MAX", "ROLL_LIMIT_DEG"),
    l1_params=("NAVL1_PERIOD", "RLL2SRV_TCONST"),
)
PX4 = AutopilotQuirks(
    name="PX4",
    conventions="px4",
    pipelined=True,
    modes=PX4_MODES,
    arm_mode=None,
    start_arm_mode=None,
    takeoff=Takeoff.COMMAND_AMSL,
    start_with_range=True,
    speed_type=SPEED_GROUNDSPEED,
    clear_all_at_once=True,
    streams_by_request=False,
    return_mode="RTL",
    land_mode="LAND",
    readback="PX4",
    stores_as_received=frozenset(),
    verdict_after_ack_s=1.0,
    rejection_texts=("mission rejected", "mission invalid"),
    ramp_params=("MPC_ACC_HOR", "MPC_JERK_AUTO", 1.0),  # mc_pos_control / FlightTaskAuto
)
GENERIC = AutopilotQuirks(
    name="MAVLink",
    conventions="px4",
    pipelined=False,  # MAVSDK's MissionRawServer stores every item it gets, whatever its seq
    modes=None,
    arm_mode=None,
    start_arm_mode=None,
    takeoff=Takeoff.COMMAND_ABOVE_HOME,
    start_with_range=True,
    speed_type=SPEED_GROUNDSPEED,
    clear_all_at_once=True,
    streams_by_request=True,
    return_mode=None,
    land_mode=None,
    readback="GENERIC",  # stores_as_received: unknown, so every list is read back
)


def quirks_for(autopilot: int | None, mav_type: int | None = None) -> AutopilotQuirks:
    """The entry for a vehicle whose HEARTBEAT says ``autopilot`` (MAV_AUTOPILOT) and ``mav_type``."""
    if autopilot == Autopilot.ARDUPILOTMEGA:
        return ARDUPLANE if mav_type in _PLANE_TYPES else ARDUCOPTER
    if autopilot == Autopilot.PX4:
        return PX4
    return GENERIC


def mode_of(info) -> str | None:
    """The mode name of a vehicle's last HEARTBEAT (``VehicleInfo``), None when unknown."""
    modes = quirks_for(info.autopilot, info.mav_type).modes or {}
    return next((name for name, number in modes.items() if number == info.custom_mode), None)


def quirks_named(conventions: str, fixed_wing: bool = False) -> AutopilotQuirks:
    """The entry for a vehicle not heard yet, from a flag ("ardupilot" / "px4") and its airframe."""
    if conventions == "ardupilot":
        return ARDUPLANE if fixed_wing else ARDUCOPTER
    return PX4
