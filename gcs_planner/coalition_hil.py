"""Coalition HIL run (seed 003): coalition awards flown by mock vehicles on legs planned from live telemetry.

The paper's hardware-in-the-loop test pushes each coalition's new paths to the vehicles while the
swarm flies. Here the run splits the work in two:

- **The decisions come from the simulation.** The coalition simulation
  (gcs_planner.planning.coalition) runs first for the seed. Its contract net decides every award:
  the winning vehicle, the target and task, the awarded time and the attack (or assessment)
  angle. The run keeps those decisions and logs them at their times. A real-time contract net with
  bids from telemetry is future work.
- **The flown legs come from live state.** When an award's mission is about to be uploaded, the
  vehicle's leg is planned from its own newest GLOBAL_POSITION_INT reports, not from the
  simulated state: position, course and ground speed of the newest report, turn rate fitted over
  the last ``FIT_S`` of course (``live_state``). That turn is propagated to the leg start
  t0 = now + the upload estimate + ``START_AHEAD_S``. From that pose the leg goes to the award's
  stand-off entry pose (strike) or assessment-arc start pose (assess), arriving at the awarded
  time at the awarded angle (``plan_live_leg``). It uses the coalition path functions as sim.py's
  ``_replan`` does: ``paths.min_route`` for safe-point threat avoidance (threats known at the
  award), ``paths.timed_route`` for radius stretching with detour and loiter fallbacks,
  ``paths.sample_segments``, and for an assessment ``paths.arc_leg`` after the transit. The
  report gives, per award, the distance and heading between the simulated and the flown pose at
  the flown leg's start.

Flow:
1. Every vehicle awarded a task (of the chosen targets and UAVs) is a mock fixed wing; the fleet
   runs in its own process (``_FleetProcess``). Its first mission is a straight ``LEAD_IN_S``
   lead-in to its simulated position at the window start ``t_start`` = first award - ``lead_s``,
   then its simulated pre-award track (idle loiter, recon) up to its simulated leg start t_e^s,
   then ``PRE_AWARD_EXTEND_S`` more at the same turn rate (the loiter the bids predicted, flown
   until the award's mission starts). Its home is south of the lead-in start by the take-off's
   ground run (the mock climbs heading north), so the climb ends where the route starts.
   ``HilOptions.offset_m`` moves a vehicle's first mission (tests: its live state then differs
   from the simulated one).
2. The fleet takes off (fly._take_off_all) and every route starts at once at route time 0 =
   scenario time ``t_start - LEAD_IN_S`` (fly._start_routes).
3. At an award's time the award joins a priority queue served by ``UPLOAD_WORKERS`` upload
   workers, earliest deadline first: the deadline is the latest leg start from which the shortest
   path (from the pose predicted then) still arrives on time, so a vehicle turning away from its
   goal goes first; "idle" missions come last. A worker plans the leg (in a thread) just before
   the upload, so t0 only allows for that one upload, not for the queue. The mission is: the
   predicted turn from now to t0 (the path the vehicle is flying anyway, a waypoint at least every
   ``PREFIX_DT_S``), the leg (waypoints every 0.5 s on the last 1.5 s before the goal pose and 1 s
   after it), then ``AFTER_GOAL_S`` of the simulated track. It is built with plan_to_items,
   uploaded with MissionClient (``UPLOAD_TIMING``) while the vehicle flies, and started with
   MISSION_START at the first waypoint ``START_AHEAD_S`` ahead. The upload estimate is the
   measured wall time per item (an EMA over the uploads so far, seeded by the initial fleet
   upload) x items x speed-up x ``HilOptions.upload_safety``, plus the planning time. At the leg end an
   "idle" mission (the simulated track up to the next award or the window end) is uploaded, so the
   urgent award missions stay short (19-45 items). Waypoints are placed every ``TURN_STEP_DEG`` of
   turn and at least every ``waypoint_dt_s``: fewer items on straights, so uploads land sooner.
   ``HilOptions.replay_legs`` uploads the simulation's own legs instead (the earlier behaviour,
   kept for comparison; the test shows it missing where the live leg hits).
4. A ScheduleKeeper holds every vehicle to its current mission's timing (it is replaced at each
   upload), as in ``gcs-planner fly``; it gets the path every ``KEEPER_SAMPLE_S`` so that its
   60-sample look-ahead stays shorter than a loiter lap.
5. Report, one row per award (``measure_task``): the flown arrival at the goal point (strike:
   stand-off entry point; assess: arc start point) = the closest approach of the piecewise-linear
   flown track (time interpolated, simulated clock), heading = that track segment's direction,
   both against the award (time_s; strike heading angle_deg + 180, assessment heading the CCW
   tangent angle_deg + 90). An assessment row also gives the largest radial deviation from the
   assessment circle over the arc's duration (bound ``ARC_TOL_M``).

Choices: a live leg short of time is planned faster, up to ``LEG_SPEED_FACTOR`` x cruise (the
mock's top speed is CATCH_UP_FACTOR x cruise); one that cannot arrive on time even then is flown
at its minimum length and reported late. An assessor's transit is timed to reach the arc start at
the awarded time (the simulation instead flies to the arc start and waits on the circle, and its
track jumps there). Isolated far samples are removed from the simulated tracks before they
become missions (``_drop_spikes``). Take-off climbs at ``TAKEOFF_CLIMB_MPS`` (the climb is not
part of the measurement and a real fleet would be airborne before the scenario starts). The
airframe is tuned like fly._airframe_for, with bank for the minimum turn radius at the schedule
keeper's top speed (CATCH_UP_FACTOR x cruise), so catching up does not widen turns.
"""

