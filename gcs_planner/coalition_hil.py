"""Coalition HIL run (seed 003): the coalition awards become missions uploaded to flying mock vehicles.

The paper's hardware-in-the-loop test pushes each coalition's new paths to the vehicles while the
swarm flies. Here the planner in the loop is the coalition simulation
(gcs_planner.planning.coalition), run first for the seed; it is deterministic, so its decisions
(tenders, bids, awards, legs) are *replayed* onto the vehicles at their award times:

1. Every vehicle awarded a task (of the chosen targets) is a mock fixed wing. Its first mission
   is a straight ``LEAD_IN_S`` lead-in to its simulated position at the window start
   ``t_start`` = first award - ``lead_s``, then its simulated pre-award track (idle loiter, recon)
   up to its leg start t_e^s, then ``EXTEND_S`` more at the same turn rate (the loiter the bids
   predicted, flown until the award lands). Its home is south of the lead-in start by the
   take-off's ground run (the mock climbs heading north), so the climb ends where the route starts.
2. The fleet takes off (fly._take_off_all) and every route starts at once at route time 0 =
   scenario time ``t_start - LEAD_IN_S`` (fly._start_routes).
3. When the route clock reaches an award's time, the awarded vehicle's new mission (its award leg
   with extra waypoints on the last 1.5 s before a strike entry, then ``EXTEND_S`` of its simulated
   track) is built with plan_to_items, uploaded with MissionClient while the vehicle flies, and
   started with MISSION_START at the first waypoint ``START_AHEAD_S`` ahead (an upload that ends
   after t_e^s must not send the vehicle back). Where the simulation flies on for longer before
   the next award or the window end, an "idle" mission (that track) is uploaded at the leg end, so
   urgent award missions stay short. The simulation's tender / bid / award events are logged to
   the MCAP at their times, each upload with its start and end times.
4. A ScheduleKeeper holds every vehicle to its current mission's timing (it is replaced at each
   upload), as in ``gcs-planner fly``; it gets the path every ``KEEPER_SAMPLE_S`` so that its
   60-sample look-ahead stays shorter than a loiter lap.
5. Report: for each strike award, the flown arrival at the stand-off entry point = the closest
   approach of the piecewise-linear flown track (time interpolated, simulated clock), heading =
   that track segment's direction; both against the award (time_s, angle_deg + 180).

Choices: the real-time contract net against live telemetry (bids from the vehicles' reported
states) is future work; awards are replayed. Take-off climbs at ``TAKEOFF_CLIMB_MPS`` (the climb is
not part of the measurement and a real fleet would be airborne before the scenario starts). The
airframe is tuned like fly._airframe_for, with bank for the minimum turn radius at the schedule
keeper's top speed (CATCH_UP_FACTOR x cruise), so catching up does not widen turns.
"""

from __future__ import annotations

import asyncio
import logging
import time
from dataclasses import dataclass, field, replace
from functools import partial
from pathlib import Path

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcs_planner.errors import UserError
from gcs_planner.fly import (
    CATCH_UP_FACTOR,
    G_MPS2,
    HEARTBEAT_WAIT_S,
    KEEPER_PERIOD_S,
    MAX_WALL_TELEMETRY_HZ,
    MOCK_TELEMETRY_HZ,
    NAV_TAKEOFF,
    FlyOptions,
    _airframe_for,
    _start_routes,
    _take_off_all,
    _TrackRecorder,
    _wait_for_vehicles,
)
from gcs_planner.geo import Origin, enu_to_geodetic
from gcs_planner.mavlink.command import CommandClient
from gcs_planner.mavlink.errors import MavlinkError
from gcs_planner.mavlink.fleet import upload_fleet
from gcs_planner.mavlink.items import plan_to_items
from gcs_planner.mavlink.link import MavlinkLink
from gcs_planner.mavlink.mission import MissionClient
from gcs_planner.plan import Plan, VehiclePlan
from gcs_planner.planning.coalition import load_world, simulate
from gcs_planner.scenario import Scenario
from gcs_planner.telemetry import FlightLogger
from gcs_planner.timekeeping import ScheduleKeeper
from sitl_mock.flight import ALT_TOL_M, KP_ALT

