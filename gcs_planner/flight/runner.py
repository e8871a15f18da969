"""The one flight runner: a fleet flown from the link's opening to its report, whatever decides
its missions.

A FlightStrategy says what is flown: a static plan's missions (``fly``, flight/static_plan.py) or
an online task plan whose missions are uploaded in flight (the coalition contract net,
flight.coalition). The runner does for both what every flight needs, in this order: open the link
and the log (MCAP, .tlog on request, live views), wait for the vehicles and learn their autopilots,
request their streams, read and check their limits, the pre-flight gate (each connected vehicle at
its planned start), upload the first missions, check connected vehicles' clocks, take off, start
the routes on time; then the strategy flies until it is done; a failure, a signal or an unfinished
flight ends safely (every airborne vehicle home, flight.ops / mavlink.actions.safe_end) and the
strategy writes the report.

Clocks: the tracks are timed by the vehicles' shared ``time_boot_ms`` when they are simulated (one
clock: the mock fleet in lockstep, docs/clock.md), else by the receive time scaled to the
vehicles' rate (real autopilots, SITL: each boots on a clock of its own).
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import numpy as np

from gcs_planner.autopilots import AutopilotQuirks
from gcs_planner.core.errors import UserError
from gcs_planner.core.fleet_ids import id_runs, network_of
from gcs_planner.core.lockstep import check_loop, now_s, unix_s
from gcs_planner.flight.clock_check import MIN_SPAN_S, ClockRate
from gcs_planner.flight.limits import (
    FlightLimits,
    check_limits,
    check_vertical,
    check_waypoint_timing,
    read_limits,
    read_ramps,
    read_vertical,
    read_waypoint_nav,
)
from gcs_planner.flight.ops import (
    TrackRecorder,
    boot_clock,
    build_missions,
    receive_clock,
    start_routes,
    take_off_all,
    vehicle_quirks,
    wait_for_vehicles,
)
from gcs_planner.flight.safe_signals import SafeEndSignals
from gcs_planner.flight.starts import START_FIX_WAIT_S, check_starts, starts
from gcs_planner.flight.vehicles import VehicleSource
from gcs_planner.mavlink.actions import safe_end
from gcs_planner.mavlink.fleet import VehicleResult, upload_fleet
from gcs_planner.mavlink.link import FLEET_RCVBUF_BYTES, MavlinkLink
from gcs_planner.mavlink.networks import open_networks
from gcs_planner.mavlink.preflight import request_streams
from gcs_planner.mavlink.transfer import Timing
from gcs_planner.mavlink.vehicle_status import VehicleStatus
from gcs_planner.model.plan import Plan
from gcs_planner.model.scenario import Scenario
from gcs_planner.telemetry import FlightLogger
from gcs_planner.telemetry.mcap_log import tlog_network_path

__all__ = [
    "Flight",
    "FlightStrategy",
    "RunOptions",
    "check_networks",
    "end_summary",
    "networks",
    "run_flight",
]

log = logging.getLogger(__name__)

HEARTBEAT_WAIT_S = 10.0  # simulated vehicles answer at once
REAL_HEARTBEAT_WAIT_S = 30.0  # real vehicles / SITL started by hand
END_WAIT_S = 300.0  # after a signal, how long the log waits for the vehicles to land [s flight time]
LANDING_WAIT_S = 60.0  # after the missions, how long the log waits for final landings [s flight time]

Progress = Callable[[str, float, float], None]  # (stage, done, total); ("wait", sysid, reason)


@dataclass
class RunOptions:
    """How a flight is run, whatever is flown."""

    out_dir: Path = Path("out")
    workers: int = 8  # concurrent uploads and take-offs
    tlog: bool = False  # a .tlog per network beside the MCAP log
    timeout_factor: float = 2.0  # a stage may take this many times its planned flight time
    live: object | None = None  # a rerun.RecordingStream: the Rerun views streamed while flying
    in_flight: int = Timing.window  # mission items sent ahead of a vehicle's requests


class FlightStrategy(Protocol):
    """What a flight flies and how it is judged; the runner does the rest (module docstring)."""

    scenario: Scenario
    plan: Plan  # the missions uploaded before take-off (an online run's first ones)
    command: str  # the front end's command, for hints ("fly", "fly-coalition")
    start_bound_m: float  # the pre-flight gate's loosest bound (0: each vehicle's own)
    speed_factor: float  # missions may fly up to this x the planned top speed (the limits check)
    limit_hint: str  # what to do when a vehicle's limits refuse the plan ("": nothing to add)
    schedule_bound_s: float  # the along-track time error a vehicle may fly [s] (inf: not judged on it)
    climb_into_route: bool  # fixed wings start their route as soon as they are up

    def check(self, vehicles: VehicleSource) -> None:
        """Refuse, before anything is sent, what this strategy cannot fly on these vehicles."""

    def attach(self, flight: Flight) -> None:
        """The flight's link, log and recorder exist: subscribe what the strategy listens to."""

    async def prepare(self, flight: Flight) -> None:
        """After the limits are read, before the first upload."""

    def leads(self, flight: Flight) -> tuple[float, dict[int, float]]:
        """Route time 0 this long after the fleet is up [s], and how early each route starts [s]."""

    async def fly(self, flight: Flight) -> None:
        """From the route starts (``flight.routes``, a task) until the flight is done."""

    def done(self, flight: Flight) -> bool:
        """Every mission flown to its end: the vehicles are left as they are, nothing commanded."""

    def result(self, flight: Flight, wall_s: float):
        """The flight's report (a result with an ``interrupted`` field)."""