from __future__ import annotations

import asyncio
import itertools
import logging
import math
import multiprocessing
import time
from collections import deque
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
from gcs_planner.geo import Origin, enu_to_geodetic, geodetic_to_enu
from gcs_planner.mavlink.command import CommandClient
from gcs_planner.mavlink.errors import MavlinkError
from gcs_planner.mavlink.fleet import upload_fleet
from gcs_planner.mavlink.items import plan_to_items
from gcs_planner.mavlink.link import MavlinkLink
from gcs_planner.mavlink.mission import MissionClient
from gcs_planner.mavlink.transfer import Timing
from gcs_planner.plan import Plan, VehiclePlan
from gcs_planner.planning.coalition import load_world, paths, simulate
from gcs_planner.planning.coalition.track import Leg
from gcs_planner.scenario import Scenario
from gcs_planner.telemetry import FlightLogger
from gcs_planner.timekeeping import ScheduleKeeper
from sitl_mock.flight import ALT_TOL_M, KP_ALT

__all__ = [
    "HilOptions",
    "HilResult",
    "LiveState",
    "TaskRow",
    "format_strike_report",
    "live_state",
    "measure_task",
    "plan_live_leg",
    "run_coalition_hil",
]

log = logging.getLogger(__name__)

AFTER_GOAL_S = 2.0  # simulated track flown after an award leg; the idle upload follows [s]
PRE_AWARD_EXTEND_S = 30.0  # continuation of a pre-award mission at its last turn rate [s]
TAKEOFF_CLIMB_MPS = 40.0  # mock climb rate for the take-off only
NAV_WAYPOINT = 16
LEAD_IN_S = 20.0  # straight lead-in to the window start, flown from the take-off point [s]
START_AHEAD_S = 1.0  # an uploaded mission starts at its first waypoint at least this far ahead [s]
PREFIX_DT_S = 2.0  # waypoint spacing on the predicted turn before a live leg [s]
IDLE_SPAN_S = 40.0  # an idle mission covers at most this much simulated track; the next one follows [s]
IDLE_LEAD_S = 10.0  # the next idle mission is uploaded this long before the last one's track ends [s]
REJOIN_MIN_S = 10.0  # an idle mission rejoins the simulated track at least this long after its start [s]
DEADLINE_HORIZON_S = 30.0  # leg-start deadlines searched this far ahead [s]
FIT_S = 2.0  # turn rate fitted over this much of the newest course reports [s]
# upload estimate = measured wall time per item x items x speed-up x this. Smaller starts legs
# sooner (a mission landing after its leg start joins the leg a little late and catches up): 0.5
# hit 8/8 of T1's strikes in 3 of 3 runs at speed-up 20 but 4/20 with the whole fleet, where
# uploads take 5-15 s of flight; 1.5 hit 3-8/8 and 7-18/20.
UPLOAD_SAFETY = 1.5
UPLOAD_WORKERS = 4
SPEED_TRIES = (0.9, 1.1, 0.8, 1.2)  # other speeds / cruise for a live leg that cannot clear the threats
LEG_SPEED_FACTOR = 1.2  # a live leg short of time may be planned up to this x cruise (mock top: 1.3)
TURN_STEP_DEG = 30.0  # a waypoint every this much turn of the planned path
ACCEPTANCE_RADIUS_M = 15.0  # a fixed wing also counts a waypoint once past it
APPROACH_DT_S, APPROACH_POINTS = 0.5, 4  # waypoints on the last 1.5 s before a goal pose (and 1 s after)
KEEPER_SAMPLE_S = 0.25  # planned-path sampling given to the ScheduleKeeper [s]
MEASURE_WINDOW_S = 15.0  # closest approach searched within this of the awarded time [s]
ARC_TOL_M = 50.0  # an assessment arc is flown within this of the assessment circle [m]
RCVBUF_BYTES = 4 << 20  # GCS socket receive buffer (Linux caps it at net.core.rmem_max)
# Mission transfers in flight: the defaults' 1.5 s COUNT re-send is 30 s of flight at speed-up 20
UPLOAD_TIMING = Timing(count_retry_s=0.25, count_retries=12, ack_timeout_max_s=0.5, item_timeout_max_s=0.5)
FLEET_START_S = 30.0  # the mock fleet's process must be serving within this [s]
LOGGED_EVENTS = ("tender", "bid", "not_bidding", "late_bid_ignored", "formed", "formation_failed", "award")


@dataclass
class HilOptions:
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
class TaskRow:
    """One award's flown arrival at its goal pose against the award, and its start-pose difference."""

    uav: str
    sysid: int
    target: str
    task: str  # "strike" | "assess"
    awarded_s: float
    flown_s: float
    awarded_heading_deg: float
    flown_heading_deg: float
    miss_m: float
    limits: tuple[float, float] = (1.0, 10.0)
    arc_dev_m: float = float("nan")  # assess: largest |distance to target - arc radius| on the arc [m]
    start_diff_m: float = float("nan")  # simulated vs flown position at the flown leg's start [m]
    start_dheading_deg: float = float("nan")  # simulated vs flown heading there [deg]

    @property
    def time_error_s(self) -> float:
        return self.flown_s - self.awarded_s

    @property
    def angle_error_deg(self) -> float:
        return float((self.flown_heading_deg - self.awarded_heading_deg + 180.0) % 360.0 - 180.0)

    @property
    def passed(self) -> bool:
        ok = abs(self.time_error_s) <= self.limits[0] and abs(self.angle_error_deg) <= self.limits[1]
        return ok and (self.task != "assess" or self.arc_dev_m <= ARC_TOL_M)


