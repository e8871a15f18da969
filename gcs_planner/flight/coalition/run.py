"""The coalition HIL run loop: simulate, fly the fleet, upload each award's mission as its time comes.

At an award's time the award joins a priority queue served by ``UPLOAD_WORKERS`` upload workers,
earliest deadline first: the deadline is the latest leg start from which the shortest path (from
the pose predicted then) still arrives on time, so a vehicle turning away from its goal goes first;
"idle" missions come last. A worker plans the leg (in a thread) just before the upload, so t0 =
now + the upload estimate + ``START_AHEAD_S`` only allows for that one upload, not for the queue.
The mission's prefix is the predicted turn from now to t0 (the path the vehicle is flying anyway, a
waypoint at least every ``PREFIX_DT_S``). It is built with plan_to_items, uploaded with
MissionClient (``UPLOAD_TIMING``) while the vehicle flies, and started with MISSION_START at the
first waypoint ``START_AHEAD_S`` ahead. The upload estimate is the measured wall time per item (an
EMA over the uploads so far, seeded by the initial fleet upload) x items x speed-up x
``HilOptions.upload_safety``, plus the planning time. An idle mission covering only part of its
span is followed by the next one ``IDLE_LEAD_S`` before its track ends. A ScheduleKeeper holds
every vehicle to its current mission's timing (it is replaced at each upload), as in
``gcs-planner fly``.
"""

from __future__ import annotations

import asyncio
import itertools
import math
import time
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from gcs_planner.core.errors import UserError
from gcs_planner.core.fleet_ids import network_of
from gcs_planner.core.geo import Origin
from gcs_planner.core.lockstep import now_s
from gcs_planner.flight import Flight, RunOptions, run_flight
from gcs_planner.flight.coalition.live_legs import (
    LEG_SPEED_FACTOR,
    RUN_IN_S,
    TURN_FACTOR,
    LiveState,
    Telemetry,
    goal_pose,
    live_state,
    onto_sim_leg,
    plan_live_leg,
    rejoin_leg,
)
from gcs_planner.flight.coalition.missions import (
    IDLE_SPAN_S,
    KEEPER_SAMPLE_S,
    LEAD_IN_S,
    Award,
    Idle,
    VehicleSchedule,
    award_mission,
    build_schedules,
    idle_mission,
)
from gcs_planner.flight.coalition.report import TaskRow, add_prediction_errors, task_rows
from gcs_planner.flight.l1_guidance import L1Response, shape_for_l1
from gcs_planner.flight.limits import read_l1_params
from gcs_planner.flight.ops import KEEPER_PERIOD_S, NAV_TAKEOFF
from gcs_planner.flight.timekeeping import ScheduleKeeper
from gcs_planner.flight.vehicles import VehicleSource
from gcs_planner.mavlink.actions import change_speed, start_mission_at
from gcs_planner.mavlink.errors import MavlinkError
from gcs_planner.mavlink.link import MavlinkLink
from gcs_planner.mavlink.mission import MissionClient
from gcs_planner.mavlink.transfer import Timing
from gcs_planner.missions.items import plan_to_items
from gcs_planner.model.plan import Plan, VehiclePlan
from gcs_planner.model.scenario import Scenario
from gcs_planner.planning.coalition import load_world, paths, simulate
from gcs_planner.planning.coalition.track import Leg
from gcs_planner.telemetry import FlightLogger

__all__ = [
    "UPLOAD_SAFETY", "CoalitionRun", "HilOptions", "HilResult", "OfflineRun", "UploadJob", "UploadTiming",
    "VehiclesFor", "initial_plans", "keep_current", "run_coalition_hil",
]  # fmt: skip

NAV_WAYPOINT = 16
# a connected plane joins the online run from where it is (its first leg is planned live from its
# pose): its start is only checked for a SITL left at its default home, another continent [m]
COALITION_START_M = 1000.0
START_AHEAD_S = 1.0  # an uploaded mission starts at its first waypoint at least this far ahead [s]
PASSED_WITHIN_M = 150.0  # a due waypoint behind the plane and this close was just flown past [m]
PREFIX_DT_S = 2.0  # waypoint spacing on the predicted turn before a live leg [s]
IDLE_LEAD_S = 10.0  # the next idle mission is uploaded this long before the last one's track ends [s]
DEADLINE_HORIZON_S = 30.0  # leg-start deadlines searched this far ahead [s]
UPLOAD_SAFETY = 1.5  # upload estimate = wall time per item x items x speed-up x this (docs/coalition.md)
UPLOAD_WORKERS = 4
# Mission transfers in flight: the defaults' 1.5 s COUNT re-send is 30 s of flight at speed-up 20
UPLOAD_TIMING = Timing(count_retry_s=0.25, count_retries=12, ack_timeout_max_s=0.5, item_timeout_max_s=0.5)
NEXT_REPORT_POLL_S = 0.005  # upload end stamped at the next position report, polled this often [s wall]
NEXT_REPORT_TIMEOUT_S = 2.0
LOGGED_EVENTS = ("tender", "bid", "not_bidding", "late_bid_ignored", "formed", "formation_failed", "award")


