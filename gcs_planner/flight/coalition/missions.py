"""Simulated tracks and planned legs turned into the missions (VehiclePlans) the vehicles fly.

Each awarded UAV gets a schedule (``build_schedules``): its first mission is a straight
``LEAD_IN_S`` lead-in to its simulated position at the window start, then its simulated pre-award
track (idle loiter, recon) up to its simulated leg start, then ``PRE_AWARD_EXTEND_S`` more at the
same turn rate (the loiter the bids predicted, flown until the award's mission starts). An award
mission (``award_mission``) is the predicted turn up to the leg start, the leg, then
``AFTER_GOAL_S`` of the simulated track. At the leg end an "idle" mission (``idle_mission``: the
rejoin leg, then the simulated track up to the next award or the window end, at most
``IDLE_SPAN_S`` per upload) follows, so the urgent award missions stay short (19-45 items).

Choices: waypoints are placed every ``TURN_STEP_DEG`` of turn and at least every ``dt_s``
(``waypoint_index``): fewer items on straights, so uploads land sooner; goal poses get waypoints
every ``APPROACH_DT_S`` on the last 1.5 s before them and 1 s after. Isolated far samples are
removed from the simulated tracks before they become missions (``tracks.drop_spikes``). The
ScheduleKeeper gets the path every ``KEEPER_SAMPLE_S`` so that its 60-sample look-ahead stays
shorter than a loiter lap.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import partial

import numpy as np

from gcs_planner.flight.coalition.live_legs import LEG_SPEED_FACTOR, SPEED_TRIES
from gcs_planner.flight.coalition.tracks import continue_turn, drop_spikes, slice_track
from gcs_planner.model.plan import VehiclePlan
from gcs_planner.planning.coalition.track import Leg

__all__ = [
    "IDLE_SPAN_S",
    "KEEPER_SAMPLE_S",
    "LEAD_IN_S",
    "Award",
    "Idle",
    "VehicleSchedule",
    "award_mission",
    "build_schedules",
    "first_mission",
    "idle_mission",
]

AFTER_GOAL_S = 2.0  # simulated track flown after an award leg; the idle upload follows [s]
PRE_AWARD_EXTEND_S = 30.0  # continuation of a pre-award mission at its last turn rate [s]
LEAD_IN_S = 20.0  # straight lead-in to the window start, flown from the take-off point [s]
IDLE_SPAN_S = 40.0  # an idle mission covers at most this much simulated track; the next one follows [s]
TURN_STEP_DEG = 30.0  # a waypoint every this much turn of the planned path
MIN_GAP_M = 7.5  # a turn or time waypoint this close to the one before is left out (half the acceptance)
ACCEPTANCE_RADIUS_M = 15.0  # a fixed wing also counts a waypoint once past it
APPROACH_DT_S, APPROACH_POINTS = 0.5, 4  # waypoints on the last 1.5 s before a goal pose (and 1 s after)
KEEPER_SAMPLE_S = 0.25  # planned-path sampling given to the ScheduleKeeper [s]


@dataclass
class Award:
    """One award to fly: the simulated leg and the simulated track after it, up to ``end_s``."""

    event: dict
    sim_leg: Leg
    end_s: float  # the next award's leg start or the window end


@dataclass
class Idle:
    """The flight after an award's leg: the simulated track from t_s (the leg end) to end_s."""

    t_s: float
    event: dict  # the award whose leg ends at t_s
    end_s: float
    mission: VehiclePlan | None  # the simulated track itself (replay_legs)


@dataclass
class VehicleSchedule:
    uav: object
    initial: VehiclePlan
    track: tuple[np.ndarray, np.ndarray]  # simulated t [s], xy [m] over the window
    awards: list[Award]
    idles: list[Idle]


def _waypoint_index(t: np.ndarray, xy: np.ndarray, dt_s: float, forced) -> np.ndarray:
    """Indices of the waypoints: every TURN_STEP_DEG of turn, at least every dt_s, the samples
    nearest the forced times, and the last sample; a turn or time waypoint closer than
    MIN_GAP_M to the waypoint before is left out (a leg of a few metres has no direction to
    steer along, and a plane reaches both ends at once)."""
    h = np.unwrap(np.arctan2(*np.diff(xy, axis=0).T[::-1])) if len(t) > 1 else np.zeros(1)
    turn = np.r_[0.0, np.cumsum(np.abs(np.diff(h)))]
    by_turn = np.searchsorted(turn, np.arange(0.0, turn[-1], math.radians(TURN_STEP_DEG)), side="left")
    by_time = np.searchsorted(t, np.arange(t[0], t[-1], dt_s), side="right") - 1
    forced_idx = {int(np.argmin(np.abs(t - f))) for f in forced if t[0] <= f <= t[-1]} | {len(t) - 1}
    keep: list[int] = []
    for i in np.unique(np.clip(np.r_[by_turn, by_time, sorted(forced_idx)], 0, len(t) - 1)).astype(int):
        if keep and np.hypot(*(xy[i] - xy[keep[-1]])) < MIN_GAP_M:
            if i not in forced_idx:
                continue
            if keep[-1] not in forced_idx and len(keep) > 1:
                keep.pop()
        keep.append(int(i))
    return np.asarray(keep, dtype=int)


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