@dataclass
class HilResult:
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


# ---- live state
@dataclass(frozen=True)
class LiveState:
    """A vehicle's newest reported state: time [s, simulated], ENU position [m], course [rad, CCW
    from east], ground speed [m/s] and fitted turn rate [rad/s]."""

    t_s: float
    x_m: float
    y_m: float
    course_rad: float
    speed_mps: float
    rate_rps: float

    def predict(self, t_s) -> np.ndarray:
        """(len(t), 3) x, y, course at times t_s, flying the same turn at the same speed."""
        dt = np.atleast_1d(np.asarray(t_s, dtype=float)) - self.t_s
        h = self.course_rad + self.rate_rps * dt
        if abs(self.rate_rps) < 1e-6:
            x = self.x_m + self.speed_mps * dt * math.cos(self.course_rad)
            y = self.y_m + self.speed_mps * dt * math.sin(self.course_rad)
        else:
            rho = self.speed_mps / self.rate_rps
            x = self.x_m + rho * (np.sin(h) - math.sin(self.course_rad))
            y = self.y_m - rho * (np.cos(h) - math.cos(self.course_rad))
        return np.column_stack([x, y, h])


def live_state(rows, origin: Origin, max_rate_rps: float, fit_s: float = FIT_S) -> LiveState | None:
    """LiveState from GLOBAL_POSITION_INT rows (t [s], lat, lon [deg], v_east, v_north [m/s]), oldest
    first: the newest row's position, course and speed; the turn rate is the least-squares slope of
    the unwrapped course over the last fit_s, clipped to +-max_rate_rps."""
    if not rows:
        return None
    arr = np.asarray(rows, dtype=float)
    arr = arr[arr[:, 0] >= arr[-1, 0] - fit_s]
    course = np.unwrap(np.arctan2(arr[:, 4], arr[:, 3]))
    rate = 0.0
    if len(arr) >= 3 and arr[-1, 0] - arr[0, 0] > 0.2:
        rate = float(np.clip(np.polyfit(arr[:, 0], course, 1)[0], -max_rate_rps, max_rate_rps))
    x, y, _ = geodetic_to_enu(arr[-1, 1], arr[-1, 2], origin.alt_m, origin)
    speed = float(np.hypot(arr[-1, 3], arr[-1, 4]))
    return LiveState(float(arr[-1, 0]), float(x), float(y), float(course[-1]), speed, rate)


class _Telemetry:
    """The newest GLOBAL_POSITION_INT reports of each vehicle (simulated clock)."""

    def __init__(self, sysids, keep: int = 64) -> None:
        self.rows = {s: deque(maxlen=keep) for s in sysids}

    def on_frame(self, msg, raw: bytes, t_s: float) -> None:
        if msg.get_type() != "GLOBAL_POSITION_INT":
            return
        rows = self.rows.get(msg.get_srcSystem())
        if rows is not None:
            rows.append(
                (msg.time_boot_ms / 1000.0, msg.lat / 1e7, msg.lon / 1e7, msg.vy / 100.0, msg.vx / 100.0)
            )


def _goal_pose(world, award: dict) -> np.ndarray:
    """The award's goal pose: strike stand-off entry pose or assessment arc start pose."""
    p = world.params
    target = next(t for t in world.targets if t.id == award["target"])
    angle = math.radians(award["angle_deg"])
    if award["task"] == "strike":
        return paths.entry_poses(target.xy, [angle], p.standoff_m)[0]
    return paths.arc_start_pose(target.xy, angle, p.assess_radius_m)[0]


def timed_leg(
    world, uav, q0, t0_s: float, goal, t_goal_s: float, known, kind: str, max_speed_factor=1.0
) -> Leg:
    """A threat-avoiding Dubins leg from pose q0 at t0_s to pose goal at t_goal_s (poses: x, y,
    heading [rad]): at cruise when there is time; else the minimum route, flown up to
    max_speed_factor x cruise (info["speed_mps"]); if that is still too slow, late (info["late_s"]
    > 0). When the timing fallbacks find no threat-clear path of the length the speed asks for,
    the other speeds of SPEED_TRIES (up to max_speed_factor) are tried."""
    p = world.params
    route = paths.min_route(q0, goal, uav.r_min_m, known, p.kappa, p.sample_ds_m)
    span_s = max(t_goal_s - t0_s, 1e-3)
    speed = float(np.clip(route.length_m / span_s, uav.speed_mps, max_speed_factor * uav.speed_mps))
    others = [f * uav.speed_mps for f in SPEED_TRIES if f * uav.speed_mps * span_s >= route.length_m]
    first = None
    for v in [speed, *(v for v in others if v <= max_speed_factor * uav.speed_mps and v != speed)]:
        segs, clear = paths.timed_route(route, max(route.length_m, v * span_s), known, p.sample_ds_m)
        length = sum(seg.length for seg in segs)
        attempt = (segs, bool(clear and route.clear), v)
        first = first or attempt
        if attempt[1] and abs(length - v * span_s) < 0.05 * v:
            break
    else:
        attempt = first
    segs, clear, speed = attempt
    leg = paths.sample_segments(segs, t0_s, speed, p.sample_ds_m, kind, {"clear": clear, "speed_mps": speed})
    leg.info["late_s"] = float(leg.t[-1] - t_goal_s)
    return leg