__all__ = ["HilOptions", "HilResult", "StrikeRow", "format_strike_report", "run_coalition_hil"]

log = logging.getLogger(__name__)

EXTEND_S = 10.0  # continuation of a pre-award mission at its last turn rate [s]
TAKEOFF_CLIMB_MPS = 40.0  # mock climb rate for the take-off only
NAV_WAYPOINT = 16
LEAD_IN_S = 20.0  # straight lead-in to the window start, flown from the take-off point [s]
START_AHEAD_S = 4.0  # an award mission starts at its first waypoint at least this far ahead [s]
ACCEPTANCE_RADIUS_M = 15.0  # a fixed wing also counts a waypoint once past it
APPROACH_DT_S, APPROACH_POINTS = 0.5, 4  # waypoints on the last 1.5 s before a strike entry
KEEPER_SAMPLE_S = 0.25  # planned-path sampling given to the ScheduleKeeper [s]
MEASURE_WINDOW_S = 15.0  # closest approach searched within this of the awarded time [s]
LOGGED_EVENTS = ("tender", "bid", "not_bidding", "late_bid_ignored", "formed", "formation_failed", "award")


@dataclass
class HilOptions:
    out_dir: Path = Path("out")
    speedup: float = 10.0
    seed: int | None = None  # default: the scenario's [planner] seed
    targets: tuple[str, ...] | None = None  # awards of these targets only (None: all)
    lead_s: float = 30.0  # window starts this long before the first award [s]
    tail_s: float = 5.0  # and ends this long after the last awarded strike [s]
    waypoint_dt_s: float = 2.0
    max_time_error_s: float = 1.0
    max_angle_error_deg: float = 10.0
    autopilot: str = "ardupilot"
    keep_schedule: bool = True


@dataclass
class StrikeRow:
    uav: str
    sysid: int
    target: str
    awarded_s: float
    flown_s: float
    awarded_heading_deg: float
    flown_heading_deg: float
    miss_m: float
    limits: tuple[float, float] = (1.0, 10.0)

    @property
    def time_error_s(self) -> float:
        return self.flown_s - self.awarded_s

    @property
    def angle_error_deg(self) -> float:
        return float((self.flown_heading_deg - self.awarded_heading_deg + 180.0) % 360.0 - 180.0)

    @property
    def passed(self) -> bool:
        return abs(self.time_error_s) <= self.limits[0] and abs(self.angle_error_deg) <= self.limits[1]


@dataclass
class HilResult:
    rows: list[StrikeRow]
    uploads: list[dict]
    mcap_path: Path
    t_start_s: float
    wall_time_s: float
    lag_events: int = 0
    failures: list[str] = field(default_factory=list)
    tracks: dict[int, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)  # sysid: t [s], ENU [m]

    @property
    def passed(self) -> bool:
        return bool(self.rows) and all(r.passed for r in self.rows) and not self.failures


def _piece_plan(uav, t: np.ndarray, xy: np.ndarray, t_origin_s: float, dt_s: float, forced) -> VehiclePlan:
    """A VehiclePlan over one piece of simulated track: waypoints every dt_s, at the forced times
    (strike entries) and at the end; times relative to t_origin_s (route time)."""
    keep = np.searchsorted(t, np.arange(t[0], t[-1], dt_s), side="right") - 1
    forced_idx = [int(np.argmin(np.abs(t - f))) for f in forced if t[0] <= f <= t[-1]]
    keep = np.unique(np.r_[keep, np.asarray(forced_idx, dtype=int), len(t) - 1]).astype(int)
    path = np.column_stack([xy, np.full(len(t), uav.altitude_m)])
    # dense path for the ScheduleKeeper: its look-ahead (60 samples) must stay below one loiter lap
    dense_t = np.unique(np.r_[np.arange(t[0], t[-1], KEEPER_SAMPLE_S), t[-1]])
    dense = np.column_stack([np.interp(dense_t, t, xy[:, 0]), np.interp(dense_t, t, xy[:, 1])])
    return VehiclePlan(
        vehicle_id=uav.id,
        sysid=uav.sysid,
        vehicle_type="fixed_wing",
        waypoints=path[keep],
        times_s=t[keep] - t_origin_s,
        speeds_mps=np.full(len(keep), uav.speed_mps),
        path=np.column_stack([dense, np.full(len(dense_t), uav.altitude_m)]),
        path_times_s=dense_t - t_origin_s,
        turn_radius_m=uav.r_min_m,
        final_action="loiter",
        acceptance_radius_m=ACCEPTANCE_RADIUS_M,
    )


