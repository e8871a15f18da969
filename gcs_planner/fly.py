"""The hardware-in-the-loop run: plan -> missions -> vehicles -> telemetry log -> conformance.

Mirrors the seed papers' HIL setup (planner -> datalink -> flight controller -> telemetry ->
display): the plan's missions are uploaded to every vehicle concurrently over MAVLink, the fleet
is armed and started, every received frame is logged to MCAP (and .tlog on request), and the
flown tracks are checked against the plan (gcs_planner.conformance). The vehicles come from a
VehicleSource (gcs_planner.vehicles): the mock fleet the CLI hands in, or real ones / SITL.

Choices:
- Each mock vehicle's home is the plan's first waypoint projected to the ground, so mission
  altitudes (relative to home) equal plan ``z`` on the flat mock world, and its airframe is
  tuned to the planned speed and turn radius (sitl_mock.plan_fleet).
- Track time is the vehicle's ``time_boot_ms`` for mocks (one simulated clock for the whole fleet,
  so separations are compared at the same instant whatever the speed-up) and the receive time
  for real vehicles, whose boot clocks differ.
- Two-phase start (gcs_planner.flight_ops), so that the plan's timing (and with it the planned
  separation) holds in the air: take off, then start each route at the common start plus its
  planned delay (delayed take-off as a timed start; the mission's NAV_DELAY is then skipped).
  Climb rates differ between vehicles and altitudes, so a one-shot start would shift every route
  by its own climb time.
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
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gcs_planner.clock_check import MIN_SPAN_S, ClockRate
from gcs_planner.conformance import MAX_SCHEDULE_ERROR_S, MovingObstacle, VehicleReport, conformance_report
from gcs_planner.errors import UserError
from gcs_planner.fleet_ids import id_runs, network_of, wire_sysid
from gcs_planner.flight_limits import check_limits, read_limits, read_ramps
from gcs_planner.flight_ops import (
    TrackRecorder,
    accel_lead_s,
    boot_clock,
    build_missions,
    receive_clock,
    start_routes,
    take_off_all,
    vehicle_quirks,
    wait_for_vehicles,
    wait_until_done,
)
from gcs_planner.flight_report import write_flight_report
from gcs_planner.lockstep import check_loop, now_s, unix_s
from gcs_planner.mavlink.actions import safe_end
from gcs_planner.mavlink.autopilots import AutopilotQuirks, quirks_named
from gcs_planner.mavlink.fleet import VehicleResult, upload_fleet
from gcs_planner.mavlink.items import AUTOPILOTS
from gcs_planner.mavlink.link import FLEET_RCVBUF_BYTES, MavlinkLink
from gcs_planner.mavlink.networks import open_networks
from gcs_planner.mavlink.preflight import request_streams
from gcs_planner.mavlink.vehicle_status import VehicleStatus
from gcs_planner.plan import Plan
from gcs_planner.safe_signals import SafeEndSignals
from gcs_planner.scenario import Scenario
from gcs_planner.starts import START_FIX_WAIT_S, check_starts, starts
from gcs_planner.telemetry import FlightLogger
from gcs_planner.telemetry.mcap_log import tlog_network_path
from gcs_planner.timekeeping import ScheduleKeeper
from gcs_planner.vehicles import VehicleSource

__all__ = ["FlyOptions", "FlyResult", "check_flight", "check_networks", "end_summary", "fly", "networks"]

log = logging.getLogger(__name__)

HEARTBEAT_WAIT_S = 10.0  # simulated vehicles answer at once
REAL_HEARTBEAT_WAIT_S = 30.0  # real vehicles / SITL started by hand
END_WAIT_S = 300.0  # after a signal, how long the log waits for the vehicles to land [s flight time]


@dataclass
class FlyOptions:
    out_dir: Path = Path("out")
    workers: int = 8
    tlog: bool = False
    rrd: bool = True
    max_cross_track_m: float = 15.0
    max_schedule_error_s: float = MAX_SCHEDULE_ERROR_S
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
    tlog_paths: list[Path]  # one .tlog per MAVLink network (FlightLogger), empty without --tlog
    wall_time_s: float
    end_states: dict[int, str] = field(default_factory=dict)  # safe end: sysid -> what was done
    report_path: Path | None = None  # the flight report PNG (flight_report.py)
    log_error: str | None = None  # the flight log could not be written (full disk); the report stands
    frames_received: int = 0  # MAVLink frames the link delivered (every one is handed to the log)
    interrupted: str | None = None  # the signal that ended the flight early (SIGINT, SIGTERM, SIGHUP)

    @property
    def passed(self) -> bool:
        uploaded = all(u.ok for u in self.uploads.values())
        return all(r.passed for r in self.reports) and uploaded and self.interrupted is None


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


def check_flight(plan: Plan) -> None:
    """What must hold before anything is sent: one sysid in 1..255 per vehicle (per network: fleet
    ids, mavlink/networks.py), and every vehicle's mission valid in both autopilots' conventions."""
    sysids = [vp.sysid for vp in plan.vehicles]
    if any(wire_sysid(s) == 0 for s in sysids) or len(set(sysids)) != len(sysids):
        raise UserError(f"every vehicle needs its own MAVLink sysid in 1..255 to fly, got {sysids}")
    empty = sorted(set(range(networks(plan))) - {network_of(s) for s in sysids})
    if empty:
        raise UserError(f"network {empty[0]} has no vehicle; number the networks 0, 1, ... without gaps")
    for conventions in AUTOPILOTS:
        build_missions(plan, {s: quirks_named(conventions) for s in sysids})


def networks(plan: Plan) -> int:
    """How many MAVLink networks the plan's vehicles are on (fleet ids, mavlink/networks.py)."""
    return 1 + max((network_of(vp.sysid) for vp in plan.vehicles), default=0)


