"""Flight operations shared by `fly` and the coalition HIL run: wait for vehicles, take off, start
routes on time, record tracks, keep the schedule, wait until done.

Choices (see also gcs_planner.flight):
- Two-phase start: every vehicle is armed and climbs (MAV_CMD_NAV_TAKEOFF) to its first
  waypoint's altitude; once all are there, each route starts (MAV_CMD_MISSION_START at the item
  after NAV_TAKEOFF) at the common start plus its planned delay, less the time it loses
  accelerating to cruise (v / 2a). A fixed wing, which cannot wait in place, starts its route as
  soon as it is up.
- A vehicle is "up" once no lower than TAKEOFF_ALT_TOL_M below its take-off altitude; a lost
  COMMAND_ACK makes a retried take-off fail (already armed / airborne), which counts as up.
"""

from __future__ import annotations

import asyncio
import logging
import math
from collections.abc import Callable, Mapping

import numpy as np

from gcs_planner.autopilots import AutopilotQuirks, quirks_for
from gcs_planner.core.errors import UserError
from gcs_planner.core.geo import Origin, geodetic_to_enu
from gcs_planner.core.lockstep import now_s
from gcs_planner.flight.starts import CLIMB_RUN_PER_M
from gcs_planner.flight.timekeeping import ScheduleKeeper
from gcs_planner.geometry.ramp import ramp_loss_s
from gcs_planner.mavlink.actions import change_speed, start_mission_at, take_off
from gcs_planner.mavlink.errors import MavlinkError
from gcs_planner.mavlink.link import MavlinkLink, check_signing
from gcs_planner.mavlink.vehicle_status import VehicleStatus
from gcs_planner.missions.items import plan_to_items
from gcs_planner.model.plan import Plan, land_point
from gcs_planner.safety.conformance import Track
from gcs_planner.wire.units import impossible_position, reports_no_fix

__all__ = [
    "KEEPER_PERIOD_S", "FrameClock", "TrackRecorder", "accel_lead_s", "boot_clock", "build_missions",
    "keep_schedule", "receive_clock", "route_seq",
    "start_routes", "take_off_all", "vehicle_quirks", "wait_for_vehicles", "wait_until_done",
]  # fmt: skip

log = logging.getLogger(__name__)

ARM_TIMEOUT_S = 120.0  # vehicle time to pass pre-arm checks (ArduCopter SITL needs ~45 s after boot)
TAKEOFF_CLIMB_MPS = 2.0  # conservative climb rate for the flight-time budget
LAND_SPEED_MPS = 1.0  # conservative landing descent rate for the flight-time budget
TAKEOFF_ATTEMPTS = 3
TAKEOFF_ALT_TOL_M = 1.0  # a vehicle is "up" once no lower than this below its take-off altitude
PLANE_CLIMB_PAST_M = 2.0  # a plane that climbs into its route is sent this much higher [m]
PLANE_RUN_FACTOR = 3.0  # ... and its take-off may run this many times its planned climb run
NAV_TAKEOFF = 22  # MAV_CMD_NAV_TAKEOFF
KEEPER_PERIOD_S = 0.5  # schedule-keeping period [s of flight time]
# a completion counts where the track ends this near the mission's end [m]: a multirotor lands or
# holds at it; a plane lands on a run past it or loiters round it
END_RADIUS_M = 50.0
PLANE_END_M = 500.0


FrameClock = Callable[[object, float], float]  # (message, receive time [Unix s]) -> flight time [s]


def boot_clock(msg, t_s: float) -> float:
    """The vehicle's own time_boot_ms: one simulated clock when the vehicles share it (the mock)."""
    return msg.time_boot_ms / 1000.0


def receive_clock(rate: float = 1.0, zero_s: float = 0.0) -> FrameClock:
    """The GCS's receive time since ``zero_s``, times ``rate`` (the vehicles' speed-up): one clock
    for vehicles that each boot on a clock of their own (real autopilots, several SITLs)."""
    return lambda msg, t_s: (t_s - zero_s) * rate