def _continue_turn(t, xy, t_end: float, speed_mps: float, max_rate: float, dt_s: float = 0.5):
    """EXTEND_S of flight after t_end at the track's turn rate there (the pre-award loiter goes on,
    as the bids predicted): times (K,) and positions (K, 2), t_end excluded."""
    tau = t_end + np.array([-2.0, -1.0, 0.0])
    p = np.column_stack([np.interp(tau, t, xy[:, 0]), np.interp(tau, t, xy[:, 1])])
    h = np.arctan2(*np.diff(p, axis=0).T[::-1])
    rate = float(np.clip((h[1] - h[0] + np.pi) % (2 * np.pi) - np.pi, -max_rate, max_rate))
    steps = np.arange(1, int(EXTEND_S / dt_s) + 1)
    heading = h[1] + rate * (0.5 + (steps - 0.5) * dt_s)
    xy_ext = p[-1] + np.cumsum(speed_mps * dt_s * np.column_stack([np.cos(heading), np.sin(heading)]), axis=0)
    return t_end + steps * dt_s, xy_ext


def _slice(t: np.ndarray, xy: np.ndarray, t0: float, t1: float) -> tuple[np.ndarray, np.ndarray]:
    """Track samples in [t0, t1], with the ends interpolated exactly."""
    inner = (t > t0 + 1e-6) & (t < t1 - 1e-6)
    ts = np.r_[t0, t[inner], t1]
    return ts, np.column_stack([np.interp(ts, t, xy[:, 0]), np.interp(ts, t, xy[:, 1])])


@dataclass
class _VehicleSchedule:
    uav: object
    initial: VehiclePlan
    uploads: list[tuple[float, str, dict, VehiclePlan]]  # (scenario time, "award"|"idle", award, mission)


def _track_piece(uav, t, xy, t0: float, dt_s: float, a: float, b: float, forced=(), extend: bool = True):
    """Mission over the simulated track in [a, b] (then the turn continued if ``extend``)."""
    ts, xys = _slice(t, xy, a, b)
    if extend:
        ext_t, ext_xy = _continue_turn(t, xy, b, uav.speed_mps, uav.speed_mps / uav.r_min_m)
        ts, xys = np.r_[ts, ext_t], np.vstack([xys, ext_xy])
    return _piece_plan(uav, ts, xys, t0, dt_s, forced)


def _schedules(world, result, awards, t_start, t_stop, dt_s) -> list[_VehicleSchedule]:
    """Each awarded UAV's missions: the initial one, then one per award (uploaded at the award
    time: the leg plus EXTEND_S of the simulated track after it) and, where the simulation flies on
    for longer before the next award or the window end, an "idle" one uploaded at the leg end
    (its idle loiter / station change), so the urgent award missions stay short."""
    by_uav: dict[str, list[dict]] = {}
    for e in awards:
        by_uav.setdefault(e["uav"], []).append(e)
    out = []
    for uav in sorted((u for u in world.uavs if u.id in by_uav), key=lambda u: u.sysid):
        t, xy, _ = result.tracks[uav.index].history(t_stop + 2 * EXTEND_S)
        t0 = t_start - LEAD_IN_S

        piece = partial(_track_piece, uav, t, xy, t0, dt_s)
        mine = sorted(by_uav[uav.id], key=lambda e: e["t_s"])
        legs = [result.award_legs[(e["target"], uav.id)] for e in mine]
        initial = piece(t_start, float(legs[0].t[0]))
        h0 = np.arctan2(*(initial.path[1, :2] - initial.path[0, :2])[::-1])
        lead_in = initial.path[0, :2] - LEAD_IN_S * uav.speed_mps * np.array([np.cos(h0), np.sin(h0)])
        ts = np.r_[t0, initial.path_times_s + t0]
        xys = np.vstack([lead_in, initial.path[:, :2]])
        initial = _piece_plan(uav, ts, xys, t0, dt_s, [])
        uploads = []
        for k, (e, leg) in enumerate(zip(mine, legs)):
            end = float(legs[k + 1].t[0]) if k + 1 < len(mine) else t_stop
            leg_end = float(leg.t[-1])
            forced = (
                [e["time_s"] - j * APPROACH_DT_S for j in range(APPROACH_POINTS)]
                if e["task"] == "strike"
                else []
            )
            short = end - leg_end <= EXTEND_S
            uploads.append(
                (
                    e["t_s"],
                    "award",
                    e,
                    piece(float(leg.t[0]), end if short else leg_end + EXTEND_S, forced, short),
                )
            )
            if not short:
                uploads.append((leg_end, "idle", e, piece(leg_end, end)))
        out.append(_VehicleSchedule(uav, initial, uploads))
    return out


