"""One mock autopilot: its UDP link, message dispatch, commands, mission server and navigator.

The vehicle owns no physics: a fleet `World` holds every vehicle's kinematics in arrays and the
vehicle keeps its row index (`attach`). Mission-protocol messages go to the I/O-free
`MissionServer` (sitl_mock/mission_server.py), parameter messages to the I/O-free `ParamServer`
(sitl_mock/param_server.py); the vehicle sends whatever they return.

Commands (COMMAND_LONG or COMMAND_INT), each answered with COMMAND_ACK:
COMPONENT_ARM_DISARM, DO_SET_MODE (ArduPilot: param2 = custom mode; PX4: param2/param3 = main/sub
mode), MISSION_START (param1 first, param2 last item; 0/0 = whole mission), DO_CHANGE_SPEED (param2
[m/s], clamped to the airframe), DO_SET_MISSION_CURRENT
(FAILED when out of range), NAV_TAKEOFF (param7 [m above home]), NAV_RETURN_TO_LAUNCH, NAV_LAND,
PREFLIGHT_REBOOT_SHUTDOWN, REQUEST_MESSAGE / REQUEST_AUTOPILOT_CAPABILITIES (AUTOPILOT_VERSION,
HOME_POSITION); anything else -> UNSUPPORTED. SET_MODE and MISSION_SET_CURRENT messages work too.

Choices where the autopilots differ (we are lenient where a strict check would only get in the
way of a GCS under test, strict where a GCS must handle the refusal):
- Arming is allowed in any mode; a vehicle armed in AUTO with a mission starts it.
- MISSION_START needs a mission (FAILED otherwise) but not arming: like ArduCopter it switches to
  AUTO and the mission runs as soon as the vehicle is armed.
- Entering AUTO without a mission fails (ArduPilot). NAV_TAKEOFF needs arming and the ground and
  switches to TAKEOFF (plane, PX4) or GUIDED (copter). Disarming in the air needs force (21196).
- A vehicle disarms itself on touchdown (PX4 ``FlightRules.landed_disarm_s`` later).
- Reboot: lists lost unless ``persist_mission``, disarmed on the ground at home, peers forgotten
  (the GCS's next heartbeat reconnects it), time_boot_ms restarts.
"""

from __future__ import annotations

import asyncio
import logging
import math
import struct
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from gcs_planner.wire.dialect import has_position
from gcs_planner.wire.enums import CommandResult, MissionState, px4_custom_mode
from gcs_planner.wire.signing import NO_KEY
from gcs_planner.wire.types import MissionItem, MissionType
from gcs_planner.wire.wire import MissionCurrentMessage
from sitl_mock import telemetry
from sitl_mock.faults import LinkFaults
from sitl_mock.flight import AIRFRAMES, Airframe
from sitl_mock.geodesy import Home, HomeLike, to_geodetic
from sitl_mock.link import TRANSPORTS, VehicleLink, mavlink
from sitl_mock.mission_exec import Navigator
from sitl_mock.mission_server import MissionServer
from sitl_mock.param_server import ParamServer, stock_params
from sitl_mock.profiles import PROFILES
from sitl_mock.world import World
from sitl_mock.wpnav import STOCK_PARAMS as WP_STOCK_PARAMS
from sitl_mock.wpnav import WaypointNav

__all__ = ["DEFAULT_HOME", "MockVehicle", "VehicleState"]

log = logging.getLogger(__name__)

DEFAULT_HOME = Home(47.397742, 8.545594, 488.0)  # PX4 SITL's default home (Zurich)
COMPID = 1
FORCE_MAGIC = 21196
DEFAULT_TAKEOFF_ALT_M = 10.0
UNLIMITED_JERK_MPS3 = 1000.0  # the mock's acceleration is not jerk-limited: it ramps linearly
TAKEOFF_MODE_EARLY_M = 2.0  # ArduPlane's TAKEOFF mode is done this far below TKOFF_ALT [m]
_MAV_TYPE = {"multirotor": mavlink.MAV_TYPE_QUADROTOR, "fixed_wing": mavlink.MAV_TYPE_FIXED_WING}
_CAPABILITIES = (
    mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT
    | mavlink.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
    | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_INT
    | mavlink.MAV_PROTOCOL_CAPABILITY_SET_ATTITUDE_TARGET
    | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_FENCE
    | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_RALLY
    | mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2
)


# MAV_STANDARD_MODE (development.xml) of the mock's mode names; the rest are NON_STANDARD (0)
_STANDARD_MODES = {"POSCTL": 1, "LOITER": 1, "RTL": 5, "AUTO": 6, "LAND": 7, "TAKEOFF": 8}


class CurrentModeMessage(mavlink.MAVLink_message):
    """CURRENT_MODE (id 436, MAVLink development.xml; not in pymavlink 2.4.50's ardupilotmega), as PX4
    streams it: a message the GCS's dialect does not know. Packed with the CRC extra pymavlink's own
    development dialect gives it (193: pymavlink.dialects.v20.development.MAVLink_current_mode_message)."""

    id = 436
    msgname = "CURRENT_MODE"
    crc_extra = 193
    fieldnames = ["standard_mode", "custom_mode", "intended_custom_mode"]
    _PAYLOAD = struct.Struct("<IIB")  # wire order: the uint32 fields first

    def __init__(self, standard_mode: int, custom_mode: int, intended_custom_mode: int) -> None:
        mavlink.MAVLink_message.__init__(self, self.id, self.msgname)
        self._fieldnames = self.fieldnames
        self.standard_mode, self.custom_mode = standard_mode, custom_mode
        self.intended_custom_mode = intended_custom_mode

    def pack(self, mav: mavlink.MAVLink, force_mavlink1: bool = False) -> bytes:
        payload = self._PAYLOAD.pack(self.custom_mode, self.intended_custom_mode, self.standard_mode)
        return self._pack(mav, self.crc_extra, payload, force_mavlink1=force_mavlink1)