def _track_piece(uav, t, xy, t0: float, dt_s: float, a: float, b: float, forced=(), extend_s: float = 0.0):
    """Mission over the simulated track in [a, b] (then the turn continued for extend_s)."""
    ts, xys = slice_track(t, xy, a, b)
    if extend_s > 0:
        ext_t, ext_xy = continue_turn(t, xy, b, uav.speed_mps, uav.speed_mps / uav.r_min_m, extend_s)
        ts, xys = np.r_[ts, ext_t], np.vstack([xys, ext_xy])
    return _piece_plan(uav, ts, xys, t0, dt_s, forced)


def first_mission(uav, track, t_start: float, t_end: float, dt_s: float, offset=(0.0, 0.0)) -> VehiclePlan:
    """A straight LEAD_IN_S lead-in to the track's position at t_start, then the track (t, xy) up to
    t_end and PRE_AWARD_EXTEND_S more at its last turn rate, shifted by offset (east, north) [m]."""
    t0 = t_start - LEAD_IN_S
    piece = _track_piece(uav, *track, t0, dt_s, t_start, t_end, extend_s=PRE_AWARD_EXTEND_S)
    h0 = np.arctan2(*(piece.path[1, :2] - piece.path[0, :2])[::-1])
    lead_in = piece.path[0, :2] - LEAD_IN_S * uav.speed_mps * np.array([np.cos(h0), np.sin(h0)])
    ts = np.r_[t0, piece.path_times_s + t0]
    xys = np.vstack([lead_in, piece.path[:, :2]]) + np.asarray(offset)
    return _piece_plan(uav, ts, xys, t0, dt_s, [])


def build_schedules(world, result, awards, t_start, t_stop, dt_s, offsets) -> list[VehicleSchedule]:
    """Each awarded UAV's missions: the initial one, its awards (flown from the award time: the leg
    plus AFTER_GOAL_S of the simulated track after it) and, where the simulation flies on before
    the next award or the window end, an "idle" one uploaded at the leg end (its idle loiter /
    station change), so the urgent award missions stay short. offsets (UAV id: (east, north) [m])
    move a vehicle's initial mission."""
    by_uav: dict[str, list[dict]] = {}
    for e in awards:
        by_uav.setdefault(e["uav"], []).append(e)
    out = []
    for uav in sorted((u for u in world.uavs if u.id in by_uav), key=lambda u: u.sysid):
        t, xy = drop_spikes(
            *result.tracks[uav.index].history(t_stop + 2 * PRE_AWARD_EXTEND_S)[:2], uav.speed_mps
        )
        piece = partial(_track_piece, uav, t, xy, t_start - LEAD_IN_S, dt_s)
        mine = sorted(by_uav[uav.id], key=lambda e: e["t_s"])
        legs = [result.award_legs[(e["target"], uav.id)] for e in mine]
        offset = offsets.get(uav.id, (0.0, 0.0))
        initial = first_mission(uav, (t, xy), t_start, float(legs[0].t[0]), dt_s, offset)
        flown, idles = [], []
        for k, (e, leg) in enumerate(zip(mine, legs)):
            end = float(legs[k + 1].t[0]) if k + 1 < len(mine) else t_stop
            leg_end = float(leg.t[-1])
            flown.append(Award(e, leg, end))
            if end - leg_end > AFTER_GOAL_S:
                idles.append(Idle(leg_end, e, end, piece(leg_end, end, extend_s=PRE_AWARD_EXTEND_S)))
        out.append(VehicleSchedule(uav, initial, (t, xy), flown, idles))
    return out


def _award_track(sched: VehicleSchedule, award: Award, leg: Leg):
    """Times and positions of an award mission after its leg: AFTER_GOAL_S of the simulated track
    from the simulated leg's end (where the live leg also ends), shifted by a live leg's lateness."""
    t, xy = sched.track
    sim_end = float(award.sim_leg.t[-1])
    stop = min(award.end_s, sim_end + AFTER_GOAL_S)
    if stop - sim_end < 1e-3:
        return np.zeros(0), np.zeros((0, 2))
    ts, xys = slice_track(t, xy, sim_end, stop)
    return ts[1:] + max(0.0, float(leg.t[-1]) - sim_end), xys[1:]


def award_mission(
    sched: VehicleSchedule, award: Award, leg: Leg, prefix, t_route0: float, dt_s: float, prefix_wp_s
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


def idle_mission(
    sched: VehicleSchedule, idle: Idle, leg: Leg, prefix, t_route0: float, dt_s: float, prefix_wp_s
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
        ts, xys = slice_track(t, xy, t_join, t_end)
        parts_t.append(ts[1:] + late)
        parts_xy.append(xys[1:])
    ext_t, ext_xy = continue_turn(
        t, xy, t_end, uav.speed_mps, uav.speed_mps / uav.r_min_m, PRE_AWARD_EXTEND_S
    )
    ts = np.r_[np.concatenate(parts_t), ext_t + late]
    xys = np.vstack([*parts_xy, ext_xy])
    return _piece_plan(uav, ts, xys, t_route0, dt_s, list(prefix_wp_s) + [float(leg.t[0])])