def _mock_fleet(schedules, origin: Origin, speedup: float):
    from sitl_mock import MockFleet

    specs = []
    for s in schedules:
        vp = s.initial
        frame = _airframe_for(vp)
        run_m = _climb_run_m(float(vp.speeds_mps[0]), TAKEOFF_CLIMB_MPS, float(vp.waypoints[0, 2]))
        lat, lon, alt = enu_to_geodetic(vp.waypoints[0, 0], vp.waypoints[0, 1] - run_m, 0.0, origin)
        fast = CATCH_UP_FACTOR * float(vp.speeds_mps[0])
        bank = float(np.arctan(fast**2 / vp.turn_radius_m / G_MPS2))
        frame = replace(frame, max_bank_rad=max(frame.max_bank_rad, bank), climb_rate_mps=TAKEOFF_CLIMB_MPS)
        specs.append(
            dict(
                sysid=vp.sysid,
                home=Origin(lat, lon, alt),
                vehicle_type="fixed_wing",
                profile="ardupilot",
                airframe=frame,
            )
        )
    rate_hz = min(MOCK_TELEMETRY_HZ * speedup, MAX_WALL_TELEMETRY_HZ)
    return MockFleet(vehicles=specs, speedup=speedup, home=origin, rate_hz=rate_hz)


def _climb_run_m(speed_mps: float, climb_mps: float, alt_m: float, dt_s: float = 0.05) -> float:
    """Ground run [m] of the mock fixed wing's take-off climb (north, at cruise speed, vz = KP_ALT x
    error clipped to the climb rate and 0.9 v), so that its home can be placed that far south of
    where the route starts."""
    z, run = 0.0, 0.0
    while z < alt_m - ALT_TOL_M:
        vz = min(KP_ALT * (alt_m - z), climb_mps, 0.9 * speed_mps)
        z += vz * dt_s
        run += float(np.sqrt(speed_mps**2 - vz**2)) * dt_s
    return run


def _first_ahead(items, vp: VehiclePlan, route_now_s: float, margin_s: float) -> int:
    """Seq of the first NAV_WAYPOINT (after take-off) whose planned time is still ahead."""
    after = next(i for i, it in enumerate(items) if it.command == NAV_TAKEOFF) + 1
    seqs = [i for i in range(after, len(items)) if items[i].command == NAV_WAYPOINT]
    times = vp.times_s[len(vp.waypoints) - len(seqs) :]  # the take-off item stands for waypoint 0
    if len(seqs) == 0 or len(times) != len(seqs):
        return after
    ahead = np.nonzero(times >= route_now_s + margin_s)[0]
    return seqs[int(ahead[0])] if len(ahead) else seqs[-1]