class TrackRecorder:
    """Collects each vehicle's positions from the link's frames (completion is VehicleStatus's).

    A vehicle in ``relative`` (its plan gives altitudes above its home, the "relative" frame) is
    recorded at its height above home (GLOBAL_POSITION_INT.relative_alt) over the origin's
    altitude: that is what its mission tells it to fly, whatever its home's AMSL altitude (a GPS's
    error, a SITL started elsewhere: PX4 SIH's home is 32 m AMSL unless SIH_LOC_H0 is set). The
    others (plans over a site's terrain, "amsl") by their AMSL altitude."""

    def __init__(self, origin: Origin, clock: FrameClock, sysids, relative=()) -> None:
        self.origin = origin
        self.clock = clock
        self.relative = frozenset(relative)
        self.samples: dict[int, list[tuple[float, float, float, float]]] = {s: [] for s in sysids}
        self.completed: dict[int, bool] = {}
        self.impossible: dict[int, int] = {}  # sysid -> reports of a position that cannot be

    def on_frame(self, msg, raw: bytes, t_s: float) -> None:
        sysid = msg.get_srcSystem()
        if sysid not in self.samples or msg.get_type() != "GLOBAL_POSITION_INT":
            return
        if reports_no_fix(msg):
            if impossible_position(msg):
                self.impossible[sysid] = self.impossible.get(sysid, 0) + 1
            return
        alt = self.origin.alt_m + msg.relative_alt / 1000.0 if sysid in self.relative else msg.alt / 1000.0
        self.samples[sysid].append((self.clock(msg, t_s), msg.lat / 1e7, msg.lon / 1e7, alt))

    def latest(self, sysid: int) -> tuple[float, np.ndarray] | None:
        """Time [s] and ENU position [m] of the vehicle's newest position report."""
        if not self.samples[sysid]:
            return None
        t, lat, lon, alt = self.samples[sysid][-1]
        return t, np.array(geodetic_to_enu(lat, lon, alt, self.origin))

    def positions_since(self, sysid: int, t_s: float) -> np.ndarray:
        """(M, 3) ENU positions [m] of the vehicle's reports from t_s on."""
        rows = self.samples[sysid]
        k = len(rows)
        while k > 0 and rows[k - 1][0] >= t_s:
            k -= 1
        if k == len(rows):
            return np.zeros((0, 3))
        arr = np.asarray(rows[k:], dtype=float)
        return np.column_stack(geodetic_to_enu(arr[:, 1], arr[:, 2], arr[:, 3], self.origin))

    def now_s(self) -> float:
        """The newest report time over all vehicles (the fleet's clock)."""
        return max((rows[-1][0] for rows in self.samples.values() if rows), default=0.0)

    def tracks(self) -> dict[int, Track]:
        out = {}
        for sysid, rows in self.samples.items():
            if not rows:
                continue
            arr = np.asarray(rows, dtype=float)
            e, n, u = geodetic_to_enu(arr[:, 1], arr[:, 2], arr[:, 3], self.origin)
            order = np.argsort(arr[:, 0], kind="stable")
            out[sysid] = Track(
                arr[order, 0], np.column_stack([e, n, u])[order], self.completed.get(sysid, False)
            )
        return out


async def wait_for_vehicles(link: MavlinkLink, sysids: list[int], timeout_s: float) -> None:
    """Until every vehicle's autopilot sent a HEARTBEAT (any other frame, or a camera's HEARTBEAT,
    says nothing of what the vehicle is); duplicate system ids are refused."""
    deadline = now_s() + timeout_s
    while now_s() < deadline:
        if all(heard(link, s) for s in sysids):
            break
        await asyncio.sleep(0.05)
    missing = [s for s in sysids if not heard(link, s)]
    check_signing(link, sysids)
    if missing:
        raise UserError(f"no autopilot HEARTBEAT from sysid {missing} within {timeout_s:.0f} s")
    duplicates = link.duplicates()
    if duplicates:
        raise UserError(f"system ids answer from several addresses (refusing to merge): {duplicates}")


def heard(link: MavlinkLink, sysid: int) -> bool:
    return getattr(link.vehicles.get(sysid), "autopilot", None) is not None


def vehicle_quirks(link: MavlinkLink, sysids: list[int]) -> dict[int, AutopilotQuirks]:
    """Each vehicle's autopilot entry, from the HEARTBEAT it sent."""
    return {s: quirks_for(link.vehicles[s].autopilot, link.vehicles[s].mav_type) for s in sysids}


def build_missions(plan: Plan, quirks: dict[int, AutopilotQuirks]) -> dict[int, list]:
    """Each vehicle's mission items in its autopilot's conventions (validated)."""
    return {vp.sysid: plan_to_items(vp, plan.origin, quirks[vp.sysid].conventions) for vp in plan.vehicles}