@dataclass
class HilOptions:
    """What to fly (targets, UAVs, window), how fast, and the pass bounds of a coalition HIL run."""

    out_dir: Path = Path("out")
    speedup: float | None = None  # mock planes: None runs them in lockstep (gcs_planner.core.lockstep)
    seed: int | None = None  # default: the scenario's [planner] seed
    targets: tuple[str, ...] | None = None  # awards of these targets only (None: all)
    uavs: tuple[str, ...] | None = None  # fly only these awarded UAVs (None: all)
    lead_s: float = 30.0  # window starts this long before the first award [s]
    tail_s: float = 5.0  # and ends this long after the last awarded strike / assessment arc [s]
    waypoint_dt_s: float = 4.0  # longest time between waypoints [s]
    max_time_error_s: float = 1.0
    max_angle_error_deg: float = 10.0
    keep_schedule: bool = True
    replay_legs: bool = False  # upload the simulation's legs instead of live-planned ones (comparison)
    offset_m: dict[str, tuple[float, float]] = field(default_factory=dict)  # UAV id: first-mission shift
    upload_safety: float = UPLOAD_SAFETY  # leg start = now + this x the measured upload estimate (+1 s)
    online: bool = False  # decisions by the contract net in flight (online_run), not the simulation's
    faults: tuple = ()  # online: online_run.Fault events tied to awards (link cut, pop-up threat)


@dataclass
class HilResult:
    """The report rows, the upload log and the flown tracks and legs, for the command and the tests."""

    rows: list[TaskRow]
    uploads: list[dict]
    mcap_path: Path
    t_start_s: float
    wall_time_s: float
    lag_events: int = 0
    failures: list[str] = field(default_factory=list)
    tracks: dict[int, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)  # sysid: t [s], ENU [m]
    legs: dict[tuple[str, str], Leg] = field(default_factory=dict)  # (target, UAV): the leg flown
    events: list[dict] = field(default_factory=list)  # online: the contract net's timeline
    formations: list[dict] = field(default_factory=list)  # online: formations beside the simulation's
    lost_awards: list[dict] = field(default_factory=list)  # online: awards of vehicles lost in flight
    released_awards: list[dict] = field(default_factory=list)  # online: awards handed on (late live leg)
    tender_compute_s: list[float] = field(default_factory=list)  # online: wall time per formation
    tender_cpu_s: list[float] = field(default_factory=list)  # online: CPU time per formation (closed tender)
    end_states: dict[int, str] = field(default_factory=dict)  # how each vehicle was left (safe end)
    interrupted: str | None = None  # the signal that ended the run early (SIGINT, SIGTERM, SIGHUP)

    @property
    def strikes(self) -> list[TaskRow]:
        return [r for r in self.rows if r.task == "strike"]

    @property
    def passed(self) -> bool:
        judged = bool(self.rows) and all(r.passed for r in self.rows)
        return judged and not self.failures and self.interrupted is None


def _first_ahead(items, vp: VehiclePlan, route_now_s: float, margin_s: float, pose=None) -> int:
    """Seq of the first NAV_WAYPOINT (after take-off) whose planned time is still ahead and, given
    the vehicle's pose (x, y, course [rad]), that it has not just flown past (behind it, within
    PASSED_WITHIN_M: a late upload): a plane started towards a waypoint just behind it turns back
    for it (``Plane::set_next_WP``) and can circle it. A vehicle far from the mission's path still
    starts at the waypoint that is due."""
    after = next(i for i, it in enumerate(items) if it.command == NAV_TAKEOFF) + 1
    seqs = [i for i in range(after, len(items)) if items[i].command == NAV_WAYPOINT]
    first = len(vp.waypoints) - len(seqs)  # the take-off item stands for waypoint 0
    times = vp.times_s[first:]
    if len(seqs) == 0 or len(times) != len(seqs):
        return after
    ahead = times >= route_now_s + margin_s
    if pose is not None:
        rel = vp.waypoints[first:, :2] - np.asarray(pose[:2])
        behind = rel @ [math.cos(pose[2]), math.sin(pose[2])] <= 0.0
        ahead &= ~(behind & (np.hypot(rel[:, 0], rel[:, 1]) < PASSED_WITHIN_M))
    index = np.nonzero(ahead)[0]
    return seqs[int(index[0])] if len(index) else seqs[-1]