def measure_strike(track_t: np.ndarray, track_xy: np.ndarray, award: dict, limits) -> StrikeRow:
    """Closest approach of the flown track (scenario time, ENU) to the award's entry point."""
    goal = np.asarray(award["entry_xy"], dtype=float)
    sel = np.abs(track_t - award["time_s"]) <= MEASURE_WINDOW_S
    t, p = track_t[sel], track_xy[sel]
    nan = float("nan")
    awarded_heading = (award["angle_deg"] + 180.0) % 360.0
    if len(t) < 2:
        return StrikeRow(award["uav"], award["sysid"], award["target"], award["time_s"], nan,
                         awarded_heading, nan, nan, limits)  # fmt: skip
    a, ab = p[:-1], np.diff(p, axis=0)
    u = np.clip(((goal - a) * ab).sum(1) / np.maximum((ab**2).sum(1), 1e-12), 0.0, 1.0)
    d = np.linalg.norm(a + u[:, None] * ab - goal, axis=1)
    k = int(np.argmin(d))
    flown_s = float(t[k] + u[k] * (t[k + 1] - t[k]))
    heading = float(np.degrees(np.arctan2(ab[k, 1], ab[k, 0])) % 360.0)
    return StrikeRow(award["uav"], award["sysid"], award["target"], award["time_s"], flown_s,
                     awarded_heading, heading, float(d[k]), limits)  # fmt: skip


def format_strike_report(rows: list[StrikeRow]) -> str:
    head = "uav   sysid target awarded_s flown_s  dt_s   awarded_deg flown_deg dangle_deg miss_m  ok"
    lines = [head]
    for r in rows:
        lines.append(
            f"{r.uav:<5} {r.sysid:>5} {r.target:<6} {r.awarded_s:>9.2f} {r.flown_s:>7.2f} "
            f"{r.time_error_s:>+6.2f} {r.awarded_heading_deg:>11.1f} {r.flown_heading_deg:>9.1f} "
            f"{r.angle_error_deg:>+10.1f} {r.miss_m:>6.1f}  {'yes' if r.passed else 'NO'}"
        )
    if rows:
        dt = np.array([abs(r.time_error_s) for r in rows])
        da = np.array([abs(r.angle_error_deg) for r in rows])
        lines.append(
            f"max |dt| {np.nanmax(dt):.2f} s, max |dangle| {np.nanmax(da):.1f} deg over {len(rows)} strikes"
        )
    return "\n".join(lines)


