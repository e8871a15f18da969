"""What an autopilot family is to the tool: its conventions as fields, its ways as methods.

A family (one module beside this one) is an ``AutopilotQuirks`` subclass instance: fields for what
the tool reads (modes, streams, limits), methods for what it does differently (take-off, mission
start) and ``matches`` for the HEARTBEAT that identifies it. The methods drive a vehicle through a
``VehiclePort`` (gcs_planner.mavlink.actions implements it), so this layer sends nothing itself.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from typing import Protocol

__all__ = ["AutopilotQuirks", "Conventions", "VehiclePort"]


class Conventions(StrEnum):
    """Mission item conventions: ArduPilot keeps the home at seq 0, PX4 and MAVSDK do not."""

    ARDUPILOT = "ardupilot"
    PX4 = "px4"


class VehiclePort(Protocol):
    """The commands a family's methods drive one vehicle with."""

    async def set_param(self, name: str, value: float) -> float: ...
    async def set_mode(self, mode: str) -> None: ...
    async def arm_when_ready(self) -> None: ...
    async def takeoff(self, param7: float) -> None: ...
    def home_amsl_m(self) -> float: ...
    async def mission_start(self, first: int, last: int) -> None: ...
    async def set_current(self, seq: int) -> None: ...


@dataclass(frozen=True)
class AutopilotQuirks:
    """One autopilot family; every field is a difference the tool has to act on."""

    name: str
    conventions: Conventions
    pipelined: bool  # drops items whose seq it does not wait for: items in flight are safe
    modes: dict[str, int] | None  # mode name -> HEARTBEAT custom_mode (None: no named modes)
    arm_mode: str | None  # mode to arm in before a take-off (None: arm in the current mode)
    start_arm_mode: str | None  # mode to arm in before MISSION_START (ArduCopter refuses to arm in AUTO)
    speed_type: float  # DO_CHANGE_SPEED param1 for schedule keeping
    clear_all_at_once: bool  # MISSION_CLEAR_ALL with mission_type ALL (255) is understood
    streams_by_request: bool  # streams telemetry only when asked (stock ArduPilot SRn_* = 0)
    return_mode: str | None  # the mode that brings a vehicle home (safe end)
    land_mode: str | None  # the mode that lands it where it is (None: no such mode)
    readback: str  # the name of its read-back model in readback.py (loaded when a verify needs it: numpy)
    # parameters of the airspeed range and bank limit, [min m/s, max m/s, roll deg] (None: none)
    flight_limits: tuple[str, str, str] | None = None
    # parameters of its L1 guidance's period [s] and its roll controller's time constant [s]
    l1_params: tuple[str, str] | None = None
    # list types (mission_type) written in place as items arrive: a failed upload leaves a mix, so
    # the client reads the list back to say what the vehicle holds
    stores_as_received: frozenset[int] = frozenset({0, 1, 2})
    # how long after its MISSION_ACK the autopilot may still refuse a mission [s], and the words it
    # refuses with (lower case)
    verdict_after_ack_s: float = 0.0
    rejection_texts: tuple[str, ...] = ()
    # parameters of its waypoint navigation's acceleration and jerk limits, with their unit scale
    # to m/s^2 and m/s^3 (None: not known): a route starts from the hover on this S-curve ramp
    ramp_params: tuple[str, str, float] | None = None
    # parameters of its climb and descent speed in missions [m/s] (None: not known): a plan that
    # climbs or descends faster is flown late (flight/limits.py)
    vertical_params: tuple[str, str] | None = None
    # the rest of the parameters of ArduCopter's S-curve legs (geometry/scurve.py), [vertical
    # acceleration m/s^2, waypoint radius m, corner acceleration m/s^2, attitude input time
    # constant s] (None: the autopilot does not fly its legs that way)
    waypoint_nav_params: tuple[str, str, str, str] | None = None
    start_latency_s: float = 0.0  # from MISSION_START to moving along the route [s] (measured)
    takeoff_level_off_m: float = 0.0  # its take-off ends this far below the target altitude [m]
    params_bytewise: bool = False  # PARAM_VALUE integers sent bytewise, not cast to float (MAVProxy)
    stack: str = ""  # the name QGroundControl writes as a parameter file's "Stack"
    signing_note: str | None = None  # what signing leaves open on this autopilot, said after set-up
    fence_alt_param: str | None = None  # the fence's ceiling [m above home] (a fence item cannot hold it)

    def matches(self, autopilot: int | None, mav_type: int | None) -> bool:
        """Whether a HEARTBEAT with these MAV_AUTOPILOT and MAV_TYPE fields is this family's."""
        raise NotImplementedError

    async def take_off(
        self, port: VehiclePort, alt_m: float, climb_past_m: float, takeoff_dist_m: float
    ) -> None:
        """Arm (once ready) and climb to ``alt_m`` above home: MAV_CMD_NAV_TAKEOFF, param7 above home."""
        await self.arm(port)
        await port.takeoff(alt_m)

    async def arm(self, port: VehiclePort) -> None:
        """Arm in the family's arming mode, once the vehicle says it is ready."""
        if self.arm_mode is not None:
            await port.set_mode(self.arm_mode)
        await port.arm_when_ready()

    async def start_mission(self, port: VehiclePort, first: int, last: int) -> None:
        """Run the mission from item ``first`` to ``last``: MISSION_START(first, last)."""
        await port.mission_start(first, last)

    def mode_command_params(self, custom_mode: int) -> tuple[float, ...]:
        """MAV_CMD_DO_SET_MODE param2.. for a HEARTBEAT custom_mode: the number itself."""
        return (float(custom_mode),)

    def readback_model(self):
        """What the autopilot returns of an item sent (readback.Model)."""
        from gcs_planner.autopilots import readback

        return getattr(readback, self.readback)

    @property
    def home_at_seq0(self) -> bool:
        return self.conventions is Conventions.ARDUPILOT