def plan_live_leg(world, award: dict, q0: np.ndarray, t0_s: float, max_speed_factor: float = 1.0) -> Leg:
    """The award's leg from pose q0 (x, y, heading [rad]) at t0_s (see ``timed_leg``): to the strike
    entry pose, or to the assessment arc start followed by the assessment arc, arriving at
    award["time_s"], around the threats known at the award."""
    p = world.params
    uav = next(u for u in world.uavs if u.id == award["uav"])
    target = next(t for t in world.targets if t.id == award["target"])
    known = [th for th in world.threats if th.appear_s <= award["t_s"]]
    strike = award["task"] == "strike"
    leg = timed_leg(world, uav, q0, t0_s, _goal_pose(world, award), float(award["time_s"]), known,
                    "strike" if strike else "transit", max_speed_factor)  # fmt: skip
    leg.info["target"] = target.id
    if strike:
        return leg
    arc = paths.arc_leg(target.xy, p.assess_radius_m, math.radians(award["angle_deg"]), float(leg.t[-1]),
                        target.assess_duration_s, uav.speed_mps, p.sample_ds_m, "assess")  # fmt: skip
    return Leg(np.r_[leg.t, arc.t[1:]], np.r_[leg.xy, arc.xy[1:]], np.r_[leg.heading, arc.heading[1:]],
               "assess", {**leg.info, "arc_t0_s": float(arc.t[0])})  # fmt: skip


def rejoin_leg(world, uav, q0, t0_s: float, track, end_s: float, now_s: float) -> Leg:
    """A timed leg from pose q0 at t0_s back onto the simulated track (t, xy) at the earliest time
    t_j >= t0_s + REJOIN_MIN_S (and <= end_s) whose point the shortest path reaches at 0.9 x
    cruise: after a strike or assessment the vehicle returns to where the simulation has it, so
    that its next award starts from about the simulated state."""
    t, xy = track
    grid = np.arange(t0_s + REJOIN_MIN_S, max(end_s, t0_s + REJOIN_MIN_S + 1.0), 1.0)
    goals = np.array([_pose_at(t, xy, tj) for tj in grid])
    lengths = paths.shortest_lengths(np.broadcast_to(q0, goals.shape), goals, uav.r_min_m)
    ok = np.nonzero(lengths <= 0.9 * uav.speed_mps * (grid - t0_s))[0]
    j = int(ok[0]) if len(ok) else len(grid) - 1
    known = [th for th in world.threats if th.appear_s <= now_s]
    return timed_leg(world, uav, q0, t0_s, goals[j], float(grid[j]), known, "transit")


def _onto_sim_leg(world, uav, q0, t0_s: float, sim_leg: Leg, now_s: float) -> Leg | None:
    """Fallback for a strike whose live leg finds no threat-clear path of the right length: a
    timed leg onto the simulation's own strike leg (``rejoin_leg``), then the rest of that leg
    (which the simulation planned clear). None when that is not clear and on time either."""
    rejoin = rejoin_leg(world, uav, q0, t0_s, (sim_leg.t, sim_leg.xy), float(sim_leg.t[-1]), now_s)
    if not rejoin.info["clear"] or abs(rejoin.info["late_s"]) >= 0.05 or rejoin.t[-1] >= sim_leg.t[-1]:
        return None
    rest = sim_leg.t > rejoin.t[-1] + 1e-6
    info = {**sim_leg.info, **rejoin.info, "onto_sim_leg": True, "late_s": 0.0}
    return Leg(np.r_[rejoin.t, sim_leg.t[rest]], np.r_[rejoin.xy, sim_leg.xy[rest]],
               np.r_[rejoin.heading, sim_leg.heading[rest]], "strike", info)  # fmt: skip


# ---- missions
def _waypoint_index(t: np.ndarray, xy: np.ndarray, dt_s: float, forced) -> np.ndarray:
    """Indices of the waypoints: every TURN_STEP_DEG of turn, at least every dt_s, the samples
    nearest the forced times, and the last sample."""
    h = np.unwrap(np.arctan2(*np.diff(xy, axis=0).T[::-1])) if len(t) > 1 else np.zeros(1)
    turn = np.r_[0.0, np.cumsum(np.abs(np.diff(h)))]
    by_turn = np.searchsorted(turn, np.arange(0.0, turn[-1], math.radians(TURN_STEP_DEG)), side="left")
    by_time = np.searchsorted(t, np.arange(t[0], t[-1], dt_s), side="right") - 1
    forced_idx = [int(np.argmin(np.abs(t - f))) for f in forced if t[0] <= f <= t[-1]]
    idx = np.r_[by_turn, by_time, np.asarray(forced_idx, dtype=int), len(t) - 1]
    return np.unique(np.clip(idx, 0, len(t) - 1)).astype(int)


def _speeds(t: np.ndarray, xy: np.ndarray, keep: np.ndarray, cruise_mps: float) -> np.ndarray:
    """Ground speed on the leg ending at each kept sample (path length / time), within [0.8, 1.2] x
    cruise (SPEED_TRIES, LEG_SPEED_FACTOR), as a live leg may be flown; a jump in a simulated track
    (the simulation's tracks have some) must not set the airframe's speed. Within 2 % of cruise it
    is cruise, so that speed items are only emitted where the speed really changes."""
    s = np.r_[0.0, np.cumsum(np.hypot(*np.diff(xy, axis=0).T))][keep]
    v = np.r_[cruise_mps, np.diff(s) / np.maximum(np.diff(t[keep]), 1e-9)]
    v = np.clip(v, min(SPEED_TRIES) * cruise_mps, LEG_SPEED_FACTOR * cruise_mps)
    return np.where(np.abs(v - cruise_mps) <= 0.02 * cruise_mps, cruise_mps, v)