def networks(plan: Plan) -> int:
    """How many MAVLink networks the plan's vehicles are on (fleet ids, mavlink/networks.py)."""
    return 1 + max((network_of(vp.sysid) for vp in plan.vehicles), default=0)


def check_networks(plan: Plan, given: int) -> None:
    """A link (a --connect) per network the plan's vehicles are on."""
    if given != networks(plan):
        raise UserError(f"the plan's vehicles are on {networks(plan)} MAVLink network(s), but {given}"
                        " were given: one --connect per network")  # fmt: skip


async def run_flight(
    strategy: FlightStrategy,
    vehicles: VehicleSource,
    options: RunOptions,
    progress: Progress | None = None,
    say: Callable[[str], None] | None = None,
):
    """Fly ``strategy`` on ``vehicles``; its result. A signal (Ctrl-C, SIGTERM, SIGHUP) ends the
    flight safely and the result says which (``interrupted``); any other failure is raised after
    the safe end, a UserError saying where each vehicle was left."""
    t_wall = time.monotonic()
    check_loop(vehicles.lockstep)
    strategy.check(vehicles)  # before anything is sent
    options.out_dir.mkdir(parents=True, exist_ok=True)
    with SafeEndSignals() as signals:
        flight = Flight(strategy, vehicles, options, signals, progress, say)
        async with vehicles as urls:
            check_networks(strategy.plan, len(urls))
            await flight.run(urls)
    if signals.received is not None and isinstance(flight.aborted, asyncio.CancelledError):
        result = strategy.result(flight, time.monotonic() - t_wall)  # the vehicles were brought home
        result.interrupted = signals.received.name
        return result
    if flight.aborted is not None:
        ended = end_summary(flight.end_states)
        if flight.end_states:
            log.error("safe end: %s", ended)
        if isinstance(flight.aborted, UserError) and flight.end_states:
            raise UserError(f"{flight.aborted}; safe end: {ended}") from flight.aborted
        raise flight.aborted
    return strategy.result(flight, time.monotonic() - t_wall)