def check_networks(plan: Plan, given: int) -> None:
    """A link (a --connect) per network the plan's vehicles are on."""
    if given != networks(plan):
        raise UserError(f"the plan's vehicles are on {networks(plan)} MAVLink network(s), but {given}"
                        " were given: one --connect per network")  # fmt: skip


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
    vehicles: VehicleSource,
    progress: Callable[[str, float, float], None] | None = None,
) -> FlyResult:
    """Upload, start and record the whole fleet; return the per-vehicle conformance report.

    ``progress(stage, done, total)`` reports "upload" (vehicles) and "fly" (completed vehicles);
    ``progress("wait", sysid, 0)`` with a reason while a vehicle is not ready to arm.
    """
    t_wall = time.monotonic()
    check_loop(vehicles.lockstep)
    check_flight(plan)  # before anything is sent
    sysids = [vp.sysid for vp in plan.vehicles]
    unknown = sorted(set(options.drift_mps) - set(sysids))
    if unknown:
        raise UserError(f"drift for sysid {unknown[0]}, which is not in the plan {sorted(sysids)}")
    if options.drift_mps and not vehicles.simulated:
        raise UserError("--drift injects a fault into mock vehicles; it cannot act on connected vehicles")
    options.out_dir.mkdir(parents=True, exist_ok=True)
    with SafeEndSignals() as signals:
        flight = _Flight(scenario, plan, options, vehicles, progress, signals)
        async with vehicles as urls:
            check_networks(plan, len(urls))
            await flight.run(urls)
    if signals.received is not None and isinstance(flight.aborted, asyncio.CancelledError):
        result = flight.result(time.monotonic() - t_wall)  # the vehicles were brought home: report it
        result.interrupted = signals.received.name
        return result
    if flight.aborted is not None:
        ended = end_summary(flight.end_states)
        if flight.end_states:
            log.error("safe end: %s", ended)
        if isinstance(flight.aborted, UserError) and flight.end_states:
            raise UserError(f"{flight.aborted}; safe end: {ended}") from flight.aborted
        raise flight.aborted
    return flight.result(time.monotonic() - t_wall)