def _piece_plan(uav, t: np.ndarray, xy: np.ndarray, t_origin_s: float, dt_s: float, forced) -> VehiclePlan:
    """A VehiclePlan over one piece of track (see _waypoint_index); times relative to t_origin_s
    (route time)."""
    keep = _waypoint_index(t, xy, dt_s, forced)
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
        speeds_mps=_speeds(t, xy, keep, uav.speed_mps),
        path=np.column_stack([dense, np.full(len(dense_t), uav.altitude_m)]),
        path_times_s=dense_t - t_origin_s,
        turn_radius_m=uav.r_min_m,
        final_action="loiter",
        acceptance_radius_m=ACCEPTANCE_RADIUS_M,
    )


def _continue_turn(
    t, xy, t_end: float, speed_mps: float, max_rate: float, extend_s: float, dt_s: float = 0.5
):
    """extend_s of flight after t_end at the track's turn rate there (the pre-award loiter goes on,
    as the bids predicted): times (K,) and positions (K, 2), t_end excluded."""
    tau = t_end + np.array([-2.0, -1.0, 0.0])
    p = np.column_stack([np.interp(tau, t, xy[:, 0]), np.interp(tau, t, xy[:, 1])])
    h = np.arctan2(*np.diff(p, axis=0).T[::-1])
    rate = float(np.clip((h[1] - h[0] + np.pi) % (2 * np.pi) - np.pi, -max_rate, max_rate))
    steps = np.arange(1, int(extend_s / dt_s) + 1)
    heading = h[1] + rate * (0.5 + (steps - 0.5) * dt_s)
    xy_ext = p[-1] + np.cumsum(speed_mps * dt_s * np.column_stack([np.cos(heading), np.sin(heading)]), axis=0)
    return t_end + steps * dt_s, xy_ext


def _slice(t: np.ndarray, xy: np.ndarray, t0: float, t1: float) -> tuple[np.ndarray, np.ndarray]:
    """Track samples in [t0, t1], with the ends interpolated exactly."""
    inner = (t > t0 + 1e-6) & (t < t1 - 1e-6)
    ts = np.r_[t0, t[inner], t1]
    return ts, np.column_stack([np.interp(ts, t, xy[:, 0]), np.interp(ts, t, xy[:, 1])])


def _pose_at(t: np.ndarray, xy: np.ndarray, t_s: float) -> np.ndarray:
    """x, y, heading [rad] of a sampled track at t_s (heading of the segment there)."""
    k = int(np.clip(np.searchsorted(t, t_s) - 1, 0, len(t) - 2))
    u = (t_s - t[k]) / max(t[k + 1] - t[k], 1e-9)
    d = xy[k + 1] - xy[k]
    return np.r_[xy[k] + u * d, math.atan2(d[1], d[0])]


@dataclass
class _Award:
    """One award to fly: the simulated leg and the simulated track after it, up to ``end_s``."""

    event: dict
    sim_leg: Leg
    end_s: float  # the next award's leg start or the window end


@dataclass
class _Idle:
    """The flight after an award's leg: the simulated track from t_s (the leg end) to end_s."""

    t_s: float
    event: dict  # the award whose leg ends at t_s
    end_s: float
    mission: VehiclePlan | None  # the simulated track itself (replay_legs)


@dataclass
class _VehicleSchedule:
    uav: object
    initial: VehiclePlan
    track: tuple[np.ndarray, np.ndarray]  # simulated t [s], xy [m] over the window
    awards: list[_Award]
    idles: list[_Idle]


def _track_piece(uav, t, xy, t0: float, dt_s: float, a: float, b: float, forced=(), extend_s: float = 0.0):
    """Mission over the simulated track in [a, b] (then the turn continued for extend_s)."""
    ts, xys = _slice(t, xy, a, b)
    if extend_s > 0:
        ext_t, ext_xy = _continue_turn(t, xy, b, uav.speed_mps, uav.speed_mps / uav.r_min_m, extend_s)
        ts, xys = np.r_[ts, ext_t], np.vstack([xys, ext_xy])
    return _piece_plan(uav, ts, xys, t0, dt_s, forced)


def _drop_spikes(t: np.ndarray, xy: np.ndarray, speed_mps: float) -> tuple[np.ndarray, np.ndarray]:
    """The simulated track without its isolated far samples: a sample reached and left at more than
    twice the cruise speed. Track.start_leg, cutting a leg short, fills the gap up to the new leg
    with the loiter planned after the cut leg, which starts elsewhere (one sample, up to 1.6 km
    away, on the station changes at t = 140 s of the paper scenario); as a waypoint it would send the
    vehicle there."""
    v = np.hypot(*np.diff(xy, axis=0).T) / np.maximum(np.diff(t), 1e-9)
    spike = np.r_[False, (v[:-1] > 2.0 * speed_mps) & (v[1:] > 2.0 * speed_mps), False]
    return t[~spike], xy[~spike]


