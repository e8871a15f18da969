"""The hardware-in-the-loop run: plan -> missions -> vehicles -> telemetry log -> conformance.

Mirrors the seed papers' HIL setup (planner -> datalink -> flight controller -> telemetry ->
display): the plan's missions are uploaded to every vehicle concurrently over MAVLink, the fleet
is armed and started, every received frame is logged to MCAP (and .tlog on request), and the
flown tracks are checked against the plan (gcs_planner.conformance). The vehicles are mock
autopilots (sitl_mock) started here, or real ones / SITL reached with ``connect`` URLs.

Choices:
- Each mock vehicle's home is the plan's first waypoint projected to the ground, so mission
  altitudes (relative to home) equal plan ``z`` on the flat mock world, and its airframe is
  tuned to the planned speed and turn radius (``_airframe_for``).
- Track time is the vehicle's ``time_boot_ms`` for mocks (one simulated clock for the whole fleet,
  so separations are compared at the same instant whatever the speed-up) and the receive time
  for real vehicles, whose boot clocks differ.
- Two-phase start, so that the plan's timing (and with it the planned separation) holds in the
  air: every vehicle is armed and takes off (MAV_CMD_NAV_TAKEOFF) to its first waypoint's
  altitude; once all hover there, each vehicle's route starts with MAV_CMD_MISSION_START at the
  item after NAV_TAKEOFF, at the common start time plus its planned delay (delayed take-off as
  a timed start; the mission's NAV_DELAY is then skipped), less the time the vehicle loses
  accelerating to cruise speed (v / 2a, a = ROUTE_ACCEL_MPS2). Climb rates differ between
  vehicles and altitudes, so a one-shot start would shift every route by its own climb time.
- While the routes run, a ScheduleKeeper (gcs_planner.timekeeping) sends each vehicle ground
  speed set-points (MAV_CMD_DO_CHANGE_SPEED) that hold it to the plan's timing; autopilots
  slow for corners and would otherwise fall behind the schedule the separation was planned on.
  ``keep_schedule=False`` flies the bare missions.
- A mission is complete when MISSION_CURRENT reports mission_state COMPLETE or the last item's
  MISSION_ITEM_REACHED arrives.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from gcs_planner.conformance import MovingObstacle, Track, VehicleReport, conformance_report
from gcs_planner.errors import UserError
from gcs_planner.flight_report import write_flight_report
from gcs_planner.geo import Origin, enu_to_geodetic, geodetic_to_enu
from gcs_planner.mavlink.actions import change_speed, safe_end, start_mission_at, take_off
from gcs_planner.mavlink.autopilots import AutopilotQuirks, quirks_for, quirks_named
from gcs_planner.mavlink.errors import MavlinkError
from gcs_planner.mavlink.fleet import VehicleResult, upload_fleet
from gcs_planner.mavlink.items import AUTOPILOTS, plan_to_items
from gcs_planner.mavlink.link import MavlinkLink
from gcs_planner.mavlink.preflight import request_streams
from gcs_planner.mavlink.vehicle_status import VehicleStatus
from gcs_planner.plan import Plan
from gcs_planner.scenario import Scenario
from gcs_planner.telemetry import FlightLogger
from gcs_planner.timekeeping import ScheduleKeeper

__all__ = ["FlyOptions", "FlyResult", "fly"]

log = logging.getLogger(__name__)

HEARTBEAT_WAIT_S = 10.0
REAL_HEARTBEAT_WAIT_S = 30.0  # real vehicles / SITL started by hand
ARM_TIMEOUT_S = 120.0  # vehicle time to pass pre-arm checks (ArduCopter SITL needs ~45 s after boot)
TAKEOFF_CLIMB_MPS = 2.0  # conservative climb rate for the flight-time budget
LAND_SPEED_MPS = 1.0  # conservative landing descent rate for the flight-time budget
TAKEOFF_ATTEMPTS = 3
TAKEOFF_ALT_TOL_M = 1.0  # a vehicle is "up" once no lower than this below its take-off altitude
NAV_TAKEOFF = 22  # MAV_CMD_NAV_TAKEOFF
MOCK_TELEMETRY_HZ = 10.0  # wanted position-report rate [Hz of flight time]
MAX_WALL_TELEMETRY_HZ = 40.0  # cap per vehicle [Hz of wall time] so the mock keeps up
KEEPER_PERIOD_S = 0.5  # schedule-keeping period [s of flight time]
CATCH_UP_FACTOR = 1.3  # mock top speed / planned speed (headroom for schedule keeping)
G_MPS2 = 9.80665
ROUTE_ACCEL_MPS2 = 2.5  # real vehicles' assumed acceleration from the hover (ArduCopter WPNAV_ACCEL)


@dataclass
class FlyOptions:
    out_dir: Path = Path("out")
    connect: list[str] = field(default_factory=list)  # empty: start mock vehicles
    speedup: float = 10.0
    autopilot: str = "ardupilot"
    workers: int = 8
    tlog: bool = False
    rrd: bool = True
    max_cross_track_m: float = 15.0
    drift_mps: dict[int, tuple[float, float]] = field(default_factory=dict)  # mock fault injection
    timeout_factor: float = 2.0
    keep_schedule: bool = True
    live: object | None = None  # a rerun.RecordingStream: the Rerun views streamed while flying


@dataclass
class FlyResult:
    reports: list[VehicleReport]
    uploads: dict[int, VehicleResult]
    mcap_path: Path
    rrd_path: Path | None
    tlog_path: Path | None
    wall_time_s: float
    end_states: dict[int, str] = field(default_factory=dict)  # safe end: sysid -> what was done
    report_path: Path | None = None  # the flight report PNG (flight_report.py)
    log_error: str | None = None  # the flight log could not be written (full disk); the report stands

    @property
    def passed(self) -> bool:
        return all(r.passed for r in self.reports) and all(u.ok for u in self.uploads.values())


class _TrackRecorder:
    """Collects each vehicle's positions from the link's frames (completion is VehicleStatus's)."""

    def __init__(self, origin: Origin, sim_clock: bool, sysids) -> None:
        self.origin = origin
        self.sim_clock = sim_clock
        self.samples: dict[int, list[tuple[float, float, float, float]]] = {s: [] for s in sysids}
        self.completed: dict[int, bool] = {}

    def on_frame(self, msg, raw: bytes, t_s: float) -> None:
        sysid = msg.get_srcSystem()
        if sysid not in self.samples or msg.get_type() != "GLOBAL_POSITION_INT":
            return
        t = msg.time_boot_ms / 1000.0 if self.sim_clock else t_s
        self.samples[sysid].append((t, msg.lat / 1e7, msg.lon / 1e7, msg.alt / 1000.0))

    def latest(self, sysid: int) -> tuple[float, np.ndarray] | None:
        """Time [s] and ENU position [m] of the vehicle's newest position report."""
        if not self.samples[sysid]:
            return None
        t, lat, lon, alt = self.samples[sysid][-1]
        return t, np.array(geodetic_to_enu(lat, lon, alt, self.origin))

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


def manned_traffic(scenario: Scenario, route_t0_s: float) -> list[MovingObstacle]:
    """The scenario's [[manned]] aircraft as constant-velocity traffic from the route start.

    Their bound is the planner's ``safety_m`` when given, else the largest vehicle separation.
    """
    bound = float(
        scenario.planner.get("safety_m", max((v.separation_m for v in scenario.vehicles), default=0))
    )
    return [
        MovingObstacle(
            str(m.get("id", f"manned{k}")),
            tuple(m["position_m"]),
            tuple(m["velocity_mps"]),
            route_t0_s,
            bound,
        )
        for k, m in enumerate(scenario.raw.get("manned", []))
        if "position_m" in m and "velocity_mps" in m
    ]


def _airframe_for(vp):
    """The mock airframe tuned to the planned vehicle, as one would set SITL parameters.

    The plan's speed and turn radius need a lateral acceleration of v^2 / R, and its steepest
    legs a climb and sink rate of v x slope. A multirotor gets at least that acceleration, a fixed
    wing at least that bank, both at least those vertical rates, all with headroom
    (CATCH_UP_FACTOR) to catch up with their schedule.
    """
    from sitl_mock import AIRFRAMES

    base = AIRFRAMES[vp.vehicle_type]
    speed = float(np.max(vp.speeds_mps))
    if speed <= 0:
        return base
    legs = np.diff(vp.path, axis=0)
    horizontal = np.hypot(legs[:, 0], legs[:, 1])
    slope = (legs[:, 2] / np.maximum(horizontal, 1e-9))[horizontal > 1.0]  # not take-off / landing
    frame = replace(
        base,
        cruise_speed_mps=speed,
        max_speed_mps=max(base.max_speed_mps, CATCH_UP_FACTOR * speed),
        climb_rate_mps=max(base.climb_rate_mps, CATCH_UP_FACTOR * speed * float(np.max(slope, initial=0.0))),
        sink_rate_mps=max(base.sink_rate_mps, -CATCH_UP_FACTOR * speed * float(np.min(slope, initial=0.0))),
    )
    if vp.turn_radius_m <= 0:
        return frame
    lateral_mps2 = speed**2 / vp.turn_radius_m
    if vp.vehicle_type == "fixed_wing":
        return replace(frame, max_bank_rad=max(base.max_bank_rad, float(np.arctan(lateral_mps2 / G_MPS2))))
    return replace(frame, accel_mps2=max(base.accel_mps2, lateral_mps2))


def _mock_fleet(plan: Plan, options: FlyOptions):
    """One mock per vehicle, home under its first waypoint; a fixed wing's home is its take-off
    climb run south of it (the mock climbs north), so that it reaches the first waypoint at its
    altitude and flies on into the route."""
    from sitl_mock import MockFleet
    from sitl_mock.flight import climb_run_m

    specs = []
    for vp in plan.vehicles:
        x, y = vp.waypoints[0, :2]
        frame = _airframe_for(vp)
        if vp.vehicle_type == "fixed_wing":
            frame = replace(frame, climb_rate_mps=TAKEOFF_CLIMB_MPS)
            y -= climb_run_m(frame.cruise_speed_mps, TAKEOFF_CLIMB_MPS, float(vp.waypoints[0, 2]))
        lat, lon, alt = enu_to_geodetic(x, y, 0.0, plan.origin)
        specs.append(
            dict(
                sysid=vp.sysid,
                home=Origin(lat, lon, alt),
                vehicle_type=vp.vehicle_type,
                profile=options.autopilot,
                airframe=frame,
            )
        )
    # position reports at MOCK_TELEMETRY_HZ of flight time, within what one Python process streams
    rate_hz = min(MOCK_TELEMETRY_HZ * options.speedup, MAX_WALL_TELEMETRY_HZ)
    return MockFleet(vehicles=specs, speedup=options.speedup, home=plan.origin, rate_hz=rate_hz)


async def _wait_for_vehicles(link: MavlinkLink, sysids: list[int], timeout_s: float) -> None:
    """Until every vehicle's autopilot sent a HEARTBEAT (any other frame, or a camera's HEARTBEAT,
    says nothing of what the vehicle is); duplicate system ids are refused."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if all(_heard(link, s) for s in sysids):
            break
        await asyncio.sleep(0.05)
    missing = [s for s in sysids if not _heard(link, s)]
    if missing:
        raise UserError(f"no autopilot HEARTBEAT from sysid {missing} within {timeout_s:.0f} s")
    duplicates = link.duplicates()
    if duplicates:
        raise UserError(f"system ids answer from several addresses (refusing to merge): {duplicates}")


def _heard(link: MavlinkLink, sysid: int) -> bool:
    return getattr(link.vehicles.get(sysid), "autopilot", None) is not None


def vehicle_quirks(link: MavlinkLink, sysids: list[int]) -> dict[int, AutopilotQuirks]:
    """Each vehicle's autopilot entry, from the HEARTBEAT it sent."""
    return {s: quirks_for(link.vehicles[s].autopilot, link.vehicles[s].mav_type) for s in sysids}


def build_missions(plan: Plan, quirks: dict[int, AutopilotQuirks]) -> dict[int, list]:
    """Each vehicle's mission items in its autopilot's conventions (validated)."""
    return {vp.sysid: plan_to_items(vp, plan.origin, quirks[vp.sysid].conventions) for vp in plan.vehicles}


def check_flight(plan: Plan) -> None:
    """What must hold before anything is sent: one sysid in 1..255 per vehicle, and every
    vehicle's mission valid in both autopilots' conventions."""
    sysids = [vp.sysid for vp in plan.vehicles]
    if 0 in sysids or len(set(sysids)) != len(sysids):
        raise UserError(f"every vehicle needs its own MAVLink sysid in 1..255 to fly, got {sysids}")
    for conventions in AUTOPILOTS:
        build_missions(plan, {s: quirks_named(conventions) for s in sysids})


class _KeptLog:
    """Closes a FlightLogger on exit; an OSError (full disk) is kept in ``errors``, not raised,
    so the flight still ends safely and gets its report."""

    def __init__(self, logger: FlightLogger, errors: list[str]) -> None:
        self.logger, self.errors = logger, errors

    def __enter__(self) -> FlightLogger:
        return self.logger

    def __exit__(self, *exc) -> None:
        try:
            self.logger.close()
        except OSError as err:
            self.errors.append(f"could not be written completely: {err.strerror or err}")


async def fly(
    scenario: Scenario,
    plan: Plan,
    options: FlyOptions,
    progress: Callable[[str, float, float], None] | None = None,
) -> FlyResult:
    """Upload, start and record the whole fleet; return the per-vehicle conformance report.

    ``progress(stage, done, total)`` reports "upload" (vehicles) and "fly" (completed vehicles);
    ``progress("wait", sysid, 0)`` with a reason while a vehicle is not ready to arm.
    """
    t_wall = time.monotonic()
    sysids = [vp.sysid for vp in plan.vehicles]
    check_flight(plan)  # before anything is sent
    unknown = sorted(set(options.drift_mps) - set(sysids))
    if unknown:
        raise UserError(f"drift for sysid {unknown[0]}, which is not in the plan {sorted(sysids)}")
    log_errors: list[str] = []
    options.out_dir.mkdir(parents=True, exist_ok=True)
    mcap_path = options.out_dir / "flight.mcap"
    tlog_path = options.out_dir / "flight.tlog" if options.tlog else None
    route_t0_s = 0.0
    fleet = None if options.connect else _mock_fleet(plan, options)
    speedup = 1.0 if fleet is None else options.speedup
    scenario_text = scenario.path.read_text() if scenario.path else None
    uploads: dict[int, VehicleResult] = {}
    end_states: dict[int, str] = {}
    aborted: BaseException | None = None
    if fleet is not None:
        fleet.__enter__()
    try:
        urls = options.connect or [f"udpout:{h}:{p}" for h, p in fleet.addresses]
        link = await MavlinkLink.open(*urls)
        recorder = _TrackRecorder(plan.origin, fleet is not None, sysids)
        status = VehicleStatus(link, sysids)
        quirks: dict[int, AutopilotQuirks] = {}
        try:
            flight_log = FlightLogger(mcap_path, plan.origin, plan, scenario_text, tlog_path)
        except OSError as exc:
            raise UserError(f"cannot write the flight log {mcap_path}: {exc.strerror or exc}") from None
        with _KeptLog(flight_log, log_errors) as logger:
            link.subscribe(logger.on_frame)
            link.subscribe(recorder.on_frame)
            if options.live is not None:
                link.subscribe(_live_views(options.live, plan, scenario).on_frame)
            try:
                await _wait_for_vehicles(link, sysids, HEARTBEAT_WAIT_S if fleet else REAL_HEARTBEAT_WAIT_S)
                quirks = vehicle_quirks(link, sysids)
                missions = build_missions(plan, quirks)
                status.last_seq = {s: len(m) - 1 for s, m in missions.items()}
                await request_streams(link, sysids)
                uploads = await upload_fleet(
                    link,
                    missions,
                    workers=options.workers,
                    progress=lambda done, total, r: progress and progress("upload", done, total),
                )
                for sysid, r in uploads.items():
                    logger.log_event(
                        {"event": "upload", "sysid": sysid, "ok": r.ok, "error": str(r.error or "")}
                    )
                failed = [s for s, r in uploads.items() if not r.ok]
                if failed:
                    log.error("upload failed for sysid %s; not starting the fleet", failed)
                else:
                    for sysid, drift in options.drift_mps.items():
                        if fleet is not None:
                            fleet.set_drift(sysid, *drift)
                    await _take_off_all(link, plan, status, speedup, options, quirks, progress, missions)
                    climbed = frozenset(v.sysid for v in plan.vehicles if v.vehicle_type == "fixed_wing")
                    logger.log_event({"event": "airborne", "sysids": sysids})
                    leads = {
                        vp.sysid: _accel_lead_s(
                            vp, ROUTE_ACCEL_MPS2 if fleet is None else _airframe_for(vp).accel_mps2
                        )
                        for vp in plan.vehicles
                    }
                    lead_s = max(leads.values())
                    route_t0_s = (recorder.now_s() if fleet is not None else time.time()) + lead_s
                    routes = asyncio.create_task(
                        _start_routes(link, plan, missions, speedup, logger, lead_s, leads, quirks, climbed)
                    )
                    keeper = None
                    if options.keep_schedule:
                        keeper = ScheduleKeeper()
                        for vp in plan.vehicles:
                            keeper.add(vp)
                    await _wait_until_done(
                        link, recorder, status, plan, speedup, options, progress, keeper, route_t0_s, quirks
                    )
                    await routes
            except BaseException as exc:  # noqa: BLE001 - any failure or Ctrl-C ends safely, then re-raises
                aborted = exc
            finally:
                if quirks and (aborted is not None or not all(t.done for t in status.tracks.values())):
                    end_states = await asyncio.shield(safe_end(link, status, quirks))
                elif quirks:  # every mission done: say where each vehicle ended, command nothing
                    end_states = {s: _end_state(link, s) for s in sysids}
                if end_states:
                    states = {str(k): v for k, v in end_states.items()}
                    logger.log_event({"event": "safe_end" if aborted else "end", "states": states})
                status.close()
                await link.close()
    finally:
        if fleet is not None:
            fleet.__exit__(None, None, None)
    if aborted is not None:
        if end_states:
            log.error("safe end: %s", _said(end_states))
        if isinstance(aborted, UserError) and end_states:
            raise UserError(f"{aborted}; safe end: {_said(end_states)}") from aborted
        raise aborted
    for sysid, track in status.tracks.items():
        recorder.completed[sysid] = track.done
    reports = conformance_report(
        plan,
        recorder.tracks(),
        {v.sysid: v.separation_m for v in scenario.vehicles},
        scenario.cylinders,
        scenario.hemispheres,
        manned_traffic(scenario, route_t0_s),
        max_cross_track_m=options.max_cross_track_m,
    )
    for r in reports:
        if not uploads[r.sysid].ok:
            r.failures.insert(0, f"upload failed: {uploads[r.sysid].error}")
    report_path = write_flight_report(
        options.out_dir / "report.png", plan, recorder.tracks(), reports, scenario, options.max_cross_track_m
    )
    rrd_path = None
    if options.rrd and not log_errors:
        from gcs_planner.telemetry import log_flight_to_rerun, read_flight

        rrd_path = options.out_dir / "flight.rrd"
        log_flight_to_rerun(read_flight(mcap_path), rrd_path)
    wall_s = time.monotonic() - t_wall
    log_error = log_errors[0] if log_errors else None
    return FlyResult(
        reports, uploads, mcap_path, rrd_path, tlog_path, wall_s, end_states, report_path, log_error
    )


def _live_views(rec, plan: Plan, scenario: Scenario):
    """The views of a log (telemetry.rerun_views), fed frame by frame while flying."""
    from gcs_planner.telemetry.rerun_views import LiveRerunLogger

    live = LiveRerunLogger(rec, plan.origin, time.time())
    live.start(plan, scenario)
    return live


def _end_state(link: MavlinkLink, sysid: int) -> str:
    info = link.vehicles.get(sysid)
    return "holding (mission complete)" if info is not None and info.armed else "landed (disarmed)"


def _said(end_states: dict[int, str]) -> str:
    return ", ".join(f"sysid {s} {what}" for s, what in sorted(end_states.items()))


async def _take_off_all(
    link: MavlinkLink,
    plan: Plan,
    status: VehicleStatus,
    speedup: float,
    options: FlyOptions,
    quirks: dict[int, AutopilotQuirks],
    progress=None,
    missions: dict | None = None,
) -> None:
    """Arm every vehicle once it is ready and climb it to its first waypoint's altitude; return
    when all are there. With ``missions``, a fixed wing (which cannot wait in place) starts its
    route as soon as it is up (``_start_routes`` leaves it out)."""
    gate = asyncio.Semaphore(options.workers)
    targets = {vp.sysid: float(vp.waypoints[0, 2]) for vp in plan.vehicles}

    def late() -> list[int]:
        return [s for s, z in targets.items() if (status.tracks[s].rel_alt_m or -1e9) < z - TAKEOFF_ALT_TOL_M]

    async def climb_into_route(vp) -> None:
        while vp.sysid in late():
            await asyncio.sleep(0.02)
        items = missions[vp.sysid]
        await start_mission_at(link, vp.sysid, quirks[vp.sysid], _route_seq(items), len(items) - 1)

    def waiting(sysid: int, reason: str) -> None:
        log.info("sysid %d not ready to arm: %s", sysid, reason)
        if progress:
            progress("wait", sysid, reason)

    async def one(vp) -> None:
        async with gate:
            q = quirks[vp.sysid]
            for attempt in range(1, TAKEOFF_ATTEMPTS + 1):
                try:
                    await take_off(
                        link, status, vp.sysid, q, float(vp.waypoints[0, 2]), ARM_TIMEOUT_S, speedup, waiting
                    )
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
    deadline = time.monotonic() + climb_s * options.timeout_factor / speedup + 10.0
    while time.monotonic() < deadline and late():
        await asyncio.sleep(0.05)
    if late():
        for task in climbs:
            task.cancel()
        seen = {s: status.tracks[s].rel_alt_m for s in late()}
        raise UserError(f"sysid {late()} did not reach take-off altitude in time (relative altitude {seen})")
    await asyncio.gather(*climbs)


def _accel_lead_s(vp, accel_mps2: float) -> float:
    """How much earlier than planned a route starts, so that accelerating from the hover at
    ``accel_mps2`` puts the vehicle where a plan assuming instant cruise speed has it."""
    return float(vp.speeds_mps[1] if len(vp.speeds_mps) > 1 else vp.speeds_mps[0]) / (2.0 * accel_mps2)


async def _start_routes(
    link: MavlinkLink,
    plan: Plan,
    missions: dict,
    speedup: float,
    logger,
    lead_s: float,
    leads: dict[int, float],
    quirks: dict[int, AutopilotQuirks],
    started: frozenset[int] = frozenset(),
) -> None:
    """Start each route (the item after NAV_TAKEOFF) at its planned start time, but those in
    ``started`` (fixed wings that climbed into theirs).

    Route time 0 is ``lead_s`` after now; each route starts its own acceleration lead earlier.
    """
    t0 = time.monotonic()

    async def one(vp) -> None:
        items = missions[vp.sysid]
        if vp.sysid in started:
            return
        first = _route_seq(items)
        offset_s = max(vp.takeoff_delay_s, float(vp.times_s[0]))  # planned time at the first waypoint
        start_s = lead_s + offset_s - leads[vp.sysid]
        await asyncio.sleep(max(0.0, t0 + start_s / speedup - time.monotonic()))
        try:
            await start_mission_at(link, vp.sysid, quirks[vp.sysid], first, len(items) - 1)
        except MavlinkError as exc:
            raise UserError(
                f"vehicle {vp.vehicle_id} (sysid {vp.sysid}) refused the mission start: {exc}"
            ) from exc
        logger.log_event({"event": "route_start", "sysid": vp.sysid, "planned_offset_s": offset_s})

    await asyncio.gather(*(one(vp) for vp in plan.vehicles))


def _route_seq(items) -> int:
    """The route's first item: the one after NAV_TAKEOFF."""
    return next(i for i, it in enumerate(items) if it.command == NAV_TAKEOFF) + 1


async def _wait_until_done(
    link: MavlinkLink,
    recorder: _TrackRecorder,
    status: VehicleStatus,
    plan: Plan,
    speedup: float,
    options: FlyOptions,
    progress,
    keeper: ScheduleKeeper | None,
    route_t0_s: float,
    quirks: dict[int, AutopilotQuirks],
) -> None:
    descent_s = max(float(v.waypoints[-1, 2]) for v in plan.vehicles) / LAND_SPEED_MPS
    planned_s = max(float(v.path_times_s[-1]) + v.takeoff_delay_s for v in plan.vehicles) + descent_s
    budget_s = planned_s * options.timeout_factor / speedup + 10.0
    deadline = time.monotonic() + budget_s
    total = len(plan.vehicles)

    def done() -> set[int]:
        return {s for s, t in status.tracks.items() if t.done}

    while time.monotonic() < deadline and len(done()) < total:
        if progress:
            progress("fly", len(done()), total)
        if keeper is not None:
            _keep_schedule(link, recorder, status, keeper, route_t0_s, quirks)
        await asyncio.sleep(KEEPER_PERIOD_S / speedup)
    if progress:
        progress("fly", len(done()), total)
    # a little more telemetry after the last item (landing) for the log
    await asyncio.sleep(min(1.0, 5.0 / speedup))


def _keep_schedule(
    link: MavlinkLink,
    recorder: _TrackRecorder,
    status: VehicleStatus,
    keeper: ScheduleKeeper,
    route_t0_s: float,
    quirks: dict[int, AutopilotQuirks],
) -> None:
    for sysid, track in status.tracks.items():
        if not track.started or track.done:
            continue
        latest = recorder.latest(sysid)
        if latest is None:
            continue
        t_s, position = latest
        speed = keeper.speed_command(sysid, t_s - route_t0_s, position)
        if speed is not None:
            change_speed(link, sysid, quirks[sysid], speed)
