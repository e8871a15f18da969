"""Live vehicle state from telemetry, and the legs planned from it.

When an award's mission is about to be uploaded, the vehicle's leg is planned from its own newest
GLOBAL_POSITION_INT reports (``Telemetry``), not from the simulated state: position, course and
ground speed of the newest report, turn rate fitted over the last ``FIT_S`` of course
(``live_state``). The caller propagates that turn to the leg start t0 (``LiveState.predict``).
From that pose the leg goes to the award's stand-off entry pose (strike) or assessment-arc start
pose (assess), arriving at the awarded time at the awarded angle (``plan_live_leg``). It uses the
coalition path functions as sim.py's ``_replan`` does: ``paths.min_route`` for safe-point threat
avoidance (threats known at the award), ``paths.timed_route`` for radius stretching with detour
and loiter fallbacks, ``paths.sample_segments``, and for an assessment ``paths.arc_leg`` after the
transit.

Choices: a live leg short of time is planned faster, up to the caller's speed factor x cruise;
one that cannot arrive on time even then is flown at its minimum length and reported late
(``timed_leg``). An assessor's transit is timed to reach the arc start at the awarded time (the
simulation instead flies to the arc start and waits on the circle, and its track jumps there).
After an award the vehicle returns onto the simulated track (``rejoin_leg``), so that its next
award starts from about the simulated state. A strike whose live leg finds no threat-clear path of
the right length falls back to a leg onto the simulation's own strike leg (``onto_sim_leg``).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, replace

import numpy as np

from gcs_planner.core.geo import Origin, geodetic_to_enu
from gcs_planner.flight.coalition.tracks import pose_at
from gcs_planner.flight.l1_guidance import TurnGain
from gcs_planner.flight.ops import FrameClock, boot_clock
from gcs_planner.geometry.dubins import DubinsPath
from gcs_planner.planning.coalition import paths
from gcs_planner.planning.coalition.track import Leg
from gcs_planner.wire.units import reports_no_fix

__all__ = [
    "FIT_S",
    "LEG_SPEED_FACTOR",
    "SPEED_TRIES",
    "RUN_IN_S",
    "TURN_FACTOR",
    "LiveState",
    "Telemetry",
    "goal_pose",
    "live_state",
    "onto_sim_leg",
    "plan_live_leg",
    "rejoin_leg",
    "timed_leg",
]

FIT_S = 2.0  # turn rate fitted over this much of the newest course reports [s]
SPEED_TRIES = (0.9, 1.1, 0.8, 1.2)  # other speeds / cruise for a live leg that cannot clear the threats
LEG_SPEED_FACTOR = 1.2  # a live leg short of time may be planned up to this x cruise (mock top: 1.3)
REJOIN_MIN_S = 10.0  # an idle mission rejoins the simulated track at least this long after its start [s]
RUN_IN_S = 6.0  # straight flown into a connected vehicle's goal pose (ArduPlane's L1 settles on it) [s]
TURN_FACTOR = 1.5  # a connected plane's legs turn at this x r_min (ArduPlane's L1 flies tight arcs wide)


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


class Telemetry:
    """The newest GLOBAL_POSITION_INT reports of each vehicle, timed by ``clock`` (flight.ops), and
    each vehicle's turn gain learnt from them and its ATTITUDE reports (l1_guidance.TurnGain)."""

    def __init__(self, sysids, clock: FrameClock = boot_clock, keep: int = 64) -> None:
        self.rows = {s: deque(maxlen=keep) for s in sysids}
        self.turn_gains = {s: TurnGain() for s in sysids}
        self.clock = clock

    def on_frame(self, msg, raw: bytes, t_s: float) -> None:
        kind, gain = msg.get_type(), self.turn_gains.get(msg.get_srcSystem())
        if gain is None:
            return
        if kind == "ATTITUDE":
            gain.attitude(msg.roll)
        elif kind == "GLOBAL_POSITION_INT" and not reports_no_fix(msg):
            east, north = msg.vy / 100.0, msg.vx / 100.0
            row = (self.clock(msg, t_s), msg.lat / 1e7, msg.lon / 1e7, east, north)
            self.rows[msg.get_srcSystem()].append(row)
            gain.velocity(msg.time_boot_ms / 1000.0, east, north)