def _schedules(world, result, awards, t_start, t_stop, dt_s, offsets) -> list[_VehicleSchedule]:
    """Each awarded UAV's missions: the initial one, its awards (flown from the award time: the leg
    plus AFTER_GOAL_S of the simulated track after it) and, where the simulation flies on before
    the next award or the window end, an "idle" one uploaded at the leg end (its idle loiter /
    station change), so the urgent award missions stay short."""
    by_uav: dict[str, list[dict]] = {}
    for e in awards:
        by_uav.setdefault(e["uav"], []).append(e)
    out = []
    for uav in sorted((u for u in world.uavs if u.id in by_uav), key=lambda u: u.sysid):
        t, xy = _drop_spikes(
            *result.tracks[uav.index].history(t_stop + 2 * PRE_AWARD_EXTEND_S)[:2], uav.speed_mps
        )
        t0 = t_start - LEAD_IN_S
        piece = partial(_track_piece, uav, t, xy, t0, dt_s)
        mine = sorted(by_uav[uav.id], key=lambda e: e["t_s"])
        legs = [result.award_legs[(e["target"], uav.id)] for e in mine]
        initial = piece(t_start, float(legs[0].t[0]), extend_s=PRE_AWARD_EXTEND_S)
        h0 = np.arctan2(*(initial.path[1, :2] - initial.path[0, :2])[::-1])
        lead_in = initial.path[0, :2] - LEAD_IN_S * uav.speed_mps * np.array([np.cos(h0), np.sin(h0)])
        ts = np.r_[t0, initial.path_times_s + t0]
        xys = np.vstack([lead_in, initial.path[:, :2]]) + np.asarray(offsets.get(uav.id, (0.0, 0.0)))
        initial = _piece_plan(uav, ts, xys, t0, dt_s, [])
        flown, idles = [], []
        for k, (e, leg) in enumerate(zip(mine, legs)):
            end = float(legs[k + 1].t[0]) if k + 1 < len(mine) else t_stop
            leg_end = float(leg.t[-1])
            flown.append(_Award(e, leg, end))
            if end - leg_end > AFTER_GOAL_S:
                idles.append(_Idle(leg_end, e, end, piece(leg_end, end, extend_s=PRE_AWARD_EXTEND_S)))
        out.append(_VehicleSchedule(uav, initial, (t, xy), flown, idles))
    return out


def _award_track(sched: _VehicleSchedule, award: _Award, leg: Leg):
    """Times and positions of an award mission after its leg: AFTER_GOAL_S of the simulated track
    from the simulated leg's end (where the live leg also ends), shifted by a live leg's lateness."""
    t, xy = sched.track
    sim_end = float(award.sim_leg.t[-1])
    stop = min(award.end_s, sim_end + AFTER_GOAL_S)
    if stop - sim_end < 1e-3:
        return np.zeros(0), np.zeros((0, 2))
    ts, xys = _slice(t, xy, sim_end, stop)
    return ts[1:] + max(0.0, float(leg.t[-1]) - sim_end), xys[1:]


def _award_mission(
    sched, award: _Award, leg: Leg, prefix, t_route0: float, dt_s: float, prefix_wp_s
) -> VehiclePlan:
    """The award mission: [the predicted turn up to the leg start (prefix: times, xy), waypoints at
    prefix_wp_s,] the leg, the track after it."""
    uav, e = sched.uav, award.event
    tail_t, tail_xy = _award_track(sched, award, leg)
    parts_t, parts_xy = [leg.t], [leg.xy]
    forced = []
    if prefix is not None:
        pt, pxy = prefix
        parts_t.insert(0, pt[:-1])
        parts_xy.insert(0, pxy[:-1])
        forced += list(prefix_wp_s)
    goal_s = float(leg.info.get("arc_t0_s", leg.t[-1] if e["task"] == "strike" else e["time_s"]))
    forced += [goal_s + j * APPROACH_DT_S for j in range(-APPROACH_POINTS + 1, 3)]
    ts = np.r_[np.concatenate(parts_t), tail_t]
    xys = np.vstack([*parts_xy, tail_xy])
    return _piece_plan(uav, ts, xys, t_route0, dt_s, forced)


def _serve_fleet(conn, kwargs: dict) -> None:
    """Child process: run a MockFleet, send its addresses, run until told to stop, send its lag count."""
    from sitl_mock import MockFleet

    with MockFleet(**kwargs) as fleet:
        conn.send(fleet.addresses)
        conn.recv()
        lag = fleet.lag_events
    conn.send(lag)


class _FleetProcess:
    """The mock fleet in its own process. In the GCS's process the fleet's thread shares the GIL,
    so the simulation, telemetry parsing, planning and uploads all ran on one core; at speed-up 20
    with 26 vehicles that core was saturated and an upload of 50 items took 10 s of flight time."""

    def __init__(self, **kwargs) -> None:
        self.kwargs = kwargs
        self.addresses: list[tuple[str, int]] = []
        self.lag_events = 0

    def __enter__(self) -> _FleetProcess:
        ctx = multiprocessing.get_context("spawn")
        self._conn, child = ctx.Pipe()
        self._proc = ctx.Process(target=_serve_fleet, args=(child, self.kwargs), daemon=True)
        self._proc.start()
        if not self._conn.poll(FLEET_START_S):
            self._proc.terminate()
            raise UserError(f"the mock fleet process did not start within {FLEET_START_S} s")
        self.addresses = self._conn.recv()
        return self

    def __exit__(self, *exc: object) -> None:
        try:
            self._conn.send("stop")
            if self._conn.poll(10.0):
                self.lag_events = int(self._conn.recv())
        except (BrokenPipeError, EOFError):
            pass
        self._proc.join(10.0)
        if self._proc.is_alive():
            self._proc.terminate()


