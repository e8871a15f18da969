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
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from gcs_planner.coalition_hil.fleet import mock_fleet
from gcs_planner.coalition_hil.live_legs import (
    LEG_SPEED_FACTOR,
    LiveState,
    Telemetry,
    goal_pose,
    live_state,
    onto_sim_leg,
    plan_live_leg,
    rejoin_leg,
)
from gcs_planner.coalition_hil.missions import (
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
from gcs_planner.coalition_hil.report import TaskRow, add_prediction_errors, task_rows
from gcs_planner.errors import UserError
from gcs_planner.fly import (
    HEARTBEAT_WAIT_S,
    KEEPER_PERIOD_S,
    NAV_TAKEOFF,
    FlyOptions,
    _start_routes,
    _take_off_all,
    _TrackRecorder,
    _wait_for_vehicles,
    vehicle_quirks,
)
from gcs_planner.mavlink.actions import change_speed, start_mission_at
from gcs_planner.mavlink.errors import MavlinkError
from gcs_planner.mavlink.fleet import upload_fleet
from gcs_planner.mavlink.items import plan_to_items
from gcs_planner.mavlink.link import MavlinkLink
from gcs_planner.mavlink.mission import MissionClient
from gcs_planner.mavlink.preflight import request_streams
from gcs_planner.mavlink.transfer import Timing
from gcs_planner.mavlink.vehicle_status import VehicleStatus
from gcs_planner.plan import Plan, VehiclePlan
from gcs_planner.planning.coalition import load_world, paths, simulate
from gcs_planner.planning.coalition.track import Leg
from gcs_planner.scenario import Scenario
from gcs_planner.telemetry import FlightLogger
from gcs_planner.timekeeping import ScheduleKeeper

__all__ = ["UPLOAD_SAFETY", "HilOptions", "HilResult", "run_coalition_hil"]

NAV_WAYPOINT = 16
START_AHEAD_S = 1.0  # an uploaded mission starts at its first waypoint at least this far ahead [s]
PREFIX_DT_S = 2.0  # waypoint spacing on the predicted turn before a live leg [s]
IDLE_LEAD_S = 10.0  # the next idle mission is uploaded this long before the last one's track ends [s]
DEADLINE_HORIZON_S = 30.0  # leg-start deadlines searched this far ahead [s]
# upload estimate = measured wall time per item x items x speed-up x this. Smaller starts legs
# sooner (a mission landing after its leg start joins the leg a little late and catches up): 0.5
# hit 8/8 of T1's strikes in 3 of 3 runs at speed-up 20 but 4/20 with the whole fleet, where
# uploads take 5-15 s of flight; 1.5 hit 3-8/8 and 7-18/20.
UPLOAD_SAFETY = 1.5
UPLOAD_WORKERS = 4
RCVBUF_BYTES = 4 << 20  # GCS socket receive buffer (Linux caps it at net.core.rmem_max)
# Mission transfers in flight: the defaults' 1.5 s COUNT re-send is 30 s of flight at speed-up 20
UPLOAD_TIMING = Timing(count_retry_s=0.25, count_retries=12, ack_timeout_max_s=0.5, item_timeout_max_s=0.5)
NEXT_REPORT_POLL_S = 0.005  # upload end stamped at the next position report, polled this often [s wall]
NEXT_REPORT_TIMEOUT_S = 2.0
LOGGED_EVENTS = ("tender", "bid", "not_bidding", "late_bid_ignored", "formed", "formation_failed", "award")


@dataclass
class HilOptions:
    """What to fly (targets, UAVs, window), how fast, and the pass bounds of a coalition HIL run."""

    out_dir: Path = Path("out")
    speedup: float = 10.0
    seed: int | None = None  # default: the scenario's [planner] seed
    targets: tuple[str, ...] | None = None  # awards of these targets only (None: all)
    uavs: tuple[str, ...] | None = None  # fly only these awarded UAVs (None: all)
    lead_s: float = 30.0  # window starts this long before the first award [s]
    tail_s: float = 5.0  # and ends this long after the last awarded strike / assessment arc [s]
    waypoint_dt_s: float = 4.0  # longest time between waypoints [s]
    max_time_error_s: float = 1.0
    max_angle_error_deg: float = 10.0
    autopilot: str = "ardupilot"
    keep_schedule: bool = True
    replay_legs: bool = False  # upload the simulation's legs instead of live-planned ones (comparison)
    offset_m: dict[str, tuple[float, float]] = field(default_factory=dict)  # UAV id: first-mission shift
    upload_safety: float = UPLOAD_SAFETY  # leg start = now + this x the measured upload estimate (+1 s)


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

    @property
    def strikes(self) -> list[TaskRow]:
        return [r for r in self.rows if r.task == "strike"]

    @property
    def passed(self) -> bool:
        return bool(self.rows) and all(r.passed for r in self.rows) and not self.failures


def _first_ahead(items, vp: VehiclePlan, route_now_s: float, margin_s: float) -> int:
    """Seq of the first NAV_WAYPOINT (after take-off) whose planned time is still ahead."""
    after = next(i for i, it in enumerate(items) if it.command == NAV_TAKEOFF) + 1
    seqs = [i for i in range(after, len(items)) if items[i].command == NAV_WAYPOINT]
    times = vp.times_s[len(vp.waypoints) - len(seqs) :]  # the take-off item stands for waypoint 0
    if len(seqs) == 0 or len(times) != len(seqs):
        return after
    ahead = np.nonzero(times >= route_now_s + margin_s)[0]
    return seqs[int(ahead[0])] if len(ahead) else seqs[-1]


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


async def run_coalition_hil(scenario: Scenario, options: HilOptions) -> HilResult:
    """Simulate, fly the awarded vehicles on mock autopilots, upload each award as a leg planned from
    the vehicle's live state (or, with ``replay_legs``, the simulation's leg)."""
    t_wall = time.monotonic()
    world = load_world(scenario)
    seed = options.seed if options.seed is not None else int(scenario.planner.get("seed", 0))
    result = simulate(world, np.random.default_rng(seed))
    awards, t_start, t_stop = _select_awards(result, options, seed)
    schedules = build_schedules(
        world, result, awards, t_start, t_stop, options.waypoint_dt_s, options.offset_m
    )
    t_route0 = t_start - LEAD_IN_S  # scenario time of route time 0 (the lead-in start)
    flying = {s.uav.sysid for s in schedules}
    targets = {e["target"] for e in awards}
    replay = [
        e for e in result.events
        if e["event"] in LOGGED_EVENTS and t_start <= e["t_s"] <= t_stop and e.get("target") in targets
    ]  # fmt: skip
    initial = Plan(scenario.origin, "coalition", [s.initial for s in schedules])
    missions = {vp.sysid: plan_to_items(vp, scenario.origin, options.autopilot) for vp in initial.vehicles}
    options.out_dir.mkdir(parents=True, exist_ok=True)
    mcap_path = options.out_dir / "flight.mcap"
    fly_options = FlyOptions(out_dir=options.out_dir, speedup=options.speedup, autopilot=options.autopilot)
    scenario_text = scenario.path.read_text() if scenario.path else None
    uploads: list[dict] = []
    failures: list[str] = []
    flown_legs: dict[tuple[str, str], Leg] = {}
    fleet = mock_fleet(schedules, scenario.origin, options.speedup)
    recorder = _TrackRecorder(scenario.origin, True, list(missions))
    telemetry = Telemetry(flying)
    with fleet:
        # ~2000 reports/s arrive; the default 208 kB buffer holds ~0.1 s of them, and a mission
        # message lost when it overflows costs a re-send timer
        urls = [f"udpout:{h}:{p}" for h, p in fleet.addresses]
        link = await MavlinkLink.open(*urls, receive_buffer_bytes=RCVBUF_BYTES)
        try:
            with FlightLogger(mcap_path, scenario.origin, initial, scenario_text) as logger:
                link.subscribe(logger.on_frame)
                link.subscribe(recorder.on_frame)
                link.subscribe(telemetry.on_frame)
                await _wait_for_vehicles(link, sorted(flying), HEARTBEAT_WAIT_S)
                quirks = vehicle_quirks(link, sorted(flying))
                status = VehicleStatus(link, sorted(flying))
                await request_streams(link, sorted(flying))
                t_up = time.monotonic()
                first = await upload_fleet(link, missions, workers=8)
                bad = [s for s, r in first.items() if not r.ok]
                if bad:
                    raise UserError(f"initial mission upload failed for sysid {bad}")
                # seed of the upload estimate: wall time per item at this concurrency
                n_items = sum(len(m) for m in missions.values())
                timing = {"item_wall_s": (time.monotonic() - t_up) * min(8, len(missions)) / n_items,
                          "plan_wall_s": 0.0, "items": 20, "idle_items": 30}  # fmt: skip
                await _take_off_all(link, initial, status, options.speedup, fly_options, quirks)
                lead_s = 2.0
                route_t0 = recorder.now_s() + lead_s
                await _start_routes(
                    link, initial, missions, options.speedup, logger, lead_s, {s: 0.0 for s in flying}, quirks
                )
                keeper = ScheduleKeeper()
                current = {vp.sysid: vp for vp in initial.vehicles}
                for vp in initial.vehicles:
                    keeper.add(vp)

                def scenario_now() -> float:
                    return recorder.now_s() - route_t0 + t_route0

                def upload_estimate_s(items: int) -> float:
                    wall = timing["plan_wall_s"] + timing["item_wall_s"] * items
                    return options.speedup * wall * options.upload_safety

                def vehicle_state(uav) -> LiveState:
                    rows = list(telemetry.rows[uav.sysid])  # a copy: planning runs in a thread
                    state = live_state(rows, scenario.origin, 1.05 * uav.speed_mps / uav.r_min_m)
                    return replace(state, t_s=state.t_s - route_t0 + t_route0)

                def deadline_s(uav, e: dict, now: float) -> float:
                    """The latest leg start [s] from which the shortest path (threats ignored) to the
                    award's goal, flown at cruise from the pose predicted then, still arrives on
                    time: the uploads' order of urgency (earliest deadline first). A vehicle turning
                    away from its goal loses more than a second per second of waiting."""
                    at = now + np.arange(0.0, DEADLINE_HORIZON_S, 0.5)
                    q = vehicle_state(uav).predict(at)
                    goal = np.broadcast_to(goal_pose(world, e), q.shape)
                    spare = e["time_s"] - at - paths.shortest_lengths(q, goal, uav.r_min_m) / uav.speed_mps
                    late = np.nonzero(spare < 0.0)[0]
                    return float(at[late[0]] if len(late) else at[-1] + spare[-1])

                def live_leg(sched: VehicleSchedule, award: Award, state: LiveState, now: float):
                    """Plan the award's leg from the vehicle's newest reports (see live_legs).
                    Runs in a thread, so that the event loop keeps draining the sockets: a loop
                    blocked for ~0.1 s overflows them and a lost mission message costs a 1 s
                    (wall) re-request."""
                    e = award.event
                    t_plan = time.monotonic()
                    items = timing["items"]
                    for _ in range(2):  # once more when the mission has more items than guessed
                        t0 = now + upload_estimate_s(items) + START_AHEAD_S
                        q0 = state.predict([t0])[0]
                        leg = plan_live_leg(world, e, q0, t0, LEG_SPEED_FACTOR)
                        if e["task"] == "strike" and not (
                            leg.info["clear"] and abs(leg.info["late_s"]) < 0.05
                        ):
                            leg = onto_sim_leg(world, sched.uav, q0, t0, award.sim_leg, e["t_s"]) or leg
                        prefix = _predicted_prefix(state, t0)
                        vp = award_mission(sched, award, leg, prefix, t_route0, options.waypoint_dt_s,
                                            np.arange(now, t0, PREFIX_DT_S))  # fmt: skip
                        n = len(vp.waypoints) + 4
                        if upload_estimate_s(n) <= upload_estimate_s(items) + 0.5:
                            break
                        items = n
                    plan_wall_s = time.monotonic() - t_plan
                    timing["plan_wall_s"] = 0.5 * timing["plan_wall_s"] + 0.5 * plan_wall_s
                    info = {
                        "plan_wall_ms": round(1000.0 * plan_wall_s, 1),
                        "t0_s": round(t0, 3),
                        "estimate_s": round(t0 - now - START_AHEAD_S, 3),
                        "live_pose": [round(float(v), 2) for v in q0],
                        "state_age_s": round(now - state.t_s, 3),
                        "turn_rate_dps": round(math.degrees(state.rate_rps), 2),
                        "leg_late_s": round(leg.info["late_s"], 3),
                        "clear": leg.info["clear"],
                    }
                    return leg, vp, info

                def live_idle(sched: VehicleSchedule, idle: Idle, state: LiveState, now: float):
                    """Plan the idle mission from the vehicle's newest reports: back onto the
                    simulated track (``rejoin_leg``), then along it. Runs in a thread."""
                    t_plan = time.monotonic()
                    t0 = now + upload_estimate_s(timing["idle_items"]) + START_AHEAD_S
                    q0 = state.predict([t0])[0]
                    leg = rejoin_leg(world, sched.uav, q0, t0, sched.track, idle.end_s, now)
                    prefix = _predicted_prefix(state, t0)
                    vp = idle_mission(sched, idle, leg, prefix, t_route0, options.waypoint_dt_s,
                                       np.arange(now, t0, PREFIX_DT_S))  # fmt: skip
                    info = {
                        "plan_wall_ms": round(1000.0 * (time.monotonic() - t_plan), 1),
                        "t0_s": round(t0, 3),
                        "live_pose": [round(float(v), 2) for v in q0],
                        "rejoin_s": round(float(leg.t[-1]), 3),
                        "covered_s": round(min(idle.end_s, float(leg.t[-1]) + IDLE_SPAN_S), 3),
                        "leg_late_s": round(leg.info["late_s"], 3),
                        "clear": leg.info["clear"],
                    }
                    return vp, info

                async def upload(kind: str, sched: VehicleSchedule, payload) -> None:
                    e = payload.event
                    sysid = sched.uav.sysid
                    entry = {"kind": kind, "uav": e["uav"], "sysid": sysid, "target": e["target"],
                             "task": e["task"], "award_t_s": e["t_s"], "ok": False}  # fmt: skip
                    try:
                        if kind == "idle" and options.replay_legs:
                            vp = payload.mission
                        elif kind == "idle":
                            state, now = vehicle_state(sched.uav), scenario_now()
                            vp, info = await asyncio.to_thread(live_idle, sched, payload, state, now)
                            entry.update(info)
                        elif options.replay_legs:
                            leg = payload.sim_leg
                            vp = award_mission(sched, payload, leg, None, t_route0, options.waypoint_dt_s, [])
                            entry["t0_s"] = round(float(leg.t[0]), 3)
                        else:
                            state, now = vehicle_state(sched.uav), scenario_now()
                            leg, vp, info = await asyncio.to_thread(live_leg, sched, payload, state, now)
                            entry.update(info)
                        items = plan_to_items(vp, scenario.origin, options.autopilot)
                        entry["upload_start_s"] = scenario_now()
                        t_up = time.monotonic()
                        await MissionClient(link, sysid, timing=UPLOAD_TIMING).upload(items)
                        per_item = (time.monotonic() - t_up) / len(items)
                        timing["item_wall_s"] = 0.5 * timing["item_wall_s"] + 0.5 * per_item
                        timing["items" if kind == "award" else "idle_items"] = len(items)
                        seq = _first_ahead(items, vp, scenario_now() - t_route0, START_AHEAD_S)
                        await start_mission_at(link, sysid, quirks[sysid], seq, len(items) - 1)
                        current[sysid] = vp
                        keeper.add(vp)
                        if kind == "award":
                            flown_legs[(e["target"], e["uav"])] = leg
                        entry.update(ok=True, start_seq=seq, items=len(items))
                        if entry.get("covered_s", math.inf) < payload.end_s - 1.0:  # the next idle chunk
                            t_next = entry["covered_s"] - IDLE_LEAD_S
                            due.append(
                                (t_next, (2, t_next), "idle", sched, Idle(t_next, e, payload.end_s, None))
                            )
                            due.sort(key=lambda d: (d[0], d[1]))
                    except MavlinkError as exc:
                        entry["error"] = str(exc)
                        failures.append(f"{e['uav']}: {kind} upload failed: {exc}")
                    # the fleet's clock moves in steps of one position report: the upload ended
                    # after the newest report and before the next one, which is its end time (so
                    # start < end even when a fast upload fits between two reports)
                    entry["upload_end_s"] = await next_report_after(scenario_now, scenario_now())
                    if "t0_s" in entry:
                        entry["landed_before_leg_s"] = round(entry["t0_s"] - entry["upload_end_s"], 3)
                    uploads.append(entry)
                    logger.log_event({"event": "upload", **entry})

                queue: asyncio.PriorityQueue = asyncio.PriorityQueue()
                order = itertools.count()

                async def worker() -> None:
                    while True:
                        *_, kind, sched, payload = await queue.get()
                        try:
                            await upload(kind, sched, payload)
                        finally:
                            queue.task_done()

                workers = [asyncio.create_task(worker()) for _ in range(UPLOAD_WORKERS)]
                due = [
                    (a.event["t_s"], (a.event["task"] != "strike", a.event["time_s"]), "award", s, a)
                    for s in schedules
                    for a in s.awards
                ]
                due += [
                    (i.t_s, (2, i.t_s), "idle", s, i) for s in schedules for i in s.idles if i.t_s <= t_stop
                ]
                due.sort(key=lambda d: (d[0], d[1]))
                events = sorted(replay, key=lambda e: e["t_s"])
                route_end = t_stop - t_route0
                deadline = time.monotonic() + (route_end + 10.0) * 2.0 / options.speedup + 10.0
                while scenario_now() - t_route0 < route_end and time.monotonic() < deadline:
                    now = scenario_now()
                    while events and events[0]["t_s"] <= now:
                        logger.log_event({**events.pop(0), "source": "coalition_simulation"})
                    while due and due[0][0] <= now:
                        _, rank, kind, sched, payload = due.pop(0)
                        if kind == "award" and not options.replay_legs:
                            rank = (False, deadline_s(sched.uav, payload.event, now))
                        queue.put_nowait((rank, next(order), kind, sched, payload))
                    if options.keep_schedule:
                        _keep(link, recorder, keeper, current, route_t0, quirks)
                    await asyncio.sleep(KEEPER_PERIOD_S / options.speedup)
                try:
                    await asyncio.wait_for(queue.join(), 10.0)
                finally:
                    for w in workers:
                        w.cancel()
                    await asyncio.gather(*workers, return_exceptions=True)
                if time.monotonic() >= deadline:
                    failures.append("the run did not reach the window end in time")
        finally:
            await link.close()
    lag = fleet.lag_events
    tracks = recorder.tracks()
    flown = {s: (tr.times_s - route_t0 + t_route0, tr.positions) for s, tr in tracks.items()}
    sim_tracks = {s.uav.id: s.track for s in schedules}
    limits = (options.max_time_error_s, options.max_angle_error_deg)
    rows, missing = task_rows(world, awards, flown, flown_legs, sim_tracks, limits)
    failures += missing
    add_prediction_errors(uploads, flown)
    return HilResult(
        rows, uploads, mcap_path, t_start, time.monotonic() - t_wall, lag, failures, flown, flown_legs
    )


async def next_report_after(clock, t_s: float, timeout_s: float = NEXT_REPORT_TIMEOUT_S) -> float:
    """The first value of ``clock`` (a telemetry clock: it moves only when a report arrives) above
    ``t_s``, polled every ``NEXT_REPORT_POLL_S`` [s wall]; after ``timeout_s`` of wall time without a
    report, the clock's value then (the fleet has stopped reporting: the run fails anyway)."""
    deadline = time.monotonic() + timeout_s
    now = clock()
    while now <= t_s and time.monotonic() < deadline:
        await asyncio.sleep(NEXT_REPORT_POLL_S)
        now = clock()
    return now


def _keep(link, recorder, keeper: ScheduleKeeper, current: dict, route_t0: float, quirks: dict) -> None:
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