def goal_pose(world, award: dict) -> np.ndarray:
    """The award's goal pose: strike stand-off entry pose or assessment arc start pose."""
    p = world.params
    target = next(t for t in world.targets if t.id == award["target"])
    angle = math.radians(award["angle_deg"])
    if award["task"] == "strike":
        return paths.entry_poses(target.xy, [angle], p.standoff_m)[0]
    return paths.arc_start_pose(target.xy, angle, p.assess_radius_m)[0]


def timed_leg(
    world,
    uav,
    q0,
    t0_s: float,
    goal,
    t_goal_s: float,
    known,
    kind: str,
    max_speed_factor=1.0,
    run_in_m: float = 0.0,
) -> Leg:
    """A threat-avoiding Dubins leg from pose q0 at t0_s to pose goal at t_goal_s (poses: x, y,
    heading [rad]): at cruise when there is time; else the minimum route, flown up to
    max_speed_factor x cruise (info["speed_mps"]); if that is still too slow, late (info["late_s"]
    > 0). When the timing fallbacks find no threat-clear path of the length the speed asks for,
    the other speeds of SPEED_TRIES (up to max_speed_factor) are tried. With run_in_m the leg
    ends with a straight of that length into the goal pose."""
    p = world.params
    goal = np.asarray(goal, dtype=float)
    run_in = _straight_into(goal, run_in_m, uav.r_min_m)
    route_goal = run_in[0].start if run_in else goal
    route = paths.min_route(q0, route_goal, uav.r_min_m, known, p.kappa, p.sample_ds_m)
    span_s = max(t_goal_s - t0_s, 1e-3)
    need_m = route.length_m + run_in_m
    speed = float(np.clip(need_m / span_s, uav.speed_mps, max_speed_factor * uav.speed_mps))
    others = [f * uav.speed_mps for f in SPEED_TRIES if f * uav.speed_mps * span_s >= need_m]
    run_in_clear = not run_in or bool(paths.chains_clear([run_in], known, p.sample_ds_m)[0])
    first = None
    for v in [speed, *(v for v in others if v <= max_speed_factor * uav.speed_mps and v != speed)]:
        timed_m = max(route.length_m, v * span_s - run_in_m)
        segs, clear = paths.timed_route(route, timed_m, known, p.sample_ds_m)
        segs = [*segs, *run_in]
        length = sum(seg.length for seg in segs)
        attempt = (segs, bool(clear and route.clear and run_in_clear), v)
        first = first or attempt
        if attempt[1] and abs(length - v * span_s) < 0.05 * v:
            break
    else:
        attempt = first
    segs, clear, speed = attempt
    leg = paths.sample_segments(segs, t0_s, speed, p.sample_ds_m, kind, {"clear": clear, "speed_mps": speed})
    leg.info["late_s"] = float(leg.t[-1] - t_goal_s)
    return leg


def _straight_into(goal: np.ndarray, length_m: float, r_m: float) -> list:
    """[the straight Dubins path of length_m ending at pose goal], or [] for no length."""
    if length_m <= 0.0:
        return []
    back = goal - length_m * np.array([math.cos(goal[2]), math.sin(goal[2]), 0.0])
    return [DubinsPath(tuple(map(float, back)), "LSL", (0.0, length_m, 0.0), (r_m, math.inf, r_m))]