def _select_awards(result, options: HilOptions, seed: int) -> tuple[list[dict], float, float]:
    """The simulation's awards to fly (of the chosen targets and UAVs, with a leg) and the window
    [t_start, t_stop] [s]: from lead_s before the first award to tail_s after the last strike or
    assessment arc."""
    awards = [
        e for e in result.events
        if e["event"] == "award" and (options.targets is None or e["target"] in options.targets)
        and (options.uavs is None or e["uav"] in options.uavs)
        and (e["target"], e["uav"]) in result.award_legs
    ]  # fmt: skip
    if not awards:
        raise UserError(
            f"no awards for targets {options.targets} and UAVs {options.uavs} in the simulation (seed {seed})"
        )
    t_start = max(0.0, min(e["t_s"] for e in awards) - options.lead_s)
    ends = [
        e["time_s"] if e["task"] == "strike" else result.award_legs[(e["target"], e["uav"])].t[-1]
        for e in awards
    ]
    t_stop = float(max(ends)) + options.tail_s
    awards = [e for e in awards if e["t_s"] <= t_stop]
    unknown = set(options.offset_m) - {e["uav"] for e in awards}
    if unknown:
        raise UserError(f"offset_m names UAVs without an award in the run: {sorted(unknown)}")
    return awards, t_start, t_stop


def _predicted_prefix(state: LiveState, t0_s: float) -> tuple[np.ndarray, np.ndarray]:
    """The turn the vehicle is flying, predicted from its live state up to the leg start t0_s:
    times [s] and xy [m], sampled for the ScheduleKeeper."""
    pre_t = np.unique(np.r_[np.arange(state.t_s, t0_s, KEEPER_SAMPLE_S), t0_s])
    return pre_t, state.predict(pre_t)[:, :2]


@dataclass
class UploadTiming:
    """The upload estimate's inputs, EMAs over the uploads so far (seeded by the fleet upload)."""

    item_s: float  # loop time per mission item at this concurrency (gcs_planner.core.lockstep)
    plan_s: float = 0.0  # loop time to plan a live leg (none under lockstep: the clock waits)
    items: int = 20  # items of the last award mission
    idle_items: int = 30  # and of the last idle mission

    def estimate_s(self, items: int, speedup: float, safety: float) -> float:
        """Flight time [s] an upload of ``items`` is expected to take, with the safety factor."""
        return speedup * (self.plan_s + self.item_s * items) * safety


@dataclass(order=True)
class UploadJob:
    """A mission to plan and upload: due at ``t_s`` [scenario s], then served in ``rank`` order
    (earliest deadline first, idle missions last; equal ranks in arrival order)."""

    t_s: float
    rank: tuple
    kind: str = field(default="award", compare=False)  # "award" | "idle"
    sched: VehicleSchedule | None = field(default=None, compare=False)
    payload: Award | Idle | None = field(default=None, compare=False)
    gen: int = field(default=0, compare=False)  # the vehicle's plan generation it belongs to (online run)


VehiclesFor = Callable[[list[VehiclePlan], Origin, float], VehicleSource]


async def run_coalition_hil(
    scenario: Scenario,
    options: HilOptions,
    vehicles_for: VehiclesFor,
    runner: type | None = None,
    say: Callable[[str], None] | None = None,
) -> HilResult:
    """Simulate, fly the awarded vehicles (``vehicles_for(initial plans, origin, speed-up)``, the mock
    fleet from the CLI) with the one flight runner (gcs_planner.flight), upload each award as a leg
    planned from the vehicle's live state (or, with ``replay_legs``, the simulation's leg).
    ``runner``: the run's class (OfflineRun, online_run.OnlineRun); ``say(line)``: where the run's stages are
    told (each vehicle not ready to arm, once per reason)."""
    run = (runner or OfflineRun)(scenario, options)
    if any(network_of(vp.sysid) > 0 for vp in run.plan.vehicles):
        raise UserError("the coalition run flies one network: its vehicles need sysids 1..254")
    vehicles = vehicles_for(run.plan.vehicles, scenario.origin, options.speedup)
    said: dict[int, str] = {}

    def waiting(stage: str, sysid, reason) -> None:
        if stage == "wait" and say is not None and said.get(sysid) != reason:
            said[sysid] = reason
            say(f"sysid {sysid} not ready to arm yet: {reason} (waiting)")

    return await run_flight(run, vehicles, RunOptions(options.out_dir), waiting, say)