async def take_off_all(
    link: MavlinkLink,
    plan: Plan,
    status: VehicleStatus,
    speedup: float,
    quirks: dict[int, AutopilotQuirks],
    workers: int = 8,
    timeout_factor: float = 2.0,
    progress=None,
    missions: dict | None = None,
    on_route_start: Callable[[int], None] | None = None,
) -> None:
    """Arm every vehicle once it is ready and climb it to its first waypoint's altitude; return
    when all are there. With ``missions``, a fixed wing (which cannot wait in place) starts its
    route as soon as it is up (``start_routes`` leaves it out), then ``on_route_start(sysid)``."""
    gate = asyncio.Semaphore(workers)
    targets = {vp.sysid: float(vp.waypoints[0, 2]) for vp in plan.vehicles}

    tolerance = {s: TAKEOFF_ALT_TOL_M + q.takeoff_level_off_m for s, q in quirks.items()}

    def late() -> list[int]:
        return [s for s, z in targets.items() if (status.tracks[s].rel_alt_m or -1e9) < z - tolerance[s]]

    async def climb_into_route(vp) -> None:
        while vp.sysid in late():
            await asyncio.sleep(0.02)
        items = missions[vp.sysid]
        await start_mission_at(link, vp.sysid, quirks[vp.sysid], route_seq(items), len(items) - 1)
        if on_route_start is not None:
            on_route_start(vp.sysid)

    def waiting(sysid: int, reason: str) -> None:
        log.info("sysid %d not ready to arm: %s", sysid, reason)
        if progress:
            progress("wait", sysid, reason)

    async def one(vp) -> None:
        async with gate:
            q = quirks[vp.sysid]
            for attempt in range(1, TAKEOFF_ATTEMPTS + 1):
                try:
                    climbing_in = missions is not None and vp.vehicle_type == "fixed_wing"
                    z0 = float(vp.waypoints[0, 2])
                    await take_off(
                        link, status, vp.sysid, q, z0, ARM_TIMEOUT_S, speedup, waiting,
                        PLANE_CLIMB_PAST_M if climbing_in else 0.0, PLANE_RUN_FACTOR * z0 * CLIMB_RUN_PER_M,
                    )  # fmt: skip
                    break
                except MavlinkError as exc:
                    # a lost ACK makes the retried command fail (already armed / airborne)
                    if (status.tracks[vp.sysid].rel_alt_m or 0.0) > TAKEOFF_ALT_TOL_M:
                        return
                    if attempt == TAKEOFF_ATTEMPTS:
                        reason = status.reason(vp.sysid)
                        raise UserError(
                            f"vehicle {vp.vehicle_id} (sysid {vp.sysid}) could not take off: {exc}"
                            + (f" ({reason})" if reason else "")
                        ) from exc
                    log.warning("sysid %d take-off attempt %d failed: %s", vp.sysid, attempt, exc)
                    await asyncio.sleep(1.0 / speedup)
        if missions is not None and vp.vehicle_type == "fixed_wing":
            climbs.append(asyncio.create_task(climb_into_route(vp)))

    climbs: list[asyncio.Task] = []
    await asyncio.gather(*(one(vp) for vp in plan.vehicles))
    climb_s = max(float(vp.waypoints[0, 2]) for vp in plan.vehicles) / TAKEOFF_CLIMB_MPS
    deadline = now_s() + climb_s * timeout_factor / speedup + 10.0
    while now_s() < deadline and late():
        await asyncio.sleep(0.05)
    if late():
        for task in climbs:
            task.cancel()
        seen = {s: status.tracks[s].rel_alt_m for s in late()}
        raise UserError(
            f"sysid {late()} did not reach take-off altitude in time (relative altitude {seen})"
            + "".join(_state_of(link, status, s) for s in late())
        )
    await asyncio.gather(*climbs)


def _state_of(link: MavlinkLink, status: VehicleStatus, sysid: int) -> str:
    """'; sysid N disarmed: <its newest text>' for a vehicle that gave up its climb (PX4 SIH once
    detected a landing 0.8 m up and disarmed), else its newest text, if any."""
    info = link.vehicles.get(sysid)
    disarmed = " disarmed" if info is not None and not info.armed else ""
    text = status.reason(sysid)
    return f"; sysid {sysid}{disarmed}: {text}" if disarmed or text else ""


def accel_lead_s(vp, accel_mps2: float, jerk_mps3: float = math.inf, latency_s: float = 0.0) -> float:
    """How much earlier than planned a route starts, so that accelerating from the hover puts the
    vehicle where a plan assuming instant cruise speed has it: the time lost on the ramp to cruise
    speed (geometry.ramp), plus the autopilot's latency from MISSION_START to moving."""
    return ramp_loss_s(vp.first_leg_speed_mps, accel_mps2, jerk_mps3) + latency_s