@dataclass(frozen=True)
class VehicleState:
    """Snapshot of one vehicle (thread-safe to pass around)."""

    sysid: int
    armed: bool
    mode: str
    airborne: bool
    mission_seq: int
    mission_total: int
    mission_state: MissionState
    mission_count: int
    reached: tuple[int, ...]
    battery_pct: float
    sim_time_s: float


def _check_identity(
    sysid: int, profile: str, vehicle_type: str, port: int, transport: str = "udpin", gcs: object = None
) -> None:
    if not (isinstance(sysid, int) and 1 <= sysid <= 254):
        raise ValueError(f"vehicle sysid must be an integer in 1..254, got {sysid!r}")
    if profile not in PROFILES:
        raise ValueError(f"vehicle profile must be one of {sorted(PROFILES)}, got {profile!r}")
    if vehicle_type not in AIRFRAMES:
        raise ValueError(f"vehicle_type must be one of {sorted(AIRFRAMES)}, got {vehicle_type!r}")
    if not (isinstance(port, int) and 0 <= port <= 65535):
        raise ValueError(f"vehicle port must be in 0..65535, got {port!r}")
    if transport not in TRANSPORTS:
        raise ValueError(f"vehicle transport must be one of {list(TRANSPORTS)}, got {transport!r}")
    if transport == "udpclient":
        ok = isinstance(gcs, tuple | list) and len(gcs) == 2 and isinstance(gcs[1], int)
        if not (ok and 0 < gcs[1] <= 65535):
            raise ValueError(f"a udpclient vehicle needs gcs=(HOST, PORT), where it sends; got {gcs!r}")