def initial_plans(scenario: Scenario, options: HilOptions, runner: type | None = None) -> list[VehiclePlan]:
    """The first mission of every vehicle the run flies (what ``vehicles_for`` gets)."""
    return (runner or OfflineRun)(scenario, options).plan.vehicles


class CoalitionRun(ABC):
    """A coalition HIL run, the FlightStrategy of the one flight runner (gcs_planner.flight) for
    missions uploaded in flight: the fleet's live state, live legs, the upload queue. Who decides
    the awards is a subclass's: ``OfflineRun`` (the simulation) or ``online_run.OnlineRun`` (the
    contract net in flight); each builds its first missions (``__init__`` ending in
    ``_init_flight``), serves the run (``_serve``) and judges it (``_result``)."""

    command = "fly-coalition"
    # a connected plane joins the run from where it is (its first leg is planned live from its
    # pose): the gate only refuses a SITL left at its default home, another continent
    start_bound_m = COALITION_START_M
    speed_factor = LEG_SPEED_FACTOR  # live legs fly up to this x cruise
    limit_hint = "missions/coalition_sitl.toml is the paper scenario sized for SITL's stock plane"
    climb_into_route = False  # every plane loiters up until all routes start at once
    schedule_bound_s = math.inf  # judged on its strikes' arrival times instead

    def _simulate(self, scenario: Scenario, options: HilOptions) -> int:
        """Run the event simulation; its awards to fly and the window. The seed used."""
        self.scenario, self.options = scenario, options
        self.world = load_world(scenario)
        seed = options.seed if options.seed is not None else int(scenario.planner.get("seed", 0))
        self.sim = simulate(self.world, np.random.default_rng(seed))
        self.awards, self.t_start, self.t_stop = _select_awards(self.sim, options, seed)
        return seed

    def _init_flight(self, initial: list[VehiclePlan]) -> None:
        """The flight's state: the initial missions, the telemetry, the schedule keeper, the queue."""
        scenario = self.scenario
        self.t_route0 = self.t_start - LEAD_IN_S  # scenario time of route time 0 (the lead-in start)
        self.run_in_s = 0.0  # straight into each goal pose (live_legs.RUN_IN_S for connected vehicles)
        self.turn_factor = 1.0  # legs' turns x r_min (live_legs.TURN_FACTOR for connected vehicles)
        self.say: Callable[[str], None] = lambda line: None  # where the run's stages are told
        self.flying = sorted(vp.sysid for vp in initial)
        self.plan = Plan(scenario.origin, "coalition", initial)
        self.uploads: list[dict] = []
        self.failures: list[str] = []
        self.flown_legs: dict[tuple[str, str], Leg] = {}
        self.telemetry = Telemetry(set(self.flying))
        self.keeper = ScheduleKeeper()
        self.current = {vp.sysid: vp for vp in self.plan.vehicles}
        self.route_t0 = 0.0  # the fleet clock's value at route time 0
        self.due: list[UploadJob] = []
        self.queue: asyncio.PriorityQueue[tuple[tuple, int, UploadJob]] = asyncio.PriorityQueue()
        self.order = itertools.count()
        # planes on L1 guidance: NAVL1_PERIOD [s], RLL2SRV_TCONST [s], bank limit [rad]
        self.l1: dict[int, tuple[float, float, float]] = {}

    @abstractmethod
    async def _serve(self, link: MavlinkLink, logger: FlightLogger) -> None:
        """From the route starts until the window ends: queue the missions as they come due."""

    @abstractmethod
    def _result(self, lag_events: int, wall_s: float) -> HilResult:
        """The task rows of the flown awards."""

    # --- the FlightStrategy ------------------------------------------------------------------
    def check(self, vehicles: VehicleSource) -> None:
        """A link-cut fault needs a vehicle source that can cut a link (the mock fleet)."""
        if any(f.kind == "cut" for f in self.options.faults) and not hasattr(vehicles, "cut_link"):
            raise UserError("a link-cut fault needs the mock fleet (this vehicle source cannot cut a link)")

    def attach(self, flight: Flight) -> None:
        """Share the flight's recorder and clock; vehicles on clocks of their own (connected ones)
        lag a turn: their legs get a run-in and wide turns (``connect``)."""
        self.vehicles, self.recorder, self.say = flight.vehicles, flight.recorder, flight.say
        self.mcap_path = flight.mcap_path
        self.telemetry.clock = flight.clock
        flight.link.subscribe(self.telemetry.on_frame)
        if not flight.vehicles.simulated:
            self.connect()

    def connect(self) -> None:
        """Fly vehicles whose guidance lags a turn (legs with a run-in and wide turns)."""
        self.run_in_s, self.turn_factor = RUN_IN_S, TURN_FACTOR

    async def prepare(self, flight: Flight) -> None:
        """Hold the schedule within the vehicles' speed limits; learn connected planes' L1 guidance."""
        self.quirks = flight.quirks
        for sysid, lim in flight.limits.items():
            self.keeper.limit(sysid, lim.min_mps, lim.max_mps)
        if not self.vehicles.simulated:
            l1 = await read_l1_params(flight.link, self.flying, self.quirks)
            limits = flight.limits
            self.l1 = {s: (*p, math.radians(limits[s].roll_deg)) for s, p in l1.items() if s in limits}

    def leads(self, flight: Flight) -> tuple[float, dict[int, float]]:
        """Every route starts at once, 2 s after the fleet is up (fixed wings, already at speed)."""
        return 2.0, {s: 0.0 for s in self.flying}

    async def fly(self, flight: Flight) -> None:
        """The routes start, then the awards are served until the window ends."""
        n_items = sum(len(m) for m in flight.missions.values())
        concurrent = min(flight.options.workers, len(flight.missions))
        self.timing = UploadTiming(flight.upload_s * concurrent / n_items)
        self.route_t0 = flight.route_t0_s
        await flight.routes
        for vp in self.plan.vehicles:
            self.keeper.add(vp)
        self.say(f"routes started; flying scenario time {self.t_start:.0f}-{self.t_stop:.0f} s")
        await self._serve(flight.link, flight.logger)

    def done(self, flight: Flight) -> bool:
        return False  # the planes fly on past the window: every one is sent home

    def result(self, flight: Flight, wall_s: float) -> HilResult:
        """The task rows (``task_rows``), with the flight's lag events and end states."""
        failed = {s: r.error for s, r in flight.uploads.items() if not r.ok}
        if failed:
            booting = "" if self.vehicles.simulated else "; a SITL answers uploads only once booted (~30 s)"
            self.failures.append(f"first mission upload failed for sysid {sorted(failed)}: "
                                 f"{next(iter(failed.values()))}{booting}")  # fmt: skip
        result = self._result(flight.vehicles.lag_events, wall_s)
        result.end_states = flight.end_states
        return result

    # --- clocks and estimates ----------------------------------------------------------------
    def scenario_now(self) -> float:
        return self.recorder.now_s() - self.route_t0 + self.t_route0

    def upload_estimate_s(self, items: int) -> float:
        return self.timing.estimate_s(items, self.vehicles.speedup, self.options.upload_safety)

    def vehicle_state(self, uav) -> LiveState:
        rows = list(self.telemetry.rows[uav.sysid])  # a copy: planning runs in a thread
        state = live_state(rows, self.scenario.origin, 1.05 * uav.speed_mps / uav.r_min_m)
        return replace(state, t_s=state.t_s - self.route_t0 + self.t_route0)

    def _pose(self, uav) -> tuple[float, float, float] | None:
        """The vehicle's newest reported position and course (x, y [m], course [rad]), if any."""
        if not self.telemetry.rows[uav.sysid]:
            return None
        state = self.vehicle_state(uav)
        return state.x_m, state.y_m, state.course_rad

    def known_threats(self, t_s: float) -> list:
        """The threats the legs planned at t_s avoid: the scenario's, known by then."""
        return [th for th in self.world.threats if th.appear_s <= t_s]

    def deadline_s(self, uav, e: dict, now: float) -> float:
        """The latest leg start [s] from which the shortest path (threats ignored) to the award's
        goal, flown at cruise from the pose predicted then, still arrives on time: the uploads'
        order of urgency (earliest deadline first). A vehicle turning away from its goal loses
        more than a second per second of waiting."""
        at = now + np.arange(0.0, DEADLINE_HORIZON_S, 0.5)
        q = self.vehicle_state(uav).predict(at)
        goal = np.broadcast_to(goal_pose(self.world, e), q.shape)
        spare = e["time_s"] - at - paths.shortest_lengths(q, goal, uav.r_min_m) / uav.speed_mps
        late = np.nonzero(spare < 0.0)[0]
        return float(at[late[0]] if len(late) else at[-1] + spare[-1])

    async def _drain(self, workers: list[asyncio.Task], deadline: float) -> None:
        """Let the upload queue empty (10 s at most), stop the workers; a failure when the window
        end was not reached by the wall-clock deadline."""
        try:
            await asyncio.wait_for(self.queue.join(), 10.0)
        finally:
            for w in workers:
                w.cancel()
            await asyncio.gather(*workers, return_exceptions=True)
        if now_s() >= deadline:
            self.failures.append("the run did not reach the window end in time")

    async def _worker(self, link: MavlinkLink, logger: FlightLogger) -> None:
        while True:
            *_, job = await self.queue.get()
            try:
                await self._upload(link, logger, job)
            finally:
                self.queue.task_done()

    # --- one upload --------------------------------------------------------------------------
    async def _upload(self, link: MavlinkLink, logger: FlightLogger, job: UploadJob) -> dict:
        """Plan the job's mission, upload it in flight, start it at the first waypoint ahead; the
        upload's log entry."""
        kind, sched, payload, e = job.kind, job.sched, job.payload, job.payload.event
        sysid = sched.uav.sysid
        entry = {"kind": kind, "uav": e["uav"], "sysid": sysid, "target": e["target"],
                 "task": e["task"], "award_t_s": e["t_s"], "ok": False}  # fmt: skip
        try:
            vp, leg = await self._mission(job, entry)
            items = plan_to_items(vp, self.scenario.origin, self.quirks[sysid].conventions)
            entry["upload_start_s"] = self.scenario_now()
            t_up = now_s()
            await MissionClient(link, sysid, timing=UPLOAD_TIMING).upload(items)
            per_item = (now_s() - t_up) / len(items)
            self.timing.item_s = 0.5 * self.timing.item_s + 0.5 * per_item
            if kind == "award":
                self.timing.items = len(items)
            else:
                self.timing.idle_items = len(items)
            pose = self._pose(sched.uav)
            seq = _first_ahead(items, vp, self.scenario_now() - self.t_route0, START_AHEAD_S, pose)
            await start_mission_at(link, sysid, self.quirks[sysid], seq, len(items) - 1)
            self.current[sysid] = vp
            self.keeper.add(vp)
            if kind == "award":
                self.flown_legs[(e["target"], e["uav"])] = leg
            entry.update(ok=True, start_seq=seq, items=len(items))
            if entry.get("covered_s", math.inf) < payload.end_s - 1.0:  # the next idle chunk
                t_next = entry["covered_s"] - IDLE_LEAD_S
                idle = Idle(t_next, e, payload.end_s, None)
                self.due.append(UploadJob(t_next, (2, t_next), "idle", sched, idle, job.gen))
                self.due.sort()
        except MavlinkError as exc:
            entry["error"] = str(exc)
            self.failures.append(f"{e['uav']}: {kind} upload failed: {exc}")
        # the fleet's clock moves in steps of one position report: the upload ended after the
        # newest report and before the next one, which is its end time (so start < end even when
        # a fast upload fits between two reports)
        entry["upload_end_s"] = await next_report_after(self.scenario_now, self.scenario_now())
        if "t0_s" in entry:
            entry["landed_before_leg_s"] = round(entry["t0_s"] - entry["upload_end_s"], 3)
        self.uploads.append(entry)
        logger.log_event({"event": "upload", **entry})
        return entry

    async def _mission(self, job: UploadJob, entry: dict) -> tuple[VehiclePlan, Leg | None]:
        """The job's mission and leg: planned live (in a thread) or, replaying, the simulation's."""
        sched, payload = job.sched, job.payload
        if job.kind == "idle" and self.options.replay_legs:
            return payload.mission, None
        if self.options.replay_legs:
            leg = payload.sim_leg
            entry["t0_s"] = round(float(leg.t[0]), 3)
            vp = award_mission(sched, payload, leg, None, self.t_route0, self.options.waypoint_dt_s, [])
            return vp, leg
        state, now = self.vehicle_state(sched.uav), self.scenario_now()
        if job.kind == "idle":
            vp, info = await asyncio.to_thread(self._live_idle, sched, payload, state, now)
            entry.update(info)
            return vp, None
        t_plan = now_s()
        leg, vp, info = await asyncio.to_thread(self._live_leg, sched, payload, state, now)
        self.timing.plan_s = 0.5 * self.timing.plan_s + 0.5 * (now_s() - t_plan)
        entry.update(info)
        return vp, leg

    def _live_leg(self, sched: VehicleSchedule, award: Award, state: LiveState, now: float):
        """Plan the award's leg from the vehicle's newest reports (see live_legs). Runs in a thread
        on the wall clock, so that the event loop keeps draining the sockets (a loop blocked for
        ~0.1 s overflows them); under lockstep at once, the clock standing still."""
        e = award.event
        t_plan = time.perf_counter()
        items = self.timing.items
        known = self.known_threats(e["t_s"])
        for _ in range(2):  # once more when the mission has more items than guessed
            t0 = self._leg_start_s(award, now + self.upload_estimate_s(items) + START_AHEAD_S)
            q0 = state.predict([t0])[0]
            leg = plan_live_leg(self.world, e, q0, t0, LEG_SPEED_FACTOR, known, self.run_in_s,
                                self.turn_factor)  # fmt: skip
            if e["task"] == "strike" and not (leg.info["clear"] and abs(leg.info["late_s"]) < 0.05):
                leg = onto_sim_leg(self.world, sched.uav, q0, t0, award.sim_leg, known) or leg
            prefix = _predicted_prefix(state, t0)
            vp = award_mission(sched, award, leg, prefix, self.t_route0, self.options.waypoint_dt_s,
                               np.arange(now, t0, PREFIX_DT_S))  # fmt: skip
            n = len(vp.waypoints) + 4
            if self.upload_estimate_s(n) <= self.upload_estimate_s(items) + 0.5:
                break
            items = n
        vp, shaped = self._for_guidance(vp, t0)
        info = {
            "plan_wall_ms": round(1000.0 * (time.perf_counter() - t_plan), 1),
            "t0_s": round(t0, 3),
            "estimate_s": round(self.upload_estimate_s(items), 3),
            "live_pose": [round(float(v), 2) for v in q0],
            "state_age_s": round(now - state.t_s, 3),
            "turn_rate_dps": round(math.degrees(state.rate_rps), 2),
            "leg_late_s": round(leg.info["late_s"], 3),
            "clear": leg.info["clear"],
            "run_in_s": leg.info.get("run_in_s", 0.0),
            "turn_factor": leg.info.get("turn_factor", 1.0),
            **shaped,
        }
        return leg, vp, info

    def _for_guidance(self, vp: VehiclePlan, t0_s: float) -> tuple[VehiclePlan, dict]:
        """An award mission with its waypoints after t0_s (scenario time: where the vehicle starts
        flying it) shaped for the vehicle's L1 guidance, if it flies one, and for the upload's log
        entry how far the waypoints moved (l1_shift_m) and the turn gain used. Idle missions,
        judged by nothing, are flown as planned."""
        if vp.sysid not in self.l1:
            return vp, {}
        period_s, tau_s, bank_rad = self.l1[vp.sysid]
        gain = self.telemetry.turn_gains[vp.sysid].value
        shaped = shape_for_l1(vp, L1Response(period_s, gain or 1.0, tau_s), bank_rad, t0_s - self.t_route0)
        shift = np.hypot(*(shaped.waypoints - vp.waypoints)[:, :2].T)
        told = None if gain is None else round(gain, 3)
        return shaped, {"l1_shift_m": round(float(shift.max()), 1), "turn_gain": told}

    def _leg_start_s(self, award: Award, earliest_s: float) -> float:
        """When an award's live leg starts, given the earliest start its upload allows."""
        return earliest_s

    def _live_idle(self, sched: VehicleSchedule, idle: Idle, state: LiveState, now: float):
        """Plan the idle mission from the vehicle's newest reports: back onto the simulated track
        (``rejoin_leg``), then along it. Runs in a thread."""
        t_plan = time.perf_counter()
        t0 = now + self.upload_estimate_s(self.timing.idle_items) + START_AHEAD_S
        q0 = state.predict([t0])[0]
        leg = rejoin_leg(self.world, sched.uav, q0, t0, sched.track, idle.end_s, self.known_threats(now))
        prefix = _predicted_prefix(state, t0)
        vp = idle_mission(sched, idle, leg, prefix, self.t_route0, self.options.waypoint_dt_s,
                          np.arange(now, t0, PREFIX_DT_S))  # fmt: skip
        info = {
            "plan_wall_ms": round(1000.0 * (time.perf_counter() - t_plan), 1),
            "t0_s": round(t0, 3),
            "live_pose": [round(float(v), 2) for v in q0],
            "rejoin_s": round(float(leg.t[-1]), 3),
            "covered_s": round(min(idle.end_s, float(leg.t[-1]) + IDLE_SPAN_S), 3),
            "leg_late_s": round(leg.info["late_s"], 3),
            "clear": leg.info["clear"],
        }
        return vp, info