class Flight:
    """One flight's state, from the link's opening to the report; what strategies read and use."""

    def __init__(
        self,
        strategy: FlightStrategy,
        vehicles: VehicleSource,
        options: RunOptions,
        signals: SafeEndSignals,
        progress: Progress | None,
        say: Callable[[str], None] | None,
    ) -> None:
        self.strategy, self.vehicles, self.options, self.signals = strategy, vehicles, options, signals
        self.progress = progress
        self.say = say or (lambda line: None)
        self.plan = strategy.plan
        self.speedup = vehicles.speedup
        self.sysids = [vp.sysid for vp in self.plan.vehicles]
        self.mcap_path = options.out_dir / "flight.mcap"
        tlog = options.out_dir / "flight.tlog"
        self.tlog_path = tlog if options.tlog else None
        self.tlog_paths = (
            [tlog_network_path(tlog, n) for n in range(networks(self.plan))] if options.tlog else []
        )
        self.clock = boot_clock if vehicles.simulated else receive_clock(vehicles.speedup, unix_s())
        relative = [vp.sysid for vp in self.plan.vehicles if vp.altitude_frame == "relative"]
        self.recorder = TrackRecorder(self.plan.origin, self.clock, self.sysids, relative)
        self.clocks = ClockRate(self.sysids)
        self.link: MavlinkLink | None = None
        self.logger: FlightLogger | None = None
        self.status: VehicleStatus | None = None
        self.quirks: dict[int, AutopilotQuirks] = {}
        self.commanded = False  # anything beyond stream requests sent: the pre-flight checks passed
        self.limits: dict[int, FlightLimits] = {}
        self.ramps: dict[int, tuple[float, float]] = {}  # sysid: waypoint acceleration, jerk
        self.missions: dict[int, list] = {}  # the first missions' items
        self.uploads: dict[int, VehicleResult] = {}  # the first missions' uploads
        self.upload_s = 0.0  # loop time the first missions' upload took
        self.route_t0_s = 0.0  # the fleet's route time 0 (track clock)
        self.route_t0: dict[int, float] = {}  # sysid -> its route time 0: the fleet's, a plane's own
        self.routes: asyncio.Task | None = None  # the route starts, running beside strategy.fly
        self.end_states: dict[int, str] = {}
        self.log_errors: list[str] = []
        self.aborted: BaseException | None = None
        self.frames_received = 0

    def now(self) -> float:
        """Now on the tracks' clock: the fleet's simulated time for mocks (read directly: reports
        lag on a busy machine), else the receive time scaled to the vehicles' rate."""
        if not self.vehicles.simulated:
            return self.clock(None, unix_s())
        now = self.vehicles.sim_time_s()
        return self.recorder.now_s() if now is None else now

    async def run(self, urls: list[list[str]]) -> None:
        """Fly on the link to each network's ``urls``; any failure or Ctrl-C ends safely, kept in
        ``aborted``."""
        # a fleet's telemetry arrives in bursts while the log's encoder holds the GIL: at 500
        # vehicles the default 208 kB buffer (~0.1 s of frames) overflowed, 5-10 % lost
        self.link = link = await open_networks(urls, receive_buffer_bytes=FLEET_RCVBUF_BYTES)
        self.status = VehicleStatus(link, self.sysids)
        scenario = self.strategy.scenario
        scenario_text = scenario.path.read_text() if scenario.path else None
        try:  # clock_rate: receive times are wall time at 1/speedup of flight time (telemetry.mcap_log)
            flight_log = FlightLogger(
                self.mcap_path,
                self.plan.origin,
                self.plan,
                scenario_text,
                self.tlog_path,
                clock_rate=self.speedup,
            )
        except OSError as exc:
            self.status.close()
            await link.close()
            raise UserError(f"cannot write the flight log {self.mcap_path}: {exc.strerror or exc}") from None
        with _KeptLog(flight_log, self.log_errors) as self.logger:
            for subscriber in (self.logger, self.recorder, self.clocks):
                link.subscribe(subscriber.on_frame)
            if self.options.live is not None:
                link.subscribe(_live_views(self.options.live, self.plan, scenario, self.speedup).on_frame)
            self.strategy.attach(self)
            try:
                await self._fly()
            except BaseException as exc:  # noqa: BLE001 - any failure or Ctrl-C ends safely, then re-raises
                self.aborted = exc
            finally:
                await self._end()

    async def _fly(self) -> None:
        link, strategy = self.link, self.strategy
        await wait_for_vehicles(
            link, self.sysids, HEARTBEAT_WAIT_S if self.vehicles.simulated else REAL_HEARTBEAT_WAIT_S
        )
        self.quirks = vehicle_quirks(link, self.sysids)
        await request_streams(link, self.sysids)
        self.limits = await read_limits(link, self.sysids, self.quirks)
        own = self.vehicles.own_parameters
        self.ramps = await read_ramps(link, self.sysids, self.quirks) if own else {}
        vertical = await read_vertical(link, self.sysids, self.quirks) if own else {}
        navs = await read_waypoint_nav(link, self.sysids, self.quirks, self.ramps, vertical)
        try:
            check_limits(self.plan.vehicles, self.limits, strategy.speed_factor)
            check_vertical(self.plan.vehicles, vertical, strategy.speed_factor)
            check_waypoint_timing(self.plan.vehicles, navs, strategy.schedule_bound_s)
        except UserError as exc:
            raise UserError(f"{exc} ({strategy.limit_hint})" if strategy.limit_hint else str(exc)) from None
        await self._check_starts()
        self.commanded = True
        await strategy.prepare(self)
        if not await self._upload():
            return
        if not self.vehicles.simulated:
            await self._check_clocks()
        self.say("missions uploaded; arming and taking off")
        await self._take_off()
        await self._start_routes()
        try:
            await strategy.fly(self)
            await self.routes
        finally:  # a failure or a signal: no route may start after the safe end sent the vehicles home
            self.routes.cancel()
            await asyncio.gather(self.routes, return_exceptions=True)

    async def _check_starts(self) -> None:
        """The pre-flight gate: every vehicle the source did not home itself (a connected one)
        reports a position within its bound of its planned start (starts.py), or nothing is
        armed; one line per vehicle that fails (a SITL started without ``--home`` is at its
        default home, another continent)."""
        gated = [
            s for s in starts(self.plan.vehicles, self.plan.origin) if not self.vehicles.homed_here(s.sysid)
        ]
        samples = self.recorder.samples
        deadline = now_s() + START_FIX_WAIT_S
        while not all(samples[s.sysid] for s in gated) and now_s() < deadline:
            await asyncio.sleep(0.05)
        where = {s: rows[-1][1:3] for s, rows in samples.items() if rows}
        path = self.strategy.scenario.path
        command = f"{self.strategy.command} {path.name if path else 'SCENARIO'}"
        check_starts(gated, where, f"start each vehicle there: {command} --homes prints where",
                     self.strategy.start_bound_m)  # fmt: skip

    async def _upload(self) -> bool:
        """Upload the first missions to every vehicle; False (nothing is started) when one failed."""
        self.missions = build_missions(self.plan, self.quirks)
        self.status.last_seq = {s: len(m) - 1 for s, m in self.missions.items()}
        items = sum(len(m) for m in self.missions.values())
        self.say(f"{len(self.sysids)} vehicles heard, within their limits; uploading {items} mission items")
        progress, t_up = self.progress, now_s()
        self.uploads = await upload_fleet(
            self.link,
            self.missions,
            workers=self.options.workers,
            progress=lambda done, total, r: progress and progress("upload", done, total),
            timing=Timing(window=self.options.in_flight),
        )
        self.upload_s = now_s() - t_up
        for sysid, r in self.uploads.items():
            event = {"event": "upload", "kind": "first", "sysid": sysid, "ok": r.ok}
            self.logger.log_event({**event, "error": str(r.error or "")})
        failed = [s for s, r in self.uploads.items() if not r.ok]
        if failed:
            log.error("upload failed for sysid %s; not starting the fleet", id_runs(failed))
        return not failed

    async def _check_clocks(self) -> None:
        """Refuse connected vehicles whose clocks run at another rate than this flight's."""
        deadline = now_s() + 3 * MIN_SPAN_S
        while now_s() < deadline and min(map(self.clocks.span_s, self.sysids)) < MIN_SPAN_S:
            await asyncio.sleep(0.05)
        self.clocks.check(self.speedup)

    async def _take_off(self) -> None:
        """Arm and climb every vehicle; fixed wings climb into their routes where the strategy says
        so, and their own route time 0 is when they reach its first waypoint."""
        plans = {vp.sysid: vp for vp in self.plan.vehicles}

        def plane_started(sysid: int) -> None:
            vp = plans[sysid]
            due_s = max(vp.takeoff_delay_s, float(vp.times_s[0]))  # planned time at its first waypoint
            self.route_t0[sysid] = self.now() + self._run_to_start_s(vp) - due_s

        climb = self.strategy.climb_into_route
        await take_off_all(
            self.link, self.plan, self.status, self.speedup, self.quirks, self.options.workers,
            self.options.timeout_factor, self.progress, self.missions if climb else None, plane_started,
        )  # fmt: skip
        self.logger.log_event({"event": "airborne", "sysids": self.sysids})

    def _run_to_start_s(self, vp) -> float:
        """How long a plane that starts its route now takes to reach its first waypoint, flying
        along its first leg at the leg's speed (it climbs out faster than its climb run assumes)."""
        latest = self.recorder.latest(vp.sysid)
        if latest is None or len(vp.waypoints) < 2:
            return 0.0
        leg = vp.waypoints[1, :2] - vp.waypoints[0, :2]
        ahead_m = float(np.dot(vp.waypoints[0, :2] - latest[1][:2], leg / max(float(np.hypot(*leg)), 1e-9)))
        return max(ahead_m, 0.0) / max(float(vp.speeds_mps[1]), 1e-3)

    async def _start_routes(self) -> None:
        """Route time 0 after the strategy's lead; every route not yet started starts on time (a task)."""
        lead_s, leads = self.strategy.leads(self)
        self.route_t0_s = self.now() + lead_s
        climbed = frozenset(self.route_t0)  # planes already in their routes
        self.route_t0 = {s: self.route_t0.get(s, self.route_t0_s) for s in self.sysids}
        self.routes = asyncio.create_task(start_routes(
            self.link, self.plan, self.missions, self.speedup, self.logger, lead_s, leads, self.quirks,
            climbed, self._started,
        ))  # fmt: skip

    def _started(self, sysid: int, route_s: float) -> None:
        """A route's start is being sent, due at route time ``route_s``: its route time 0 is taken
        from now, so a start this process sent late (a busy machine; a mock does not wait for it)
        is not charged to the vehicle's schedule, while everything the vehicle does after is."""
        self.route_t0[sysid] = self.now() - route_s

    async def _end(self) -> None:
        """Send airborne vehicles home after a failure or an unfinished flight (nothing after a
        finished one, nor after a refusal before anything was commanded: a vehicle the pre-flight
        checks refused is left as it was), log it, close the link."""
        sent_home = self.commanded and (self.aborted is not None or not self.strategy.done(self))
        if sent_home:
            self.end_states = await asyncio.shield(safe_end(self.link, self.status, self.quirks))
            if self.signals.received is not None:
                await self._until_landed()
        elif self.commanded:  # every mission done: command nothing, say where each vehicle ended
            landing = {vp.sysid for vp in self.plan.vehicles if vp.final_action == "land"}
            try:
                await self._until_disarmed(landing, LANDING_WAIT_S)
            except asyncio.CancelledError:  # a signal: they land on their own missions; stop waiting
                asyncio.current_task().uncancel()
            self.end_states = {s: _end_state(self.link, s, s in landing) for s in self.sysids}
        if self.end_states:
            states = {str(k): v for k, v in self.end_states.items()}
            self.logger.log_event({"event": "safe_end" if sent_home else "end", "states": states})
        self.status.close()
        await self.link.close()
        self.frames_received = self.link.frames_received

    async def _until_landed(self) -> None:
        """After a signal's safe end: keep logging until every vehicle has landed (disarmed), for at
        most END_WAIT_S of flight time or until a second signal; then say where each one is."""
        task = asyncio.current_task()
        if task is not None:
            task.uncancel()  # the signal's cancel is handled: this wait may await again
        log.warning("%s: vehicles sent home; logging until they land (send it again to stop waiting)",
                    self.signals.received.name)  # fmt: skip
        armed = await self._until_disarmed(self.sysids, END_WAIT_S)
        ended = self.end_states
        self.end_states = {s: what if s in armed else "landed (disarmed)" for s, what in ended.items()}
        self.logger.log_event({"event": "end_wait", "still_armed": armed})

    async def _until_disarmed(self, sysids, wait_s: float) -> list[int]:
        """Keep logging until the armed ones of ``sysids`` have disarmed (landed), for at most
        ``wait_s`` of flight time or until a second signal; those still armed."""
        deadline = now_s() + wait_s / self.speedup
        armed = [s for s in sysids if _armed(self.link, s)]
        while armed and now_s() < deadline and not self.signals.hurry.is_set():
            await asyncio.sleep(0.1)
            armed = [s for s in armed if _armed(self.link, s)]
        return armed


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


def _end_state(link: MavlinkLink, sysid: int, lands: bool) -> str:
    """Where a vehicle whose mission is complete ended; ``lands``: its mission ends in a landing."""
    if not _armed(link, sysid):
        return "landed (disarmed)"
    return "still armed on its final landing (mission complete)" if lands else "holding (mission complete)"


def end_summary(end_states: dict[int, str]) -> str:
    """Where the vehicles ended, one clause per state: "sysid 1-3, 7 landed (disarmed); sysid 4 ..."."""
    by_state: dict[str, list[int]] = {}
    for sysid, what in sorted(end_states.items()):
        by_state.setdefault(what, []).append(sysid)
    return "; ".join(f"sysid {id_runs(ids)} {what}" for what, ids in by_state.items())