class MockVehicle:
    """A mock autopilot with system id ``sysid`` on UDP ``host:port`` (0 = ephemeral port).
    ``transport`` (sitl_mock/link.py): "udpin" (that port, answers whoever sent first), "udpclient"
    (an ephemeral port of ``host`` sending to ``gcs`` = (HOST, PORT) from the start) or "tcp"
    (listens on TCP ``host:port``, serves one GCS connection)."""

    def __init__(
        self,
        sysid: int,
        profile: str = "ardupilot",
        vehicle_type: str = "multirotor",
        home: HomeLike = DEFAULT_HOME,
        port: int = 0,
        faults: LinkFaults | None = None,
        capacity: int | None = None,
        *,
        host: str = "127.0.0.1",
        persist_mission: bool = False,
        non_atomic: bool | None = None,  # None: as the profile stores each list
        airframe: Airframe | None = None,
        signing_key: bytes | None = None,
        flight: dict | None = None,
        transport: str = "udpin",
        gcs: tuple[str, int] | None = None,
        params: dict[str, float] | None = None,
    ) -> None:
        _check_identity(sysid, profile, vehicle_type, port, transport, gcs)
        self.transport, self.gcs = transport, (None if gcs is None else (gcs[0], gcs[1]))
        self.sysid = sysid
        self.profile = PROFILES[profile]
        self.vehicle_type = vehicle_type
        self.flight = replace(self.profile.flight[vehicle_type], **(flight or {}))  # tests may turn rules off
        self.airframe = airframe or self._stock_airframe(vehicle_type)
        self.home = home
        self.host, self.port = host, port
        self.persist_mission = persist_mission
        self.mission_server = MissionServer(
            sysid, COMPID, self.profile, capacity=capacity, non_atomic=non_atomic, vehicle_type=vehicle_type
        )
        self.mission_server.on_change = self._on_list_change
        self.mission_server.on_current = self._on_server_current
        self.link = VehicleLink(
            sysid, self._on_message, faults or LinkFaults(), COMPID, self._on_new_peer, signing_key
        )
        self._init_params()
        for name, value in (params or {}).items():  # as a SITL's --defaults file
            if name not in self.params:
                raise ValueError(f"vehicle {sysid} has no parameter {name!r} to set")
            self.params[name] = float(value)
        self.streams: set[int] | None = set() if self.flight.streams_by_request else None  # None: all
        self.intervals: dict[int, float] = {}  # message id -> requested interval [s of vehicle time]
        self._offered: dict[int, int] = {}  # message id -> times the fleet's stream offered it
        self.mission_rejected = False  # PX4 feasibility check failed on the stored mission
        self._armed_at_s = math.inf  # sim time of arming while on the ground
        self._landed_disarm_at_s = math.inf  # sim time it disarms after a touchdown
        self._modes = self.profile.modes[vehicle_type]
        self._default_mode = next(m for m in ("STABILIZE", "MANUAL") if m in self._modes)
        self.mode = self._default_mode
        self.armed = False
        self.world: World | None = None
        self.index = -1
        self.nav: Navigator | None = None
        self.boot_sim_s = 0.0
        self._pending_start: tuple[int | None, int | None] | None = None
        self._syncing_seq = False
        self._after_ack: Callable[[], None] | None = None  # runs once the COMMAND_ACK is sent
        self._dispatch, self._commands = self._handlers()

    def _stock_airframe(self, vehicle_type: str) -> Airframe:
        """The airframe of a vehicle not tuned to a plan: its type's, climbing and sinking at its
        autopilot's stock mission rates where the rules have them (``FlightRules.vertical_params``)."""
        base = AIRFRAMES[vehicle_type]
        if self.flight.stock_vertical_mps is None or base.kind != "multirotor":
            return base
        climb, sink = self.flight.stock_vertical_mps
        return replace(base, climb_rate_mps=climb, sink_rate_mps=sink)

    def _init_params(self) -> None:
        """The parameters it serves (``params``, name -> value; ``param_types``, name -> MAV_PARAM_TYPE,
        REAL32 where absent): the flight rules' own, then a handful of its autopilot's stock ones
        (sitl_mock/param_server.py), served by ``param_server``."""
        self.params = dict(self.flight.params)
        if self.flight.airspeed_range:  # the airframe's limits, as a plane's parameters say them
            af = self.airframe
            self.params.update(AIRSPEED_MIN=af.min_speed_mps, AIRSPEED_MAX=af.max_speed_mps,
                               ROLL_LIMIT_DEG=math.degrees(af.max_bank_rad),
                               NAVL1_PERIOD=af.l1.period_s if af.l1 else 0.0,
                               RLL2SRV_TCONST=af.l1.roll_tau_s if af.l1 else 0.0)  # fmt: skip
        if self.scurve_legs:  # ArduCopter's stock values, which its legs fly by
            self.params.update(WP_STOCK_PARAMS)
        elif self.flight.ramp_params and self.airframe.kind == "multirotor":  # the ramp it flies
            accel, jerk = self.flight.ramp_params
            self.params.update({accel: self.airframe.accel_mps2, jerk: UNLIMITED_JERK_MPS3})
        if self.flight.vertical_params and self.airframe.kind == "multirotor":  # the climb it flies
            up, down = self.flight.vertical_params
            self.params.update({up: self.airframe.climb_rate_mps, down: self.airframe.sink_rate_mps})
        if self.profile.sysid_enforce_params:  # ArduPilot's defaults: every system id accepted
            for name, value in (("MAV_OPTIONS", 0.0), ("MAV_GCS_SYSID", 255.0), ("MAV_GCS_SYSID_HI", 0.0)):
                self.params.setdefault(name, value)
        self.param_types: dict[str, int] = {}
        for name, (value, param_type) in stock_params(self.flight.name, self.sysid).items():
            if name not in self.params:
                self.params[name], self.param_types[name] = value, param_type
        self.param_server = ParamServer(self.profile.name, self.params, self.param_types)

    def _handlers(self) -> tuple[dict[str, Callable], dict[int, Callable]]:
        """The handler of each message type and of each command the mock emulates."""
        messages = {
            "COMMAND_LONG": self._on_command,
            "COMMAND_INT": self._on_command,
            "SET_MODE": self._on_set_mode,
            "SETUP_SIGNING": self._on_setup_signing,
            "REQUEST_DATA_STREAM": self._on_request_data_stream,
            "PARAM_SET": self._on_param_message,
            "PARAM_REQUEST_READ": self._on_param_message,
            "PARAM_REQUEST_LIST": self._on_param_message,
        }
        commands = {
            mavlink.MAV_CMD_COMPONENT_ARM_DISARM: self._cmd_arm,
            mavlink.MAV_CMD_DO_SET_MODE: self._cmd_set_mode,
            mavlink.MAV_CMD_MISSION_START: self._cmd_mission_start,
            mavlink.MAV_CMD_DO_SET_MISSION_CURRENT: self._cmd_set_current,
            mavlink.MAV_CMD_NAV_TAKEOFF: self._cmd_takeoff,
            mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH: self._cmd_rtl,
            mavlink.MAV_CMD_DO_CHANGE_SPEED: self._cmd_change_speed,
            mavlink.MAV_CMD_NAV_LAND: self._cmd_land,
            mavlink.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN: self._cmd_reboot,
            mavlink.MAV_CMD_REQUEST_MESSAGE: self._cmd_request_message,
            mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: self._cmd_capabilities,
            mavlink.MAV_CMD_SET_MESSAGE_INTERVAL: self._cmd_message_interval,
        }
        return messages, commands

    # --- lifecycle ---------------------------------------------------------------------------
    def attach(self, world: World, index: int, home_enu_m: np.ndarray) -> None:
        """Bind to row ``index`` of a fleet's world (done by MockFleet before `start`)."""
        self.world, self.index = world, index
        self.home_enu_m = np.asarray(home_enu_m, dtype=float)
        self.nav = Navigator(
            world, index, self.airframe, self.home_enu_m, 1 if self.profile.home_at_seq0 else 0,
            emit_reached=self._emit_reached, emit_progress=self._emit_progress,
            emit_text=self.statustext, landed=self._on_landed, flight=self.flight,
            enter_mode=self._set_mode_name, airspeed_allowed=self.airspeed_allowed,
        )  # fmt: skip
        if self.profile.home_at_seq0:
            h = self.home
            self.mission_server.home = MissionItem(
                seq=0, frame=0, command=16, x=round(h.lat_deg * 1e7), y=round(h.lon_deg * 1e7), z=h.alt_m
            )
        if self.scurve_legs:
            world.kin.wpnav[index] = WaypointNav(self.params)
        self.boot_sim_s = world.sim_time_s

    @property
    def scurve_legs(self) -> bool:
        """Whether it flies ArduCopter's S-curve waypoint legs (FlightRules.scurve_legs)."""
        return (
            self.flight.scurve_legs
            and self.flight.name == "ArduCopter"
            and self.airframe.kind == "multirotor"
        )

    async def start(self) -> None:
        await self.link.open(self.host, self.port, self.transport, self.gcs)

    def close(self) -> None:
        self.link.close()

    @property
    def address(self) -> tuple[str, int]:
        return self.link.address

    # --- queries -----------------------------------------------------------------------------
    def position_enu(self) -> np.ndarray:
        """Reported position [m] ENU about the fleet origin (up = altitude above it)."""
        return self._world.kin.reported_pos()[self.index].copy()

    def position_geodetic(self) -> tuple[float, float, float]:
        """Reported position: latitude, longitude [deg], altitude [m AMSL]."""
        e, n, u = self.position_enu()
        lat, lon, alt = to_geodetic(e, n, u, self._world.frame)
        return lat, lon, alt

    @property
    def state(self) -> VehicleState:
        nav = self._nav
        return VehicleState(
            sysid=self.sysid,
            armed=self.armed,
            mode=self.mode,
            airborne=bool(self._world.kin.airborne()[self.index]),
            mission_seq=nav.seq,
            mission_total=nav.total,
            mission_state=nav.state,
            mission_count=len(nav.items),
            reached=tuple(seq for seq, _ in nav.reached),
            battery_pct=float(self._world.battery_pct[self.index]),
            sim_time_s=self._world.sim_time_s,
        )

    @property
    def time_boot_ms(self) -> int:
        return int((self._world.sim_time_s - self.boot_sim_s) * 1000.0) & 0xFFFFFFFF

    # --- actions (also used by the fleet's fault scripting) ----------------------------------
    def reboot(self) -> None:
        """Restart the autopilot: lists lost unless persisted, disarmed at home, peers forgotten."""
        if not self.persist_mission:
            self.mission_server.forget()
        world, i = self._world, self.index
        self.armed = False
        world.armed[i] = False
        self._set_mode_name(self._default_mode)
        self._pending_start = None
        nav = self._nav
        nav.running = False
        nav.reached.clear()
        world.kin.place(i, self.home_enu_m)
        world.kin.speed_cmd[i] = self.airframe.cruise_speed_mps
        nav.load(self.mission_server.items(MissionType.MISSION))
        self.boot_sim_s = world.sim_time_s
        self.param_server.stop()
        self.link.forget_peers()
        log.info("vehicle %d rebooted", self.sysid)

    def set_faults(self, faults: LinkFaults) -> None:
        self.link.set_faults(faults)

    def send(self, msg: mavlink.MAVLink_message) -> None:
        self.link.send(msg)

    def statustext(self, text: str, severity: int = mavlink.MAV_SEVERITY_INFO) -> None:
        self.send(telemetry.statustext(severity, text))

    def poll(self, wall_now_s: float) -> None:
        """Mission-protocol timers (wall clock: the GCS's re-request and timeout clock) and the
        ground auto-disarm (simulated clock)."""
        for msg in self.mission_server.poll(wall_now_s):
            self.send(msg)
        for msg in self.param_server.poll():
            self.send(msg)
        if self.armed and self._world.sim_time_s >= self._landed_disarm_at_s:
            self.statustext("Disarmed by landing")
            self._landed_disarm()
        if self.armed and self._world.sim_time_s - self._armed_at_s >= self.flight.auto_disarm_s:
            running = self.mode == "AUTO" and self._nav.running
            if not running and not self._world.kin.airborne()[self.index]:
                self.statustext("Disarmed by auto preflight disarming")
                self._disarm()
            self._armed_at_s = math.inf

    @property
    def has_position(self) -> bool:
        """Its position reports carry a position (FlightRules.position_fix_s after boot)."""
        fix_s = min(self.flight.position_fix_s, self.flight.arm_ready_s)
        return self._world.sim_time_s - self.boot_sim_s >= fix_s

    @property
    def ready_to_arm(self) -> bool:
        """Pre-arm checks pass (FlightRules.arm_ready_s after boot)."""
        return self._world.sim_time_s - self.boot_sim_s >= self.flight.arm_ready_s

    def wants(self, message_id: int) -> bool:
        """The GCS asked for this message's stream (always true where everything streams unasked)."""
        return self.streams is None or message_id in self.streams

    def due(self, message_id: int, stream_period_s: float) -> bool:
        """Whether a message the fleet offers with a stream of period ``stream_period_s`` [s of
        vehicle time] goes this time: every k-th offer, k the interval the GCS asked for it in
        stream periods (rounded, at least 1), as ArduPilot sends each message on its own interval
        quantised to its scheduler (GCS_MAVLINK::set_message_interval); without one, every offer.
        Counting offers, not clock readings, keeps the rate whatever the ticks' jitter."""
        interval = self.intervals.get(message_id)
        if interval is None:
            return True
        every = max(1, round(interval / stream_period_s))
        offered = self._offered.get(message_id, 0)
        self._offered[message_id] = offered + 1
        return offered % every == 0

    # --- telemetry ---------------------------------------------------------------------------
    def send_status(self) -> None:
        """The 1 Hz group: HEARTBEAT, SYS_STATUS, BATTERY_STATUS, VFR_HUD, MISSION_CURRENT."""
        world, i = self._world, self.index
        kin = world.kin
        airborne = bool(kin.airborne()[i])
        self.send(telemetry.heartbeat(
            _MAV_TYPE[self.vehicle_type], self.profile.autopilot, self.armed, self._modes[self.mode],
            self.armed or airborne,
        ))  # fmt: skip
        battery = float(world.battery_pct[i])
        current = float(world.current_a()[i])
        if self.wants(mavlink.MAVLINK_MSG_ID_SYS_STATUS):
            self.send(telemetry.sys_status(battery, current, prearm_ok=self.ready_to_arm))
        if self.wants(mavlink.MAVLINK_MSG_ID_BATTERY_STATUS):
            self.send(telemetry.battery_status(battery, current, float(world.consumed_mah[i])))
        if self.wants(mavlink.MAVLINK_MSG_ID_VFR_HUD):
            vel = kin.vel[i]
            gvel = kin.ground_vel()[i]
            throttle = 0 if not airborne else 50
            alt = float(kin.reported_pos()[i, 2] + world.frame.alt_m)
            self.send(telemetry.vfr_hud(
                float(np.linalg.norm(vel)), float(math.hypot(gvel[0], gvel[1])), float(kin.psi[i]), throttle,
                alt, float(gvel[2]),
            ))  # fmt: skip
        if self.wants(mavlink.MAVLINK_MSG_ID_MISSION_CURRENT):
            self.send(self._mission_current())
        if self.profile.current_mode_message:
            mode = self._modes[self.mode]
            self.send(CurrentModeMessage(_STANDARD_MODES.get(self.mode, 0), mode, mode))

    def send_home(self) -> None:
        """HOME_POSITION, once the vehicle has a position (ArduPilot GCS_Common.cpp
        ``GCS_MAVLINK::send_home_position`` sends none before home is set)."""
        if self.has_position:
            self.send(telemetry.home_position(self.home.lat_deg, self.home.lon_deg, self.home.alt_m))

    def stream_home(self) -> None:
        """The periodic HOME_POSITION, when streamed."""
        if self.wants(mavlink.MAVLINK_MSG_ID_HOME_POSITION):
            self.send_home()

    def _on_new_peer(self, addr: tuple) -> None:
        """Greet a new GCS at once (identity and home) instead of at the next 1 Hz / 0.2 Hz slot."""
        if self.world is not None:
            self.send_status()
            self.stream_home()

    def _mission_current(self) -> MissionCurrentMessage:
        nav, srv = self._nav, self.mission_server
        ids = (srv.opaque_id(t) for t in (MissionType.MISSION, MissionType.FENCE, MissionType.RALLY))
        mode = 1 if self.mode == "AUTO" else 2
        return MissionCurrentMessage(nav.seq if nav.has_mission else 0, nav.total, int(nav.state), mode, *ids)

    # --- receive -----------------------------------------------------------------------------
    def _on_message(self, msg: mavlink.MAVLink_message, addr: tuple) -> None:
        target = getattr(msg, "target_system", 0)
        if target not in (0, self.sysid) or self._refuses_sender(msg):
            return
        mtype = msg.get_type()
        if mtype.startswith("MISSION_"):
            for reply in self.mission_server.handle(msg, self._wall_now()):
                self.send(reply)
            return
        handler = self._dispatch.get(mtype)
        if handler is not None:
            handler(msg)

    def _refuses_sender(self, msg: mavlink.MAVLink_message) -> bool:
        """MAV_OPTIONS bit 0 (GCS_SYSID_ENFORCE; SYSID_ENFORCE before 4.7): only the GCS system ids
        MAV_GCS_SYSID..MAV_GCS_SYSID_HI (SYSID_MYGCS before 4.7), the vehicle's own and radios are
        heard (ArduPilot GCS_Common.cpp ``GCS_MAVLINK::accept_packet``, GCS.cpp ``GCS::sysid_is_gcs``)."""
        if not int(self.params.get("MAV_OPTIONS", 0.0)) & 1:
            return False
        sender, low = msg.get_srcSystem(), round(self.params.get("MAV_GCS_SYSID", 255.0))
        high = round(self.params.get("MAV_GCS_SYSID_HI", 0.0))
        gcs = sender == low if high <= low else low <= sender <= high
        radio = msg.get_type() in ("RADIO", "RADIO_STATUS")
        return not (gcs or radio or sender == self.sysid)

    def _on_setup_signing(self, msg: mavlink.MAVLink_message) -> None:
        """Take the key (ArduPilot: an all-zero key with timestamp 0 turns signing off) and its
        timestamp as the floor of the vehicle's own (``GCS_MAVLINK::load_signing_key``).

        With signing on, only a frame that verified with the current key is taken (the link drops
        the rest; checked again here). With signing off the key is taken from any system, as
        ArduPilot does: ``GCS_MAVLINK::handle_setup_signing`` checks neither the sender nor the link
        (its ``accept_unsigned_callback`` lets unsigned frames in on channel 0, USB, only once
        signing is on), and PX4 takes the first key on any link (``MavlinkSignControl``, "trust on
        first contact"). ArduPilot's defence is SYSID_ENFORCE (``_refuses_sender``); else provision
        keys over a trusted link."""
        if self.link.signing_key is not None and not getattr(msg, "_signed", False):
            return
        if self.armed and self.flight.signing_refused_armed:
            self.statustext("Signing setup refused: vehicle armed", mavlink.MAV_SEVERITY_WARNING)
            return
        key = bytes(msg.secret_key)
        off = key == NO_KEY and msg.initial_timestamp == 0
        self.link.set_signing_key(None if off else key, msg.initial_timestamp)

    def _on_request_data_stream(self, msg: mavlink.MAVLink_message) -> None:
        """REQUEST_DATA_STREAM (MAVProxy's way): switch a group of streams on or off."""
        ids = _DATA_STREAMS.get(msg.req_stream_id, ())
        if msg.req_stream_id == mavlink.MAV_DATA_STREAM_ALL:
            ids = tuple(i for group in _DATA_STREAMS.values() for i in group)
        self._set_streams(ids, bool(msg.start_stop) and msg.req_message_rate > 0)

    def _set_streams(self, ids, on: bool) -> None:
        if self.streams is None:
            return
        self.streams = self.streams | set(ids) if on else self.streams - set(ids)

    def _on_param_message(self, msg: mavlink.MAVLink_message) -> None:
        for reply in self.param_server.handle(msg):
            self.send(reply)

    def _wall_now(self) -> float:
        return asyncio.get_running_loop().time()

    def _on_command(self, msg: mavlink.MAVLink_message) -> None:
        if msg.target_component not in (0, COMPID):
            return
        if msg.get_type() == "COMMAND_INT":
            params = (msg.param1, msg.param2, msg.param3, msg.param4, float(msg.x), float(msg.y), msg.z)
        else:
            params = (msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6, msg.param7)
        handler = self._commands.get(msg.command)
        if handler is None:
            result = CommandResult.UNSUPPORTED
        elif _invalid_param(msg.command, params):
            result = CommandResult.DENIED
        else:
            result = handler(*params)
        self.send(mavlink.MAVLink_command_ack_message(
            msg.command, int(result), 0, 0, msg.get_srcSystem(), msg.get_srcComponent()
        ))  # fmt: skip
        after, self._after_ack = self._after_ack, None
        if after is not None:
            after()

    def _on_set_mode(self, msg: mavlink.MAVLink_message) -> None:
        name = self.profile.mode_name(msg.custom_mode, self.vehicle_type)
        ok = name is not None and self._set_mode_name(name)
        result = CommandResult.ACCEPTED if ok else CommandResult.FAILED
        self.send(mavlink.MAVLink_command_ack_message(
            mavlink.MAVLINK_MSG_ID_SET_MODE, int(result), 0, 0, msg.get_srcSystem(), msg.get_srcComponent()
        ))  # fmt: skip

    # --- commands ----------------------------------------------------------------------------
    def _cmd_arm(self, p1: float, p2: float, *_: float) -> CommandResult:
        world, i = self._world, self.index
        if p1 >= 0.5:
            if not self.armed:
                refusal = self._arming_refusal()
                if refusal:
                    self.statustext(refusal, mavlink.MAV_SEVERITY_CRITICAL)
                    return self.flight.arm_refusal
                self.armed = True
                world.armed[i] = True
                self._armed_at_s = world.sim_time_s
                self.statustext("Arming motors")
                self.send_home()
                if self.mode == "AUTO":
                    first, last = self._pending_start or (None, None)
                    self._pending_start = None
                    self._nav.start(first, last)
                elif self.mode == "TAKEOFF":
                    self._takeoff_mode()
            return CommandResult.ACCEPTED
        if not self.armed:
            return CommandResult.ACCEPTED
        if world.kin.airborne()[i] and round(p2) != FORCE_MAGIC:
            self.statustext("Disarm refused: in flight", mavlink.MAV_SEVERITY_WARNING)
            return CommandResult.FAILED
        self._disarm()
        world.kin.place(i, world.kin.pos[i])
        return CommandResult.ACCEPTED

    def _arming_refusal(self) -> str:
        """Why arming is refused now ('' when it is not)."""
        if not self.ready_to_arm:
            return self.flight.not_ready_text
        if self.mission_rejected and self.mode == "AUTO":
            return "Arming denied: Resolve system health failures first"
        land_start = any(it.command == mavlink.MAV_CMD_DO_LAND_START for it in self._nav.items)
        if self.flight.land_start_needs_autoland and land_start and not self.params.get("RTL_AUTOLAND"):
            return "PreArm: DO_LAND_START set and RTL_AUTOLAND disable"
        return ""

    def _takeoff_mode(self) -> None:
        """TAKEOFF mode's climb: ArduPlane's ModeTakeoff::update ends it within 2 m of TKOFF_ALT
        or TKOFF_DIST from where it began, whichever comes first, and turns into its loiter
        (docs/real-autopilots.md, ArduPlane table)."""
        name = self.flight.takeoff_param
        alt = self.params.get(name, DEFAULT_TAKEOFF_ALT_M) if name else DEFAULT_TAKEOFF_ALT_M
        self._nav.takeoff(alt - TAKEOFF_MODE_EARLY_M, run_m=self.params.get("TKOFF_DIST", math.inf))

    def _cmd_set_mode(self, p1: float, p2: float, p3: float, *_: float) -> CommandResult:
        custom = px4_custom_mode(int(p2), int(p3)) if self.profile.name == "px4" else int(p2)
        name = self.profile.mode_name(custom, self.vehicle_type)
        if name is None:
            return CommandResult.DENIED
        return CommandResult.ACCEPTED if self._set_mode_name(name) else CommandResult.FAILED

    def _cmd_mission_start(self, p1: float, p2: float, *_: float) -> CommandResult:
        nav = self._nav
        first, last = int(p1), int(p2)
        if not self.flight.start_range and (first or last):
            return CommandResult.DENIED  # ArduPilot: only (0, 0), then it resumes at the current item
        if not nav.has_mission:
            self.statustext("Mission start: no mission", mavlink.MAV_SEVERITY_WARNING)
            return CommandResult.FAILED
        if self.mission_rejected:
            return CommandResult.DENIED
        count = len(nav.items)
        first_seq = None if first == 0 else first
        last_seq = None if last == 0 else last
        if not (0 <= first < count) or (
            last_seq is not None and not (max(first, nav.first_seq) <= last < count)
        ):
            return CommandResult.DENIED
        if not self._set_mode_name("AUTO", start=False):
            return CommandResult.FAILED
        if self.flight.start_range:
            first_seq = first_seq if first_seq is not None else nav.first_seq
        if self.armed:
            nav.start(first_seq, last_seq)
        else:
            self._pending_start = (first_seq, last_seq)
        return CommandResult.ACCEPTED

    def _cmd_set_current(self, p1: float, p2: float, *_: float) -> CommandResult:
        seq = int(p1)
        nav = self._nav
        if seq != -1 and not nav.set_current(seq):
            return CommandResult.FAILED
        if round(p2) == 1 and nav.state == MissionState.COMPLETE:
            nav.state = MissionState.PAUSED
            self._emit_progress()
        return CommandResult.ACCEPTED

    def _cmd_takeoff(self, *params: float) -> CommandResult:
        """NAV_TAKEOFF as a command: param7 read as FlightRules.takeoff_command says."""
        if self.flight.takeoff_command == "refused":
            return CommandResult.FAILED
        alt_m = params[6]
        if (
            not self.armed
            or self._world.kin.airborne()[self.index]
            or not (math.isfinite(alt_m) and alt_m > 0)
        ):
            return CommandResult.FAILED
        if self.flight.takeoff_command == "amsl":
            alt_m -= self.home.alt_m
            if alt_m <= 0.0:
                self.statustext("Already higher than takeoff altitude", mavlink.MAV_SEVERITY_WARNING)
                return CommandResult.ACCEPTED
        self._set_mode_name("TAKEOFF" if "TAKEOFF" in self._modes else "GUIDED", start=False)
        self._nav.takeoff(alt_m)
        self.statustext(f"Takeoff to {alt_m:.1f} m")
        return CommandResult.ACCEPTED

    def _cmd_rtl(self, *_: float) -> CommandResult:
        return CommandResult.ACCEPTED if self._set_mode_name("RTL") else CommandResult.FAILED

    def airspeed_allowed(self, speed_mps: float) -> bool:
        """False for an airspeed outside [AIRSPEED_MIN, AIRSPEED_MAX] where the rules have the range."""
        if not self.flight.airspeed_range:
            return True
        return self.params["AIRSPEED_MIN"] <= speed_mps <= self.params["AIRSPEED_MAX"]

    def _cmd_change_speed(self, p1: float, p2: float, *_: float) -> CommandResult:
        """DO_CHANGE_SPEED as a command (param2 [m/s]; -1 or NaN: no change), clamped to the airframe."""
        if not math.isfinite(p2) or p2 < 0:
            return CommandResult.ACCEPTED
        if round(p1) == 1 and self.flight.groundspeed_is_minimum:
            self.statustext(f"Set groundspeed {p2:.0f}")  # a minimum ground speed: cruise unchanged
            return CommandResult.ACCEPTED
        if round(p1) == 0 and not self.airspeed_allowed(p2):
            return CommandResult.FAILED
        af = self.airframe
        self._world.kin.set_speed(self.index, float(np.clip(p2, af.min_speed_mps, af.max_speed_mps)))
        return CommandResult.ACCEPTED

    def _cmd_land(self, *_: float) -> CommandResult:
        if "LAND" not in self._modes:
            return CommandResult.UNSUPPORTED
        return CommandResult.ACCEPTED if self._set_mode_name("LAND") else CommandResult.FAILED

    def _cmd_reboot(self, p1: float, *_: float) -> CommandResult:
        if round(p1) != 1:
            return CommandResult.UNSUPPORTED
        if self.armed:
            return CommandResult.DENIED
        self._after_ack = self.reboot  # reboot after the ACK has left
        return CommandResult.ACCEPTED

    def _cmd_request_message(self, p1: float, *_: float) -> CommandResult:
        """The requested message follows the ACK (so a GCS waiting for the ACK does not skip it)."""
        msg_id = int(p1)
        if msg_id == mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            self._after_ack = self._send_version
        elif msg_id == mavlink.MAVLINK_MSG_ID_HOME_POSITION:
            self._after_ack = self.send_home
        else:
            return CommandResult.UNSUPPORTED
        return CommandResult.ACCEPTED

    def _cmd_message_interval(self, p1: float, p2: float, *_: float) -> CommandResult:
        """SET_MESSAGE_INTERVAL(message id, interval [us]; -1 = off, 0 = default): a positive
        interval is kept (``due``), never faster than the fleet's own rate for the message."""
        self._set_streams((int(p1),), p2 >= 0)
        if p2 > 0:
            self.intervals[int(p1)] = p2 / 1e6
        else:
            self.intervals.pop(int(p1), None)
        return CommandResult.ACCEPTED

    def _cmd_capabilities(self, *_: float) -> CommandResult:
        self._after_ack = self._send_version
        return CommandResult.ACCEPTED

    def _send_version(self) -> None:
        """AUTOPILOT_VERSION; uid = UDP port, so two mocks given one sysid report different uids."""
        uid = self.address[1]
        version = [0] * 8
        msg = mavlink.MAVLink_autopilot_version_message(
            _CAPABILITIES, 0, 0, 0, 0, version, version, version, 0, 0, uid
        )
        self.send(msg)

    # --- modes -------------------------------------------------------------------------------
    def _set_mode_name(self, name: str, start: bool = True) -> bool:
        """Switch to mode ``name`` and act on it; False (nothing changed) when refused."""
        nav = self._nav
        if name not in self._modes:
            return False
        if name == "AUTO" and not nav.has_mission:
            self.statustext("Mode change to AUTO failed: no mission", mavlink.MAV_SEVERITY_WARNING)
            return False
        changed = name != self.mode
        self.mode = name
        self.mission_server.mission_running = name == "AUTO"
        airborne = bool(self._world.kin.airborne()[self.index])
        if name != "AUTO":
            nav.pause()
            self._pending_start = None
        if name == "AUTO":
            if start and self.armed and (changed or not nav.running):
                nav.start()
        elif name == "RTL":
            nav.rtl() if airborne else nav.idle()
        elif name == "LAND":
            nav.land() if airborne else nav.idle()
        elif name == "TAKEOFF":
            if start and self.armed and not airborne:
                self._takeoff_mode()
        else:
            nav.hold()
        if changed:
            self.statustext(f"Mode {name}")
        return True

    # --- callbacks from the navigator and the mission server ---------------------------------
    def _emit_reached(self, seq: int) -> None:
        self.send(mavlink.MAVLink_mission_item_reached_message(seq))

    def _emit_progress(self) -> None:
        nav = self._nav
        if nav.has_mission and self.mission_server.current_seq != nav.seq:
            self._syncing_seq = True
            try:
                self.mission_server.set_current(nav.seq)
            finally:
                self._syncing_seq = False
        self.send(self._mission_current())

    def _on_landed(self) -> None:
        self.statustext("Landed")
        self._landed_disarm_at_s = self._world.sim_time_s + self.flight.landed_disarm_s
        if self.flight.landed_disarm_s <= 0.0:
            self._landed_disarm()

    def _landed_disarm(self) -> None:
        self._disarm()
        if self.flight.final_land_disarms and not self._nav.running:
            self._nav.reset()  # AP_Arming_Copter::disarm resets the mission
            self._emit_progress()

    def _disarm(self) -> None:
        self._armed_at_s = self._landed_disarm_at_s = math.inf
        self.armed = False
        self._world.armed[self.index] = False
        self._nav.idle()
        self.statustext("Disarming motors")

    def _on_list_change(self, mission_type: int) -> None:
        if mission_type == MissionType.MISSION:
            items = self.mission_server.items(MissionType.MISSION)
            rejected = self.flight.rejects_position_before_takeoff and _takeoff_not_first(items)
            self.mission_rejected = rejected
            if rejected:
                text = "Mission rejected: takeoff not first waypoint item"
                self.statustext(text, mavlink.MAV_SEVERITY_CRITICAL)
            self._nav.load(items)

    def _on_server_current(self, seq: int) -> None:
        if not self._syncing_seq:
            self._nav.set_current(seq)

    @property
    def _world(self) -> World:
        if self.world is None:
            raise RuntimeError(f"vehicle {self.sysid} is not part of a running MockFleet")
        return self.world

    @property
    def _nav(self) -> Navigator:
        if self.nav is None:
            raise RuntimeError(f"vehicle {self.sysid} is not part of a running MockFleet")
        return self.nav