class OfflineRun(CoalitionRun):
    """The offline run: every decision is the simulation's (module docstring); only the awarded
    UAVs fly."""

    def __init__(self, scenario: Scenario, options: HilOptions) -> None:
        self._simulate(scenario, options)
        window = (self.t_start, self.t_stop)
        self.schedules = build_schedules(
            self.world, self.sim, self.awards, *window, options.waypoint_dt_s, options.offset_m
        )
        self._init_flight([s.initial for s in self.schedules])

    async def _serve(self, link: MavlinkLink, logger: FlightLogger) -> None:
        """Until the window ends: log the simulation's events as they come due, queue the awards
        and idle missions at their times, keep the schedule; then let the queue drain."""
        options = self.options
        workers = [asyncio.create_task(self._worker(link, logger)) for _ in range(UPLOAD_WORKERS)]
        self.due = sorted(
            [UploadJob(a.event["t_s"], (a.event["task"] != "strike", a.event["time_s"]), "award", s, a)
             for s in self.schedules for a in s.awards]
            + [UploadJob(i.t_s, (2, i.t_s), "idle", s, i)
               for s in self.schedules for i in s.idles if i.t_s <= self.t_stop]
        )  # fmt: skip
        targets = {e["target"] for e in self.awards}
        events = sorted(
            (e for e in self.sim.events if e["event"] in LOGGED_EVENTS
             and self.t_start <= e["t_s"] <= self.t_stop and e.get("target") in targets),
            key=lambda e: e["t_s"],
        )  # fmt: skip
        route_end = self.t_stop - self.t_route0
        deadline = now_s() + (route_end + 10.0) * 2.0 / self.vehicles.speedup + 10.0
        while self.scenario_now() - self.t_route0 < route_end and now_s() < deadline:
            now = self.scenario_now()
            while events and events[0]["t_s"] <= now:
                logger.log_event({**events.pop(0), "source": "coalition_simulation"})
            while self.due and self.due[0].t_s <= now:
                job = self.due.pop(0)
                if job.kind == "award" and not options.replay_legs:
                    job.rank = (False, self.deadline_s(job.sched.uav, job.payload.event, now))
                self.queue.put_nowait((job.rank, next(self.order), job))
            if options.keep_schedule:
                keep_current(link, self.recorder, self.keeper, self.current, self.route_t0, self.quirks)
            await asyncio.sleep(KEEPER_PERIOD_S / self.vehicles.speedup)
        await self._drain(workers, deadline)

    def _result(self, lag_events: int, wall_s: float) -> HilResult:
        tracks = self.recorder.tracks()
        flown = {s: (tr.times_s - self.route_t0 + self.t_route0, tr.positions) for s, tr in tracks.items()}
        sim_tracks = {s.uav.id: s.track for s in self.schedules}
        limits = (self.options.max_time_error_s, self.options.max_angle_error_deg)
        rows, missing = task_rows(self.world, self.awards, flown, self.flown_legs, sim_tracks, limits)
        add_prediction_errors(self.uploads, flown)
        return HilResult(
            rows, self.uploads, self.mcap_path, self.t_start, wall_s, lag_events, self.failures + missing,
            flown, self.flown_legs,
        )  # fmt: skip


async def next_report_after(clock, t_s: float, timeout_s: float = NEXT_REPORT_TIMEOUT_S) -> float:
    """The first value of ``clock`` (a telemetry clock: it moves only when a report arrives) above
    ``t_s``, polled every ``NEXT_REPORT_POLL_S`` [s wall]; after ``timeout_s`` of wall time without a
    report, the clock's value then (the fleet has stopped reporting: the run fails anyway)."""
    deadline = now_s() + timeout_s
    now = clock()
    while now <= t_s and now_s() < deadline:
        await asyncio.sleep(NEXT_REPORT_POLL_S)
        now = clock()
    return now


def keep_current(
    link, recorder, keeper: ScheduleKeeper, current: dict, route_t0: float, quirks: dict
) -> None:
    """One ScheduleKeeper step: a speed command to each vehicle off its current mission's timing."""
    for sysid, vp in current.items():
        latest = recorder.latest(sysid)
        if latest is None:
            continue
        t_s, position = latest
        if t_s - route_t0 > float(vp.path_times_s[-1]):
            continue
        speed = keeper.speed_command(sysid, t_s - route_t0, position)
        if speed is not None:
            change_speed(link, sysid, quirks[sysid], speed)