async def run_coalition_hil(scenario: Scenario, options: HilOptions) -> HilResult:
    """Simulate, fly the awarded vehicles on mock autopilots, replay the awards as live uploads."""
    t_wall = time.monotonic()
    world = load_world(scenario)
    seed = options.seed if options.seed is not None else int(scenario.planner.get("seed", 0))
    result = simulate(world, np.random.default_rng(seed))
    awards = [
        e for e in result.events
        if e["event"] == "award" and (options.targets is None or e["target"] in options.targets)
    ]  # fmt: skip
    strikes = [e for e in awards if e["task"] == "strike"]
    if not strikes:
        raise UserError(f"no strike awards for targets {options.targets} in the simulation (seed {seed})")
    t_start = max(0.0, min(e["t_s"] for e in awards) - options.lead_s)
    t_stop = max(e["time_s"] for e in strikes) + options.tail_s
    awards = [e for e in awards if e["t_s"] <= t_stop]
    schedules = _schedules(world, result, awards, t_start, t_stop, options.waypoint_dt_s)
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
    fleet = _mock_fleet(schedules, scenario.origin, options.speedup)
    recorder = _TrackRecorder(scenario.origin, True, {s: len(m) - 1 for s, m in missions.items()})
    with fleet:
        link = await MavlinkLink.open(*[f"udpout:{h}:{p}" for h, p in fleet.addresses])
        try:
            with FlightLogger(mcap_path, scenario.origin, initial, scenario_text) as logger:
                link.subscribe(logger.on_frame)
                link.subscribe(recorder.on_frame)
                await _wait_for_vehicles(link, sorted(flying), HEARTBEAT_WAIT_S)
                first = await upload_fleet(link, missions, workers=8)
                bad = [s for s, r in first.items() if not r.ok]
                if bad:
                    raise UserError(f"initial mission upload failed for sysid {bad}")
                await _take_off_all(link, initial, recorder, options.speedup, fly_options)
                lead_s = 2.0
                route_t0 = recorder.now_s() + lead_s
                await _start_routes(
                    link, initial, missions, options.speedup, logger, lead_s, {s: 0.0 for s in flying}
                )
                keeper = ScheduleKeeper()
                current = {vp.sysid: vp for vp in initial.vehicles}
                for vp in initial.vehicles:
                    keeper.add(vp)
                queue = sorted(replay, key=lambda e: e["t_s"])
                pending = sorted(
                    (u for s in schedules for u in s.uploads if u[0] <= t_stop), key=lambda u: u[0]
                )
                tasks = []

                async def upload(kind: str, e: dict, vp: VehiclePlan) -> None:
                    entry = {
                        "kind": kind,
                        "uav": e["uav"],
                        "sysid": vp.sysid,
                        "target": e["target"],
                        "task": e["task"],
                        "award_t_s": e["t_s"],
                        "upload_start_s": _scenario_now(),
                        "ok": False,
                    }
                    try:
                        items = plan_to_items(vp, scenario.origin, options.autopilot)
                        await MissionClient(link, vp.sysid).upload(items)
                        seq = _first_ahead(items, vp, _scenario_now() - t_route0, START_AHEAD_S)
                        await CommandClient(link, vp.sysid).mission_start(seq, len(items) - 1)
                        current[vp.sysid] = vp
                        keeper.add(vp)
                        entry.update(ok=True, start_seq=seq, items=len(items))
                    except MavlinkError as exc:
                        entry["error"] = str(exc)
                        failures.append(f"{e['uav']}: {kind} upload failed: {exc}")
                    entry["upload_end_s"] = _scenario_now()
                    uploads.append(entry)
                    logger.log_event({"event": "upload", **entry})

                def _scenario_now() -> float:
                    return recorder.now_s() - route_t0 + t_route0

                route_end = t_stop - t_route0
                deadline = time.monotonic() + (route_end + 10.0) * 2.0 / options.speedup + 10.0
                while _scenario_now() - t_route0 < route_end and time.monotonic() < deadline:
                    now = _scenario_now()
                    while queue and queue[0]["t_s"] <= now:
                        e = queue.pop(0)
                        logger.log_event({**e, "source": "coalition_simulation"})
                    while pending and pending[0][0] <= now:
                        _, kind, e, vp = pending.pop(0)
                        tasks.append(asyncio.create_task(upload(kind, e, vp)))
                    if options.keep_schedule:
                        _keep(link, recorder, keeper, current, route_t0)
                    await asyncio.sleep(KEEPER_PERIOD_S / options.speedup)
                await asyncio.gather(*tasks)
                if time.monotonic() >= deadline:
                    failures.append("the run did not reach the window end in time")
        finally:
            await link.close()
        lag = int(getattr(fleet, "lag_events", 0))
    tracks = recorder.tracks()
    rows = []
    flown = {s: (tr.times_s - route_t0 + t_route0, tr.positions) for s, tr in tracks.items()}
    for e in sorted(strikes, key=lambda e: (e["time_s"], e["sysid"])):
        tr = tracks.get(e["sysid"])
        if tr is None:
            failures.append(f"{e['uav']}: no telemetry")
            continue
        t, positions = flown[e["sysid"]]
        rows.append(
            measure_strike(t, positions[:, :2], e, (options.max_time_error_s, options.max_angle_error_deg))
        )
    return HilResult(rows, uploads, mcap_path, t_start, time.monotonic() - t_wall, lag, failures, flown)


def _keep(link, recorder, keeper: ScheduleKeeper, current: dict, route_t0: float) -> None:
    for sysid, vp in current.items():
        latest = recorder.latest(sysid)
        if latest is None:
            continue
        t_s, position = latest
        if t_s - route_t0 > float(vp.path_times_s[-1]):
            continue
        speed = keeper.speed_command(sysid, t_s - route_t0, position)
        if speed is not None:
            link.send(
                mavlink.MAVLink_command_long_message(
                    sysid, 1, mavlink.MAV_CMD_DO_CHANGE_SPEED, 0, 1, speed, -1, 0, 0, 0, 0
                )
            )