_DATA_STREAMS = {  # MAV_DATA_STREAM -> the mock's messages in it (ArduPilot's grouping)
    mavlink.MAV_DATA_STREAM_EXTENDED_STATUS: (
        mavlink.MAVLINK_MSG_ID_SYS_STATUS, mavlink.MAVLINK_MSG_ID_MISSION_CURRENT,
        mavlink.MAVLINK_MSG_ID_BATTERY_STATUS,
    ),
    mavlink.MAV_DATA_STREAM_POSITION: (
        mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, mavlink.MAVLINK_MSG_ID_HOME_POSITION,
    ),
    mavlink.MAV_DATA_STREAM_EXTRA1: (mavlink.MAVLINK_MSG_ID_ATTITUDE,),
    mavlink.MAV_DATA_STREAM_EXTRA2: (mavlink.MAVLINK_MSG_ID_VFR_HUD,),
}  # fmt: skip


def _takeoff_not_first(items: list[MissionItem]) -> bool:
    """PX4's feasibility check: a positional item comes before the NAV_TAKEOFF."""
    seqs = [k for k, it in enumerate(items) if it.command == mavlink.MAV_CMD_NAV_TAKEOFF]
    if not seqs:
        return False
    return any(has_position(it.command) for it in items[: seqs[0]])