def plan_live_leg(
    world,
    award: dict,
    q0: np.ndarray,
    t0_s: float,
    max_speed_factor: float = 1.0,
    known=None,
    run_in_s: float = 0.0,
    turn_factor: float = 1.0,
) -> Leg:
    """The award's leg from pose q0 (x, y, heading [rad]) at t0_s (see ``timed_leg``): to the strike
    entry pose, or to the assessment arc start followed by the assessment arc, arriving at
    award["time_s"], around the known threats (default: the scenario's, known at the award),
    its last run_in_s x cruise metres straight into that pose, its turns at turn_factor x r_min
    (each tried shorter, then at r_min, if that leg would be late or not clear; info["run_in_s"],
    info["turn_factor"])."""
    p = world.params
    uav = next(u for u in world.uavs if u.id == award["uav"])
    target = next(t for t in world.targets if t.id == award["target"])
    if known is None:
        known = [th for th in world.threats if th.appear_s <= award["t_s"]]
    strike = award["task"] == "strike"
    kind = "strike" if strike else "transit"
    runs_in = dict.fromkeys((run_in_s, run_in_s / 2))
    tries = [(f, r) for f in dict.fromkeys((turn_factor, 1.0)) for r in runs_in]
    for factor, run_in in dict.fromkeys([*tries, (1.0, 0.0)]):  # gentler first; as the simulation's when late
        wide = replace(uav, r_min_m=factor * uav.r_min_m)
        leg = timed_leg(world, wide, q0, t0_s, goal_pose(world, award), float(award["time_s"]), known, kind,
                        max_speed_factor, run_in * uav.speed_mps)  # fmt: skip
        if leg.info["clear"] and leg.info["late_s"] < 0.05:
            break
    leg.info.update(run_in_s=run_in, turn_factor=factor)
    leg.info["target"] = target.id
    if strike:
        return leg
    arc = paths.arc_leg(target.xy, p.assess_radius_m, math.radians(award["angle_deg"]), float(leg.t[-1]),
                        target.assess_duration_s, uav.speed_mps, p.sample_ds_m, "assess")  # fmt: skip
    return Leg(np.r_[leg.t, arc.t[1:]], np.r_[leg.xy, arc.xy[1:]], np.r_[leg.heading, arc.heading[1:]],
               "assess", {**leg.info, "arc_t0_s": float(arc.t[0])})  # fmt: skip


def rejoin_leg(world, uav, q0, t0_s: float, track, end_s: float, known) -> Leg:
    """A timed leg from pose q0 at t0_s back onto the simulated track (t, xy) at the earliest time
    t_j >= t0_s + REJOIN_MIN_S (and <= end_s) whose point the shortest path reaches at 0.9 x
    cruise, around the known threats: after a strike or assessment the vehicle returns to where
    the simulation has it, so that its next award starts from about the simulated state."""
    t, xy = track
    grid = np.arange(t0_s + REJOIN_MIN_S, max(end_s, t0_s + REJOIN_MIN_S + 1.0), 1.0)
    goals = np.array([pose_at(t, xy, tj) for tj in grid])
    lengths = paths.shortest_lengths(np.broadcast_to(q0, goals.shape), goals, uav.r_min_m)
    ok = np.nonzero(lengths <= 0.9 * uav.speed_mps * (grid - t0_s))[0]
    j = int(ok[0]) if len(ok) else len(grid) - 1
    return timed_leg(world, uav, q0, t0_s, goals[j], float(grid[j]), known, "transit")


def onto_sim_leg(world, uav, q0, t0_s: float, sim_leg: Leg, known) -> Leg | None:
    """Fallback for a strike whose live leg finds no threat-clear path of the right length: a
    timed leg onto the simulation's own strike leg (``rejoin_leg``), then the rest of that leg
    (which the simulation planned clear). None when that is not clear and on time either."""
    rejoin = rejoin_leg(world, uav, q0, t0_s, (sim_leg.t, sim_leg.xy), float(sim_leg.t[-1]), known)
    if not rejoin.info["clear"] or abs(rejoin.info["late_s"]) >= 0.05 or rejoin.t[-1] >= sim_leg.t[-1]:
        return None
    rest = sim_leg.t > rejoin.t[-1] + 1e-6
    info = {**sim_leg.info, **rejoin.info, "onto_sim_leg": True, "late_s": 0.0}
    return Leg(np.r_[rejoin.t, sim_leg.t[rest]], np.r_[rejoin.xy, sim_leg.xy[rest]],
               np.r_[rejoin.heading, sim_leg.heading[rest]], "strike", info)  # fmt: skip