class _Flight:
    """One flight's state, from the link's opening to the report (fly's steps as methods)."""

    def __init__(
        self, scenario, plan, options: FlyOptions, vehicles: VehicleSource, progress, signals: SafeEndSignals
    ) -> None:
        self.scenario, self.plan, self.options, self.vehicles, self.progress = (
            scenario, plan, options, vehicles, progress
        )  # fmt: skip
        self.signals = signals
        self.sysids = [vp.sysid for vp in plan.vehicles]
        self.mcap_path = options.out_dir / "flight.mcap"
        tlog = options.out_dir / "flight.tlog"
        self.tlog_path = tlog if options.tlog else None
        self.tlog_paths = [tlog_network_path(tlog, n) for n in range(networks(plan))] if options.tlog else []
        clock = boot_clock if vehicles.simulated else receive_clock(vehicles.speedup)
        self.recorder = TrackRecorder(plan.origin, clock, self.sysids)
        self.quirks: dict[int, AutopilotQuirks] = {}
        self.limits: dict = {}  # sysid: flight_limits.FlightLimits
        self.ramps: dict[int, tuple[float, float]] = {}  # sysid: waypoint acceleration, jerk
        self.uploads: dict[int, VehicleResult] = {}
        self.end_states: dict[int, str] = {}
        self.log_errors: list[str] = []
        self.aborted: BaseException | None = None
        self.route_t0_s = 0.0  # the fleet's route time 0 (track clock)
        self.route_t0: dict[int, float] = {}  # sysid -> its route time 0: the fleet's, a plane's own
        self.status: VehicleStatus | None = None
        self.frames_received = 0
        self.clocks = ClockRate(self.sysids)

    async def run(self, urls: list[list[str]]) -> None:
        """Fly on the link to each network's ``urls``; any failure or Ctrl-C ends safely, kept in
        ``aborted``."""
        plan = self.plan
        # a fleet's telemetry arrives in bursts while the log's encoder holds the GIL: at 500
        # vehicles the default 208 kB buffer (~0.1 s of frames) overflowed, 5-10 % lost
        link = await open_networks(urls, receive_buffer_bytes=FLEET_RCVBUF_BYTES)
        self.status = VehicleStatus(link, self.sysids)
        scenario_text = self.scenario.path.read_text() if self.scenario.path else None
        try:
            # clock_rate: the log's receive times run at 1/speedup of flight time where they are
            # wall time (a paced mock, SITL); in lockstep speedup is 1 (telemetry.mcap_log)
            rate = self.vehicles.speedup
            flight_log = FlightLogger(
                self.mcap_path, plan.origin, plan, scenario_text, self.tlog_path, clock_rate=rate
            )
        except OSError as exc:
            self.status.close()
            await link.close()
            raise UserError(f"cannot write the flight log {self.mcap_path}: {exc.strerror or exc}") from None
        with _KeptLog(flight_log, self.log_errors) as logger:
            link.subscribe(logger.on_frame)
            link.subscribe(self.recorder.on_frame)
            link.subscribe(self.clocks.on_frame)
            if self.options.live is not None:
                live = _live_views(self.options.live, plan, self.scenario, self.vehicles.speedup)
                link.subscribe(live.on_frame)
            try:
                await self._missions(link, logger)
            except BaseException as exc:  # noqa: BLE001 - any failure or Ctrl-C ends safely, then re-raises
                self.aborted = exc
            finally:
                await self._end(link, logger)

    async def _missions(self, link: MavlinkLink, logger: FlightLogger) -> None:
        wait_s = HEARTBEAT_WAIT_S if self.vehicles.simulated else REAL_HEARTBEAT_WAIT_S
        await wait_for_vehicles(link, self.sysids, wait_s)
        self.quirks = vehicle_quirks(link, self.sysids)
        await request_streams(link, self.sysids)
        await self._check_starts()
        self.limits = await read_limits(link, self.sysids, self.quirks)
        self.ramps = {} if self.vehicles.simulated else await read_ramps(link, self.sysids, self.quirks)
        check_limits(self.plan.vehicles, self.limits, 1.0)
        missions = build_missions(self.plan, self.quirks)
        self.status.last_seq = {s: len(m) - 1 for s, m in missions.items()}
        progress = self.progress
        self.uploads = await upload_fleet(
            link,
            missions,
            workers=self.options.workers,
            progress=lambda done, total, r: progress and progress("upload", done, total),
        )
        for sysid, r in self.uploads.items():
            logger.log_event({"event": "upload", "sysid": sysid, "ok": r.ok, "error": str(r.error or "")})
        failed = [s for s, r in self.uploads.items() if not r.ok]
        if failed:
            log.error("upload failed for sysid %s; not starting the fleet", failed)
            return
        if not self.vehicles.simulated:
            await self._check_clocks()
        for sysid, drift in self.options.drift_mps.items():
            self.vehicles.set_drift(sysid, *drift)
        await self._routes(link, logger, missions)

    async def _check_starts(self) -> None:
        """The pre-flight gate: every vehicle reports a position within its bound of its planned
        start (starts.py), or nothing is armed; one line per vehicle that fails."""
        samples = self.recorder.samples
        deadline = now_s() + START_FIX_WAIT_S
        while not all(samples[s] for s in self.sysids) and now_s() < deadline:
            await asyncio.sleep(0.05)
        where = {s: rows[-1][1:3] for s, rows in samples.items() if rows}
        name = self.scenario.path.name if self.scenario.path else "SCENARIO"
        check_starts(starts(self.plan.vehicles, self.plan.origin), where,
                     f"start each vehicle there: fly {name} --homes prints where")  # fmt: skip

    def _run_to_start_s(self, vp) -> float:
        """How long a plane that starts its route now takes to reach its first waypoint, flying
        along its first leg at the leg's speed (it climbs out faster than its climb run assumes:
        a SITL plane was up 80 m before it, 4.4 s early)."""
        latest = self.recorder.latest(vp.sysid)
        if latest is None or len(vp.waypoints) < 2:
            return 0.0
        leg = vp.waypoints[1, :2] - vp.waypoints[0, :2]
        ahead_m = float(np.dot(vp.waypoints[0, :2] - latest[1][:2], leg / max(float(np.hypot(*leg)), 1e-9)))
        return max(ahead_m, 0.0) / max(float(vp.speeds_mps[1]), 1e-3)

    def _started(self, sysid: int, route_s: float) -> None:
        """A route's start is being sent, due at route time ``route_s``: its route time 0 is taken
        from now, so a start this process sent late (a busy machine; a mock does not wait for it)
        is not charged to the vehicle's schedule, while everything the vehicle does after is."""
        self.route_t0[sysid] = self._now() - route_s

    def _lead_s(self, vp) -> float:
        """How early a route starts (flight_ops.accel_lead_s): a mock at its airframe's
        acceleration; a connected vehicle on the S-curve its own parameters give, after its
        autopilot's start latency (docs/real-autopilots.md)."""
        if self.vehicles.simulated or vp.sysid not in self.ramps:
            return accel_lead_s(vp, self.vehicles.accel_mps2(vp.sysid))
        return accel_lead_s(vp, *self.ramps[vp.sysid], self.quirks[vp.sysid].start_latency_s)

    def _now(self) -> float:
        """Now on the tracks' clock: the fleet's simulated time for mocks, else the receive time
        scaled to the vehicles' rate."""
        if not self.vehicles.simulated:
            return self.recorder.clock(None, unix_s())
        now = self.vehicles.sim_time_s()  # read directly: reports lag on a busy machine
        return self.recorder.now_s() if now is None else now

    async def _check_clocks(self) -> None:
        """Refuse connected vehicles whose clocks run at another rate than this flight's."""
        deadline = now_s() + 3 * MIN_SPAN_S
        while now_s() < deadline and min(map(self.clocks.span_s, self.sysids)) < MIN_SPAN_S:
            await asyncio.sleep(0.05)
        self.clocks.check(self.vehicles.speedup)

    async def _routes(self, link: MavlinkLink, logger: FlightLogger, missions: dict) -> None:
        """Take off, start every route on time, keep the schedule until all are done."""
        plan, options, speedup = self.plan, self.options, self.vehicles.speedup
        plane_t0: dict[int, float] = {}  # fixed wings start their routes once up: their own time 0

        def plane_started(sysid: int) -> None:
            vp = next(v for v in plan.vehicles if v.sysid == sysid)
            due_s = max(vp.takeoff_delay_s, float(vp.times_s[0]))  # planned time at its first waypoint
            plane_t0[sysid] = self._now() + self._run_to_start_s(vp) - due_s

        await take_off_all(
            link, plan, self.status, speedup, self.quirks, options.workers, options.timeout_factor,
            self.progress, missions, plane_started,
        )  # fmt: skip
        climbed = frozenset(v.sysid for v in plan.vehicles if v.vehicle_type == "fixed_wing")
        logger.log_event({"event": "airborne", "sysids": self.sysids})
        leads = {vp.sysid: self._lead_s(vp) for vp in plan.vehicles}
        lead_s = max(leads.values())
        self.route_t0_s = self._now() + lead_s
        self.route_t0 = {s: plane_t0.get(s, self.route_t0_s) for s in self.sysids}
        routes = asyncio.create_task(start_routes(
            link, plan, missions, speedup, logger, lead_s, leads, self.quirks, climbed, self._started
        ))  # fmt: skip
        keeper = None
        if options.keep_schedule:
            keeper = ScheduleKeeper()
            for vp in plan.vehicles:
                keeper.add(vp)
            for sysid, lim in self.limits.items():
                keeper.limit(sysid, lim.min_mps, lim.max_mps)
        try:
            await wait_until_done(
                link, self.recorder, self.status, plan, speedup, options.timeout_factor, self.progress,
                keeper, self.route_t0, self.quirks,
            )  # fmt: skip
            await routes
        finally:  # a failure or a signal: no route may start after the safe end sent the vehicles home
            routes.cancel()
            await asyncio.gather(routes, return_exceptions=True)

    async def _end(self, link: MavlinkLink, logger: FlightLogger) -> None:
        """Send airborne vehicles home after a failure (nothing after a clean end), log it, close."""
        finished = all(self.recorder.completed.get(s, False) for s in self.sysids)
        if self.quirks and (self.aborted is not None or not finished):
            self.end_states = await asyncio.shield(safe_end(link, self.status, self.quirks))
            if self.signals.received is not None:
                await self._until_landed(link, logger)
        elif self.quirks:  # every mission done: say where each vehicle ended, command nothing
            self.end_states = {s: _end_state(link, s) for s in self.sysids}
        if self.end_states:
            states = {str(k): v for k, v in self.end_states.items()}
            logger.log_event({"event": "safe_end" if self.aborted else "end", "states": states})
        self.status.close()
        await link.close()
        self.frames_received = link.frames_received

    async def _until_landed(self, link: MavlinkLink, logger: FlightLogger) -> None:
        """After a signal's safe end: keep logging until every vehicle has landed (disarmed), for at
        most END_WAIT_S of flight time or until a second signal; then say where each one is."""
        task = asyncio.current_task()
        if task is not None:
            task.uncancel()  # the signal's cancel is handled: this wait may await again
        log.warning("%s: vehicles sent home; logging until they land (send it again to stop waiting)",
                    self.signals.received.name)  # fmt: skip
        deadline = now_s() + END_WAIT_S / self.vehicles.speedup
        armed = [s for s in self.sysids if _armed(link, s)]
        while armed and now_s() < deadline and not self.signals.hurry.is_set():
            await asyncio.sleep(0.1)
            armed = [s for s in armed if _armed(link, s)]
        ended = self.end_states
        self.end_states = {s: what if s in armed else "landed (disarmed)" for s, what in ended.items()}
        logger.log_event({"event": "end_wait", "still_armed": armed})

    def result(self, wall_s: float) -> FlyResult:
        """The conformance report, the flight report PNG and the .rrd of the flown log."""
        plan, scenario, options = self.plan, self.scenario, self.options
        reports = conformance_report(
            plan,
            self.recorder.tracks(),
            {v.sysid: v.separation_m for v in scenario.vehicles},
            scenario.cylinders,
            scenario.hemispheres,
            manned_traffic(scenario, self.route_t0_s),
            max_cross_track_m=options.max_cross_track_m,
            route_t0_s=self.route_t0 or None,
            max_schedule_error_s=options.max_schedule_error_s,
        )
        for r in reports:
            upload = self.uploads.get(r.sysid)
            if upload is not None and not upload.ok:
                r.failures.insert(0, f"upload failed: {upload.error}")
            impossible = self.recorder.impossible.get(r.sysid, 0)
            if impossible:
                r.failures.append(f"{impossible} impossible positions reported (ignored)")
        report_path = write_flight_report(
            options.out_dir / "report.png", plan, self.recorder.tracks(), reports, scenario,
            options.max_cross_track_m,
        )  # fmt: skip
        rrd_path = None
        if options.rrd and not self.log_errors:
            from gcs_planner.telemetry import log_flight_to_rerun, read_flight

            rrd_path = options.out_dir / "flight.rrd"
            log_flight_to_rerun(read_flight(self.mcap_path), rrd_path)
        log_error = self.log_errors[0] if self.log_errors else None
        return FlyResult(
            reports, self.uploads, self.mcap_path, rrd_path, self.tlog_paths, wall_s, self.end_states,
            report_path, log_error, self.frames_received,
        )  # fmt: skip


def _live_views(rec, plan: Plan, scenario: Scenario, rate: float):
    """The views of a log (telemetry.rerun_views), fed frame by frame while flying; ``rate``: the
    vehicles' speed-up, so that the timeline counts seconds of flight as the log's .rrd does."""
    from gcs_planner.telemetry.rerun_views import LiveRerunLogger

    live = LiveRerunLogger(rec, plan.origin, unix_s(), rate)
    live.start(plan, scenario)
    return live


def _armed(link: MavlinkLink, sysid: int) -> bool:
    info = link.vehicles.get(sysid)
    return info is not None and info.armed


def _end_state(link: MavlinkLink, sysid: int) -> str:
    info = link.vehicles.get(sysid)
    return "holding (mission complete)" if info is not None and info.armed else "landed (disarmed)"


def end_summary(end_states: dict[int, str]) -> str:
    """Where the vehicles ended, one clause per state: "sysid 1-3, 7 landed (disarmed); sysid 4 ..."."""
    by_state: dict[str, list[int]] = {}
    for sysid, what in sorted(end_states.items()):
        by_state.setdefault(what, []).append(sysid)
    return "; ".join(f"sysid {id_runs(ids)} {what}" for what, ids in by_state.items())
