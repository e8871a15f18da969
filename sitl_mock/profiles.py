"""Autopilot profiles: the mission-protocol and flight-mode conventions the mock emulates.

Numbers come from the autopilots' sources: ArduPilot libraries/GCS_MAVLink/MissionItemProtocol.cpp
(requests with legacy MISSION_REQUEST, re-requests after 1000 ms, cancels after 8000 ms, home at seq
0, rounds stored values) and PX4 src/modules/mavlink/mavlink_mission.cpp (MISSION_REQUEST_INT, 250
ms retry, 5 s protocol timeout, no home item). Capacities are typical defaults (ArduPilot's mission
storage on a 16 kB FRAM, PX4's dataman), both overridable per vehicle.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

from gcs_planner.wire.enums import (
    ARDUCOPTER_MODES,
    ARDUPLANE_MODES,
    PX4_MODES,
    Autopilot,
    CommandResult,
    MissionResult,
)
from gcs_planner.wire.types import MissionItem, MissionType
from sitl_mock import storage as stored

__all__ = [
    "ARDUCOPTER_FLIGHT",
    "ARDUPLANE_FLIGHT",
    "PROFILES",
    "PX4_FLIGHT",
    "AutopilotProfile",
    "FlightRules",
]


@dataclass(frozen=True)
class FlightRules:
    """How one autopilot build behaves in flight, beyond the mission protocol.

    Each value is what real ArduCopter / ArduPlane and PX4 SITL do with stock parameters or what
    their source says (docs/real-autopilots.md names the run or the file and function):

    arm_ready_s: simulated seconds after boot before pre-arm checks pass (ArduCopter ~40-45 s: the
        EKF has no position estimate; PX4 ~5 s). Until then SYS_STATUS reports the PREARM_CHECK bit
        unhealthy and COMPONENT_ARM_DISARM is answered ``arm_refusal`` with ``not_ready_text``.
    position_fix_s: simulated seconds after boot (at most arm_ready_s) before GLOBAL_POSITION_INT
        carries a position; until then lat = lon = alt = relative_alt = 0. ArduPilot sends the
        location whether ``get_location`` succeeded or not (GCS_Common.cpp
        ``GCS_MAVLINK::send_global_position_int``); ArduPlane SITL: (0, 0),
        then dead reckoning up to 0.0004 deg from it, until boot + 10 s, when its GPS is detected.
    auto_disarm_s: armed on the ground without taking off this long -> disarmed (ArduPilot
        DISARM_DELAY 10 s, PX4 COM_DISARM_PRFLT 10 s); not while a mission runs in AUTO.
    takeoff_command: MAV_CMD_NAV_TAKEOFF param7 is "above_home" (ArduCopter), "amsl" (PX4
        navigator: ``rep->current.alt = cmd.param7``) or "refused" (ArduPlane without QuadPlane:
        FAILED; it takes off in TAKEOFF mode to parameter ``takeoff_param``).
    start_range: MISSION_START(first, last) other than (0, 0) accepted; ArduPilot DENIES it
        (GCS_MAVLink_Copter.cpp / GCS_MAVLink_Plane.cpp) and resumes at the current item.
    final_land_disarms: a final NAV_LAND ends with a disarm that resets the mission, with neither
        ITEM_REACHED nor mission_state COMPLETE (ArduCopter: AP_Arming_Copter::disarm).
    rtl_item_switches_mode: NAV_RETURN_TO_LAUNCH in a mission switches the vehicle to mode RTL
        (ArduPlane), so the mission stops being ACTIVE.
    groundspeed_is_minimum: DO_CHANGE_SPEED speed type 1 sets a minimum ground speed, not the
        cruise speed ("Set groundspeed"; ArduPlane keeps its airspeed).
    streams_by_request: only HEARTBEAT and STATUSTEXT flow until the GCS asks for messages
        (stock ArduPilot SRn_* = 0); PX4 streams its default set unasked.
    rejects_position_before_takeoff: feasibility check after an accepted upload: a positional
        item before NAV_TAKEOFF -> "Mission rejected: takeoff not first waypoint item", then
        arming TEMPORARILY_REJECTED and MISSION_START DENIED (PX4 FeasibilityChecker).
    signing_refused_armed: SETUP_SIGNING ignored while armed (PX4).
    airspeed_range: parameters AIRSPEED_MIN / AIRSPEED_MAX / ROLL_LIMIT_DEG (the airframe's own
        range and bank limit); a DO_CHANGE_SPEED airspeed outside the range is refused (command:
        FAILED) and ignored in a mission, the speed unchanged (ArduPlane commands_logic.cpp
        ``Plane::do_change_speed``; SITL's plane.parm: 10 / 30 m/s, 65 deg); and NAVL1_PERIOD /
        RLL2SRV_TCONST, the period of its L1 waypoint guidance (AP_L1_Control) and the lag of its
        bank (plane.parm: 15 s, 0.25 s), both 0 where the mock plane flies its pursuit guidance
        instead (ArduPlane has no such values: the mock says so).
    params: the parameters the mock serves over PARAM_SET / PARAM_REQUEST_READ.
    land_start_needs_autoland: a mission holding DO_LAND_START while parameter RTL_AUTOLAND is 0
        is refused at arming, "PreArm: DO_LAND_START set and RTL_AUTOLAND disable" (ArduPlane SITL,
        docs/real-autopilots.md).
    landed_disarm_s: after a touchdown the vehicle stays armed this long, then disarms (PX4
        COM_DISARM_LAND, 2 s by default: PX4 SIH v1.15.4 said "Landing detected" and "Disarmed by
        landing" 2.0 s apart, docs/real-autopilots.md); ArduPilot disarms on touchdown.
    ramp_params: the names of the waypoint acceleration [m/s^2] and jerk [m/s^3] limits
        (ArduCopter AC_WPNav WP_ACC / WP_JERK, PX4 MPC_ACC_HOR / MPC_JERK_AUTO); the mock serves
        its airframe's acceleration and a jerk it never limits (it ramps linearly), which is
        what it flies.
    vertical_params: the names of the climb and descent speeds [m/s] of its missions and their
        defaults, ``stock_vertical_mps`` (ArduCopter AC_WPNav.cpp WP_SPD_UP / WP_SPD_DN, 2.5 / 1.5;
        PX4 multicopter_autonomous_params.c MPC_Z_V_AUTO_UP / _DN, 3 / 1.5): a multirotor without
        an airframe of its own climbs and sinks at the defaults; the mock serves the rates it flies
        (sitl_mock.flight: slower over ground along a leg steeper than they allow).
    scurve_legs: a multirotor flies its mission's waypoints as ArduCopter does, each leg an S-curve
        from rest to rest blended at the corners (sitl_mock.wpnav, from AC_WPNav / SCurve.cpp), and
        serves ArduCopter's stock WP_ACC, WP_JERK, WP_ACC_Z, WP_RADIUS_M, WP_ACC_CNR and
        ATC_INPUT_TC, which it flies by (a PARAM_SET changes the legs planned after it). Off by
        default: the mock's own kinematics, at its airframe's acceleration, fly the waypoints.
    """

    name: str
    arm_ready_s: float
    arm_refusal: CommandResult
    not_ready_text: str
    auto_disarm_s: float
    takeoff_command: str
    start_range: bool
    final_land_disarms: bool = False
    rtl_item_switches_mode: bool = False
    groundspeed_is_minimum: bool = False
    streams_by_request: bool = True
    rejects_position_before_takeoff: bool = False
    land_start_needs_autoland: bool = False
    signing_refused_armed: bool = False
    airspeed_range: bool = False
    takeoff_param: str | None = None
    params: dict[str, float] = field(default_factory=dict)
    position_fix_s: float = 0.0
    landed_disarm_s: float = 0.0
    ramp_params: tuple[str, str] | None = None
    vertical_params: tuple[str, str] | None = None
    stock_vertical_mps: tuple[float, float] | None = None
    scurve_legs: bool = False


ARDUCOPTER_FLIGHT = FlightRules(
    name="ArduCopter",
    arm_ready_s=40.0,
    position_fix_s=10.0,
    arm_refusal=CommandResult.FAILED,
    not_ready_text="Arm: Need Position Estimate",
    auto_disarm_s=10.0,
    takeoff_command="above_home",
    start_range=False,
    final_land_disarms=True,
    ramp_params=("WP_ACC", "WP_JERK"),
    vertical_params=("WP_SPD_UP", "WP_SPD_DN"),
    stock_vertical_mps=(2.5, 1.5),
)
ARDUPLANE_FLIGHT = FlightRules(
    name="ArduPlane",
    arm_ready_s=40.0,
    position_fix_s=10.0,
    arm_refusal=CommandResult.FAILED,
    not_ready_text="Arm: Need Position Estimate",
    auto_disarm_s=math.inf,  # ArduPlane has no ground auto-disarm by default
    takeoff_command="refused",
    start_range=False,
    rtl_item_switches_mode=True,
    groundspeed_is_minimum=True,
    airspeed_range=True,
    takeoff_param="TKOFF_ALT",
    params={"TKOFF_ALT": 50.0, "TKOFF_DIST": 200.0, "RTL_AUTOLAND": 0.0},  # ArduPlane defaults
    land_start_needs_autoland=True,
)
PX4_FLIGHT = FlightRules(
    name="PX4",
    arm_ready_s=5.0,
    arm_refusal=CommandResult.TEMPORARILY_REJECTED,
    not_ready_text="Arming denied: Resolve system health failures first",
    auto_disarm_s=10.0,
    takeoff_command="amsl",
    start_range=True,
    streams_by_request=False,
    rejects_position_before_takeoff=True,
    signing_refused_armed=True,
    landed_disarm_s=2.0,
    ramp_params=("MPC_ACC_HOR", "MPC_JERK_AUTO"),
    vertical_params=("MPC_Z_V_AUTO_UP", "MPC_Z_V_AUTO_DN"),
    stock_vertical_mps=(3.0, 1.5),
)


@dataclass(frozen=True)
class AutopilotProfile:
    """How one autopilot family runs the mission protocol and encodes its flight modes.

    rerequest_s: time without the requested item before the vehicle asks again [s].
    timeout_s: time without any item before the vehicle cancels an upload [s].
    capacity: items per mission type (MISSION, FENCE, RALLY); more -> MISSION_ACK(NO_SPACE).
    modes: vehicle type ("multirotor" / "fixed_wing") -> mode name -> HEARTBEAT custom_mode.
    storage: what the autopilot stores of an item, per vehicle type (sitl_mock/storage.py, from
        AP_Mission and PX4's mavlink_mission.cpp, in their float32 / integer arithmetic), so a
        read-back shows what the real one returns; it raises storage.Refused for an item refused.
    reacks_final_item: a repeated last item after completion is answered with the ACK again
        (PX4 does; ArduPilot drops it, so a lost final ACK is never repeated).
    clear_denied_while_running: MISSION_CLEAR_ALL of the mission in AUTO -> ERROR (ArduPilot).
    flight: the in-flight behaviour per vehicle type (FlightRules).

    A second uploader (an upload session belongs to the sysid/compid of its MISSION_COUNT):
    second_uploader_result: the answer to a MISSION_COUNT from other ids during an upload. ArduPilot
        DENIED (MissionItemProtocol::handle_mission_count: ``msg.sysid != dest_sysid || msg.compid !=
        dest_compid`` -> MAV_MISSION_DENIED); PX4 ERROR, sent to the newcomer, the upload goes on
        (MavlinkMissionManager::handle_mission_count, GETLIST state: "Request from another partner").
    same_partner_restarts: a MISSION_COUNT from the uploader's own ids restarts the upload at any
        point (ArduPilot: ``free_upload_resources()`` and a new session, so two GCSs sharing ids merge);
        False = PX4: before the first item it re-requests item 0, after it it answers ERROR to the
        partner with STATUSTEXT "WPM: REJ. CMD: Busy" and keeps receiving (handle_mission_count).
    foreign_item_denied: an item from other ids during an upload -> DENIED, checked after the seq
        (ArduPilot MissionItemProtocol::handle_mission_item: INVALID_SEQUENCE first, then DENIED);
        False = PX4: STATUSTEXT "REJ. MIS ITEM: partner id mismatch", no ACK (handle_mission_item_both).
    stores_as_received: the list types written in place as items arrive, after a truncation to the
        new count at MISSION_COUNT, so a failed upload leaves a mix of new and old items. ArduPilot's
        mission (MissionItemProtocol_Waypoints::truncate / replace_item -> AP_Mission::truncate /
        replace_cmd) and rally points (MissionItemProtocol_Rally::replace_item); its fence is
        collected and written on completion (MissionItemProtocol_Fence::complete). PX4 writes every
        list into the inactive dataman slot and switches on the last item (handle_mission_item_both:
        ``_transfer_dataman_id``, update_active_mission), so a failed upload changes nothing.
    current_mode_message: streams CURRENT_MODE (id 436, MAVLink development.xml) with its 1 Hz status
        group, as PX4 main does (mavlink_main.cpp ``configure_stream_local("CURRENT_MODE", 0.5f)``,
        streams/CURRENT_MODE.hpp): a message the pinned pymavlink 2.4.50 ardupilotmega dialect does
        not know, so a GCS meets a frame it cannot decode (sitl_mock/vehicle.py packs it with the CRC
        extra 193 of pymavlink's development dialect).
    frame_per_datagram: every frame leaves in a UDP datagram of its own, as PX4 sends each message
        when it is made (``Mavlink::send_finish``); PX4 SITL v1.15.4, measured 2026-12-05 with 16
        items in flight: one datagram per MISSION_REQUEST_INT (docs/results/upload_cpu.md, "Real
        PX4 SITL"). False: the frames of a tick, and the replies to one received datagram, leave
        together, as ArduPilot's UART driver sends what its buffer holds when it runs.
    ArduPilot ignores a GCS's MISSION_ACK during an upload (MissionItemProtocol has no handler for it:
    a session ends by completion, an item error or its 8 s timeout in ``update()``); PX4 ends it on
    MISSION_ACK(OPERATION_CANCELLED) from the partner (handle_mission_ack).
    """

    name: str
    autopilot: Autopilot
    uses_legacy_request: bool
    rerequest_s: float
    timeout_s: float
    home_at_seq0: bool
    capacity: dict[int, int]
    modes: dict[str, dict[str, int]]
    storage: dict[str, Callable[[MissionItem], MissionItem]]  # vehicle type -> what the autopilot keeps
    reacks_final_item: bool
    clear_denied_while_running: bool
    flight: dict[str, FlightRules] = field(default_factory=dict)  # vehicle type -> rules
    supports_partial_write: bool = field(default=True)
    clear_all_types: bool = True  # MISSION_CLEAR_ALL with mission_type ALL (255) understood
    error_on_stray_item: bool = False  # an item with no upload running -> MISSION_ACK(ERROR)
    mission_frame_for_positionless: bool = False  # PX4: positionless commands only in MAV_FRAME_MISSION
    extra_commands: frozenset[int] = frozenset()  # mission commands it has beyond the pinned dialect
    # AP_Mission::sanity_check_params: NaN/inf in params 1-4 of an item -> INVALID_PARAMn (NaN
    # allowed only where the command gives it a meaning, e.g. yaw of NAV_WAYPOINT / LAND / TAKEOFF)
    nan_params_rejected: bool = False
    sysid_enforce_params: bool = False  # MAV_OPTIONS bit 0 / MAV_GCS_SYSID (GCS_MAVLINK::accept_packet)
    second_uploader_result: MissionResult = MissionResult.DENIED
    same_partner_restarts: bool = True
    foreign_item_denied: bool = True
    stores_as_received: frozenset[int] = frozenset()
    current_mode_message: bool = False
    frame_per_datagram: bool = False

    def custom_mode(self, mode: str, vehicle_type: str = "multirotor") -> int:
        """HEARTBEAT custom_mode of a mode name; ValueError naming the mode if it does not exist."""
        table = self.modes[vehicle_type]
        try:
            return table[mode.upper()]
        except KeyError:
            raise ValueError(
                f"mode {mode!r} does not exist on {self.name} {vehicle_type}; known: {', '.join(table)}"
            ) from None

    def mode_name(self, custom_mode: int, vehicle_type: str = "multirotor") -> str | None:
        """Mode name of a HEARTBEAT custom_mode, None when the number is not in the table."""
        for name, number in self.modes[vehicle_type].items():
            if number == custom_mode:
                return name
        return None


ARDUPILOT = AutopilotProfile(
    name="ardupilot",
    autopilot=Autopilot.ARDUPILOTMEGA,
    uses_legacy_request=True,
    rerequest_s=1.0,
    timeout_s=8.0,
    home_at_seq0=True,
    capacity={MissionType.MISSION: 724, MissionType.FENCE: 84, MissionType.RALLY: 10},
    modes={"multirotor": ARDUCOPTER_MODES, "fixed_wing": ARDUPLANE_MODES},
    storage={"multirotor": stored.ARDUCOPTER, "fixed_wing": stored.ARDUPLANE},
    reacks_final_item=False,
    clear_denied_while_running=True,
    flight={"multirotor": ARDUCOPTER_FLIGHT, "fixed_wing": ARDUPLANE_FLIGHT},
    clear_all_types=False,  # GCS_Common.cpp: no protocol for MAV_MISSION_TYPE_ALL -> UNSUPPORTED
    error_on_stray_item=True,  # MissionItemProtocol::handle_mission_item: not receiving -> ERROR
    # ArduPilot master (24a84a47) flies these in its own autotest missions (ConditionLocation,
    # DO_CHANGE_RADIUS, HomeCircleInclusionFence); pymavlink 2.4.50's ardupilotmega lacks them
    extra_commands=frozenset({116, 219, 5005}),
    nan_params_rejected=True,
    sysid_enforce_params=True,
    stores_as_received=frozenset({MissionType.MISSION, MissionType.RALLY}),
)

PX4 = AutopilotProfile(
    name="px4",
    autopilot=Autopilot.PX4,
    uses_legacy_request=False,
    rerequest_s=0.25,
    timeout_s=5.0,
    home_at_seq0=False,
    capacity={MissionType.MISSION: 2000, MissionType.FENCE: 64, MissionType.RALLY: 32},
    modes={"multirotor": PX4_MODES, "fixed_wing": PX4_MODES},
    storage={"multirotor": stored.PX4, "fixed_wing": stored.PX4},
    reacks_final_item=True,
    clear_denied_while_running=False,
    flight={"multirotor": PX4_FLIGHT, "fixed_wing": PX4_FLIGHT},
    supports_partial_write=False,
    mission_frame_for_positionless=True,
    second_uploader_result=MissionResult.ERROR,
    same_partner_restarts=False,
    foreign_item_denied=False,
    current_mode_message=True,
    frame_per_datagram=True,
)

PROFILES: dict[str, AutopilotProfile] = {p.name: p for p in (ARDUPILOT, PX4)}