async def start_routes(
    link: MavlinkLink,
    plan: Plan,
    missions: dict,
    speedup: float,
    logger,
    lead_s: float,
    leads: dict[int, float],
    quirks: dict[int, AutopilotQuirks],
    started: frozenset[int] = frozenset(),
    on_start: Callable[[int, float], None] | None = None,
) -> None:
    """Start each route (the item after NAV_TAKEOFF) at its planned start time, but those in
    ``started`` (fixed wings that climbed into theirs).

    Route time 0 is ``lead_s`` after now; each route starts its own acceleration lead earlier.
    ``on_start(sysid, route_s)`` is called as each start is sent, with the route time it was due at.
    """
    t0 = now_s()

    async def one(vp) -> None:
        items = missions[vp.sysid]
        if vp.sysid in started:
            return
        first = route_seq(items)
        offset_s = max(vp.takeoff_delay_s, float(vp.times_s[0]))  # planned time at the first waypoint
        start_s = lead_s + offset_s - leads[vp.sysid]
        await asyncio.sleep(max(0.0, t0 + start_s / speedup - now_s()))
        if on_start is not None:
            on_start(vp.sysid, offset_s - leads[vp.sysid])
        try:
            await start_mission_at(link, vp.sysid, quirks[vp.sysid], first, len(items) - 1)
        except MavlinkError as exc:
            raise UserError(
                f"vehicle {vp.vehicle_id} (sysid {vp.sysid}) refused the mission start: {exc}"
            ) from exc
        logger.log_event({"event": "route_start", "sysid": vp.sysid, "planned_offset_s": offset_s})

    await asyncio.gather(*(one(vp) for vp in plan.vehicles))


def route_seq(items) -> int:
    """The route's first item: the one after NAV_TAKEOFF."""
    return next(i for i, it in enumerate(items) if it.command == NAV_TAKEOFF) + 1


async def wait_until_done(
    link: MavlinkLink,
    recorder: TrackRecorder,
    status: VehicleStatus,
    plan: Plan,
    speedup: float,
    timeout_factor: float,
    progress,
    keeper: ScheduleKeeper | None,
    route_t0_s: Mapping[int, float],
    quirks: dict[int, AutopilotQuirks],
) -> None:
    """Until every vehicle's mission is done (or the plan's time x timeout_factor), keeping the
    schedule: ``route_t0_s[sysid]`` is when that vehicle's route time 0 was, on the recorder's clock."""
    descent_s = max(float(v.waypoints[-1, 2]) for v in plan.vehicles) / LAND_SPEED_MPS
    planned_s = max(float(v.path_times_s[-1]) + v.takeoff_delay_s for v in plan.vehicles) + descent_s
    budget_s = planned_s * timeout_factor / speedup + 10.0
    deadline = now_s() + budget_s
    total = len(plan.vehicles)
    plans = {vp.sysid: vp for vp in plan.vehicles}
    confirmed: set[int] = set()

    def done() -> set[int]:
        for sysid, track in status.tracks.items():
            if not track.done or sysid in confirmed:
                continue
            if at_route_end(recorder, plans[sysid]):
                confirmed.add(sysid)
            else:  # a claim made away from the end is dropped, not kept until the vehicle comes near
                track.done = False
        return confirmed

    while now_s() < deadline and len(done()) < total:
        if progress:
            progress("fly", len(done()), total)
        if keeper is not None:
            keep_schedule(link, recorder, status, keeper, route_t0_s, quirks)
        await asyncio.sleep(KEEPER_PERIOD_S / speedup)
    if progress:
        progress("fly", len(done()), total)
    recorder.completed.update({s: s in confirmed for s in plans})
    # a little more telemetry after the last item (landing) for the log
    await asyncio.sleep(min(1.0, 5.0 / speedup))


def at_route_end(recorder: TrackRecorder, vp) -> bool:
    """Whether the vehicle's newest report is where its mission ends (its last waypoint or its land
    point): a completion the vehicle reports is believed only where its track shows it (a forged
    MISSION_ITEM_REACHED from the vehicle's address must not end a flight)."""
    latest = recorder.latest(vp.sysid)
    if latest is None:
        return False
    radius = PLANE_END_M if vp.vehicle_type == "fixed_wing" else END_RADIUS_M
    ends = (vp.waypoints[-1, :2], land_point(vp)[:2])
    return min(float(np.hypot(*(latest[1][:2] - end))) for end in ends) <= radius


def keep_schedule(
    link: MavlinkLink,
    recorder: TrackRecorder,
    status: VehicleStatus,
    keeper: ScheduleKeeper,
    route_t0_s: Mapping[int, float],
    quirks: dict[int, AutopilotQuirks],
) -> None:
    for sysid, track in status.tracks.items():
        if not track.started or track.done:
            continue
        latest = recorder.latest(sysid)
        if latest is None:
            continue
        t_s, position = latest
        speed = keeper.speed_command(sysid, t_s - route_t0_s[sysid], position)
        if speed is not None:
            change_speed(link, sysid, quirks[sysid], speed)