def _idle_mission(
    sched, idle: _Idle, leg: Leg, prefix, t_route0: float, dt_s: float, prefix_wp_s
) -> VehiclePlan:
    """The idle mission: the predicted turn up to the leg start (prefix: times, xy; waypoints at
    prefix_wp_s), the rejoin leg, the simulated track from where it rejoins to end_s but for at
    most IDLE_SPAN_S (the next idle mission takes over), then PRE_AWARD_EXTEND_S more at the same
    turn rate (times shifted by the leg's lateness)."""
    uav = sched.uav
    t, xy = sched.track
    late = max(0.0, leg.info["late_s"])
    t_join = float(leg.t[-1]) - late
    pt, pxy = prefix
    parts_t, parts_xy = [pt[:-1], leg.t], [pxy[:-1], leg.xy]
    t_end = max(min(idle.end_s, t_join + IDLE_SPAN_S), t_join)
    if t_end - t_join > 1e-3:
        ts, xys = _slice(t, xy, t_join, t_end)
        parts_t.append(ts[1:] + late)
        parts_xy.append(xys[1:])
    ext_t, ext_xy = _continue_turn(
        t, xy, t_end, uav.speed_mps, uav.speed_mps / uav.r_min_m, PRE_AWARD_EXTEND_S
    )
    ts = np.r_[np.concatenate(parts_t), ext_t + late]
    xys = np.vstack([*parts_xy, ext_xy])
    return _piece_plan(uav, ts, xys, t_route0, dt_s, list(prefix_wp_s) + [float(leg.t[0])])


def _mock_fleet(schedules, origin: Origin, speedup: float) -> _FleetProcess:
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
    return _FleetProcess(vehicles=specs, speedup=speedup, home=origin, rate_hz=rate_hz)


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


# ---- report
def measure_task(track_t: np.ndarray, track_xy: np.ndarray, award: dict, limits, world=None) -> TaskRow:
    """Closest approach of the flown track (scenario time, ENU) to the award's goal point: the strike
    entry point (award["entry_xy"]) or, for an assessment (``world`` needed), the arc start; plus the
    largest radial deviation over the assessment arc."""
    nan = float("nan")
    strike = award["task"] == "strike"
    t_goal = float(award["time_s"])
    if strike:
        goal = np.asarray(award["entry_xy"], dtype=float)
        awarded_heading = (award["angle_deg"] + 180.0) % 360.0
    else:
        p = world.params
        target = next(t for t in world.targets if t.id == award["target"])
        goal = paths.arc_start_pose(target.xy, math.radians(award["angle_deg"]), p.assess_radius_m)[0, :2]
        awarded_heading = (award["angle_deg"] + 90.0) % 360.0
    row = partial(TaskRow, award["uav"], award["sysid"], award["target"], award["task"], t_goal)
    sel = np.abs(track_t - t_goal) <= MEASURE_WINDOW_S
    t, pts = track_t[sel], track_xy[sel]
    if len(t) < 2:
        return row(nan, awarded_heading, nan, nan, limits)
    a, ab = pts[:-1], np.diff(pts, axis=0)
    u = np.clip(((goal - a) * ab).sum(1) / np.maximum((ab**2).sum(1), 1e-12), 0.0, 1.0)
    d = np.linalg.norm(a + u[:, None] * ab - goal, axis=1)
    k = int(np.argmin(d))
    flown_s = float(t[k] + u[k] * (t[k + 1] - t[k]))
    heading = float(np.degrees(np.arctan2(ab[k, 1], ab[k, 0])) % 360.0)
    arc_dev = nan
    if not strike:
        on_arc = (track_t >= t_goal) & (track_t <= t_goal + target.assess_duration_s)
        if on_arc.sum() >= 2:
            r = np.hypot(*(track_xy[on_arc] - np.asarray(target.xy)).T)
            arc_dev = float(np.abs(r - p.assess_radius_m).max())
    return row(flown_s, awarded_heading, heading, float(d[k]), limits, arc_dev)


def format_strike_report(rows: list[TaskRow]) -> str:
    """The report table (strikes and assessments), then the worst errors per task kind."""
    head = ("uav   sysid target task   awarded_s flown_s  dt_s   awarded_deg flown_deg dangle_deg miss_m "
            "arc_dev_m start_diff_m start_dh_deg  ok")  # fmt: skip
    lines = [head]
    for r in rows:
        lines.append(
            f"{r.uav:<5} {r.sysid:>5} {r.target:<6} {r.task:<6} {r.awarded_s:>9.2f} {r.flown_s:>7.2f} "
            f"{r.time_error_s:>+6.2f} {r.awarded_heading_deg:>11.1f} {r.flown_heading_deg:>9.1f} "
            f"{r.angle_error_deg:>+10.1f} {r.miss_m:>6.1f} {r.arc_dev_m:>9.1f} {r.start_diff_m:>12.1f} "
            f"{r.start_dheading_deg:>+12.1f}  {'yes' if r.passed else 'NO'}"
        )
    for task in ("strike", "assess"):
        sel = [r for r in rows if r.task == task]
        if sel:
            dt = np.array([abs(r.time_error_s) for r in sel])
            da = np.array([abs(r.angle_error_deg) for r in sel])
            ok = sum(r.passed for r in sel)
            lines.append(
                f"{task}: {ok}/{len(sel)} within bounds, max |dt| {np.nanmax(dt):.2f} s, "
                f"max |dangle| {np.nanmax(da):.1f} deg"
            )
    return "\n".join(lines)