# The params (1-based) each command handler reads; NaN or inf in one of them -> COMMAND_ACK DENIED
# (MAV_RESULT_DENIED: "supported but one or more parameter values are invalid"). The MAVLink spec
# gives NaN a meaning in a few (DO_CHANGE_SPEED speed / throttle: "no change"; NAV_TAKEOFF yaw),
# allowed below. ArduPilot's handlers compare (``is_equal(param1, 1)``, ``is_zero``) and refuse
# what matches nothing; PX4's Commander checks ``PX4_ISFINITE`` where it reads a value. Neither
# crashes, and the mock must not either.
_READS = {
    mavlink.MAV_CMD_COMPONENT_ARM_DISARM: (1, 2),
    mavlink.MAV_CMD_DO_SET_MODE: (1, 2, 3),
    mavlink.MAV_CMD_MISSION_START: (1, 2),
    mavlink.MAV_CMD_DO_SET_MISSION_CURRENT: (1, 2),
    mavlink.MAV_CMD_NAV_TAKEOFF: (7,),
    mavlink.MAV_CMD_DO_CHANGE_SPEED: (1, 2),
    mavlink.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN: (1,),
    mavlink.MAV_CMD_REQUEST_MESSAGE: (1,),
    mavlink.MAV_CMD_SET_MESSAGE_INTERVAL: (1, 2),
}
_NAN_MEANS_DEFAULT = {mavlink.MAV_CMD_DO_CHANGE_SPEED: (2,)}


def _invalid_param(command: int, params: tuple[float, ...]) -> bool:
    """A param the command reads is inf, or NaN where NaN has no meaning."""
    nan_ok = _NAN_MEANS_DEFAULT.get(command, ())
    for k in _READS.get(command, ()):
        value = params[k - 1]
        if math.isinf(value) or (math.isnan(value) and k not in nan_ok):
            return True
    return False