# ---- the run
async def run_coalition_hil(scenario: Scenario, options: HilOptions) -> HilResult:
    """Simulate, fly the awarded vehicles on mock autopilots, upload each award as a leg planned from
    the vehicle's live state (or, with ``replay_legs``, the simulation's leg)."""
    t_wall = time.monotonic()
    world = load_world(scenario)
    seed = options.seed if options.seed is not None else int(scenario.planner.get("seed", 0))
    result = simulate(world, np.random.default_rng(seed))
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
    schedules = _schedules(world, result, awards, t_start, t_stop, options.waypoint_dt_s, options.offset_m)
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
    fleet = _mock_fleet(schedules, scenario.origin, options.speedup)
    recorder = _TrackRecorder(scenario.origin, True, {s: len(m) - 1 for s, m in missions.items()})
    telemetry = _Telemetry(flying)
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
                t_up = time.monotonic()
                first = await upload_fleet(link, missions, workers=8)
                bad = [s for s, r in first.items() if not r.ok]
                if bad:
                    raise UserError(f"initial mission upload failed for sysid {bad}")
                # seed of the upload estimate: wall time per item at this concurrency
                n_items = sum(len(m) for m in missions.values())
                timing = {"item_wall_s": (time.monotonic() - t_up) * min(8, len(missions)) / n_items,
                          "plan_wall_s": 0.0, "items": 20, "idle_items": 30}  # fmt: skip
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
                    goal = np.broadcast_to(_goal_pose(world, e), q.shape)
                    spare = e["time_s"] - at - paths.shortest_lengths(q, goal, uav.r_min_m) / uav.speed_mps
                    late = np.nonzero(spare < 0.0)[0]
                    return float(at[late[0]] if len(late) else at[-1] + spare[-1])

                def live_leg(sched: _VehicleSchedule, award: _Award, state: LiveState, now: float):
                    """Plan the award's leg from the vehicle's newest reports (see module docstring).
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
                            leg = _onto_sim_leg(world, sched.uav, q0, t0, award.sim_leg, e["t_s"]) or leg
                        pre_t = np.unique(np.r_[np.arange(state.t_s, t0, KEEPER_SAMPLE_S), t0])
                        prefix = (pre_t, state.predict(pre_t)[:, :2])
                        vp = _award_mission(sched, award, leg, prefix, t_route0, options.waypoint_dt_s,
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

                def live_idle(sched: _VehicleSchedule, idle: _Idle, state: LiveState, now: float):
                    """Plan the idle mission from the vehicle's newest reports: back onto the
                    simulated track (``rejoin_leg``), then along it. Runs in a thread."""
                    t_plan = time.monotonic()
                    t0 = now + upload_estimate_s(timing["idle_items"]) + START_AHEAD_S
                    q0 = state.predict([t0])[0]
                    leg = rejoin_leg(world, sched.uav, q0, t0, sched.track, idle.end_s, now)
                    pre_t = np.unique(np.r_[np.arange(state.t_s, t0, KEEPER_SAMPLE_S), t0])
                    prefix = (pre_t, state.predict(pre_t)[:, :2])
                    vp = _idle_mission(sched, idle, leg, prefix, t_route0, options.waypoint_dt_s,
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

                async def upload(kind: str, sched: _VehicleSchedule, payload) -> None:
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
                            vp = _award_mission(
                                sched, payload, leg, None, t_route0, options.waypoint_dt_s, []
                            )
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
                        await CommandClient(link, sysid).mission_start(seq, len(items) - 1)
                        current[sysid] = vp
                        keeper.add(vp)
                        if kind == "award":
                            flown_legs[(e["target"], e["uav"])] = leg
                        entry.update(ok=True, start_seq=seq, items=len(items))
                        if entry.get("covered_s", math.inf) < payload.end_s - 1.0:  # the next idle chunk
                            t_next = entry["covered_s"] - IDLE_LEAD_S
                            due.append(
                                (t_next, (2, t_next), "idle", sched, _Idle(t_next, e, payload.end_s, None))
                            )
                            due.sort(key=lambda d: (d[0], d[1]))
                    except MavlinkError as exc:
                        entry["error"] = str(exc)
                        failures.append(f"{e['uav']}: {kind} upload failed: {exc}")
                    entry["upload_end_s"] = scenario_now()
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
                        _keep(link, recorder, keeper, current, route_t0)
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
    rows = []
    for e in sorted(awards, key=lambda e: (e["task"] != "strike", e["time_s"], e["sysid"])):
        if e["sysid"] not in flown:
            failures.append(f"{e['uav']}: no telemetry")
            continue
        leg = flown_legs.get((e["target"], e["uav"]))
        if leg is None:
            failures.append(f"{e['uav']}: its {e['target']} {e['task']} award was not uploaded")
            continue
        t, positions = flown[e["sysid"]]
        row = measure_task(t, positions[:, :2], e, limits, world)
        t0 = float(leg.t[0])
        sim_pose, flown_pose = _pose_at(*sim_tracks[e["uav"]], t0), _pose_at(t, positions[:, :2], t0)
        row.start_diff_m = float(np.hypot(*(flown_pose[:2] - sim_pose[:2])))
        row.start_dheading_deg = float((math.degrees(flown_pose[2] - sim_pose[2]) + 180.0) % 360.0 - 180.0)
        rows.append(row)
    for u in uploads:  # how far the live prediction of the leg start was from the flown pose
        if "live_pose" in u and u["sysid"] in flown:
            t, positions = flown[u["sysid"]]
            miss = _pose_at(t, positions[:, :2], u["t0_s"])[:2] - np.asarray(u["live_pose"][:2])
            u["prediction_error_m"] = round(float(np.hypot(*miss)), 2)
    return HilResult(
        rows, uploads, mcap_path, t_start, time.monotonic() - t_wall, lag, failures, flown, flown_legs
    )


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
