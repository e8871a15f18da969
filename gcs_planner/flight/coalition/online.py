"""The online contract net (seed 003, section 5.4): the coalition simulation run on the live clock.

``OnlineContractNet`` is the event simulation (planning.coalition.sim) with its answers about the
vehicles taken from telemetry once the flight is live (``go_live``): every pose it asks for (the
bus's link ranges, the bids' predicted pose at t_e^s and their stay-in-range check, the leader's
own candidacy, station and re-plan starts) is the vehicle's newest report propagated at its
fitted turn (``LiveState.predict``). The run (online_run.py) calls ``advance(now)`` with the
scenario clock of the telemetry; every leg the engine starts for a flying vehicle becomes a
mission uploaded in flight. Before ``go_live`` (the flight's lead-in) it is the simulation itself,
so both start from the same state.

What the telemetry decides, beyond the poses:
- a recon task ends when the vehicle's own reports have passed every point of its recon arc
  (within ``RECON_TOL_M``; ``arc_covered``), checked from the arc's planned end every
  ``RECHECK_S``; only then are the target's needs revealed and the tender sent;
- a vehicle that stops reporting is lost (``vehicle_lost``, called by the run).

Choices (the paper does not model loss):
- a lost vehicle's unfinished task (awarded, not yet struck or assessed) is re-tendered on its
  own: a tender for that one task (same target, same angle) by the coalition's leader, or, when
  the leader is lost or busy, by the nearest idle vehicle to the target. The target's other
  tasks keep their awards; its J stays the first coalition's. A lost recon vehicle's target is
  given to the nearest idle recon vehicle. A lost vehicle never bids and is never a candidate.
- a member whose live leg cannot arrive within the time bound (planned at its upload, from where
  it really is) is released (``release``): its task is re-tendered as a lost vehicle's, and it
  loiters where it is, then keeps station.
- a formation that fails is re-tendered after ``retender_s``, as in the simulation (the paper).
- an award reaches a vehicle as a mission upload, not a radio message: the members start
  ``award_lag_s`` (the run's measured upload time for a coalition's missions) after t_e^s, from
  their poses predicted then, and the awarded times follow from those.
- a re-tendered task goes to a vehicle that had no award for that target (so not back to the
  member released from it); a member whose timed leg cannot clear the threats leaves every task
  of that kind, not only the one it was given.
- with connected vehicles (real planes, SITL), every member's leg is given ``approach_s`` (the
  run's run-in, live_legs.RUN_IN_S) on top of its shortest route, so that the awarded times leave
  room for the run-in and wide turns its live leg flies first. Planning the turns wide instead
  (r_min x TURN_FACTOR in bids and formations) was tried: near the goal a wide Dubins path is
  often a loop longer, and T1's strikes moved from 100.8 s to 175-233 s.
- pop-up threats come from the scenario's timeline or ``inject_threat`` while running; as in the
  simulation, every active leg that crosses one is re-planned to the same goal and time.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace
from typing import Protocol

import numpy as np

from gcs_planner.flight.coalition.live_legs import LiveState
from gcs_planner.planning.coalition.contract_net import Award
from gcs_planner.planning.coalition.model import Target, Threat, World
from gcs_planner.planning.coalition.sim import IDLE, LEADER, RECON, CoalitionSim, lookalikes
from gcs_planner.planning.coalition.track import Leg

__all__ = ["LOST", "LiveFleet", "OnlineContractNet", "arc_covered"]

LOST = "lost"
RECON_TOL_M = 60.0  # a recon arc point counts as covered once a report came this close [m]
RECHECK_S = 0.5  # an uncovered recon arc is checked again this often [s]
ARC_POINTS = 12  # recon arc points that must all be covered


class LiveFleet(Protocol):
    """What the engine needs from the flight: live state and flown track, by UAV index."""

    def state(self, i: int) -> LiveState | None: ...

    def flown_since(self, i: int, t_s: float) -> np.ndarray: ...  # (M, 2) ENU [m] reported since t_s


def arc_covered(flown_xy: np.ndarray, centre, radius_m: float, angle0_rad: float, span_rad: float) -> bool:
    """True when every one of ARC_POINTS points of the CCW arc (centre, radius, from angle0 over
    span) has a flown point within RECON_TOL_M."""
    if len(flown_xy) == 0:
        return False
    a = angle0_rad + np.linspace(0.0, span_rad, ARC_POINTS)
    pts = np.asarray(centre) + radius_m * np.column_stack([np.cos(a), np.sin(a)])
    d = np.hypot(pts[:, None, 0] - flown_xy[None, :, 0], pts[:, None, 1] - flown_xy[None, :, 1])
    return bool(np.all(d.min(axis=1) <= RECON_TOL_M))


class OnlineContractNet(CoalitionSim):
    """The contract net driven by live vehicle state (module docstring)."""

    def __init__(self, world: World, rng: np.random.Generator, fleet: LiveFleet | None = None) -> None:
        super().__init__(world, rng)
        self.fleet = fleet
        self.live_from_s = math.inf
        self.lost: set[int] = set()
        self.tasks: dict[int, Award] = {}  # the award each vehicle is executing
        self.released: list[Award] = []  # awards handed on because the vehicle could not make them
        self.parts: list[Target] = []  # single tasks re-tendered after a loss
        self.recon_of: dict[int, Target] = {}
        self.awarded: dict[str, set[int]] = {}  # target id -> the vehicles awarded one of its tasks
        self.award_lag_s = 0.0  # set by the run: the time an award takes to reach the vehicle [s]
        self._live_mark = 0
        self.live_cpu_s: list[float] = []  # CPU time of every formation since going live [s]
        self._states: dict[int, LiveState | None] = {}

    # ---- the live clock
    def go_live(self, t_s: float) -> None:
        """From t_s on, poses come from the fleet's telemetry."""
        self.live_from_s = t_s
        self._live_mark = len(self.compute_s)

    def advance(self, t_s: float) -> None:
        self._states.clear()  # one live state per vehicle per step
        super().advance(t_s)

    @property
    def live_compute_s(self) -> list[float]:
        """Wall time of every formation (tender close to awards) since going live [s]."""
        return self.compute_s[self._live_mark :]

    def is_live(self, i: int) -> bool:
        return self._live(i) is not None

    def _live(self, i: int) -> LiveState | None:
        if self.fleet is None or self.now < self.live_from_s or i in self.lost:
            return None
        if i not in self._states:
            self._states[i] = self.fleet.state(i)
        return self._states[i]

    def pose(self, i: int, t_s) -> np.ndarray:
        state = self._live(i)
        return state.predict(t_s) if state is not None else super().pose(i, t_s)

    def inject_threat(self, threat: Threat) -> None:
        """A pop-up threat known from max(now, its appear_s) on (as a timeline threat)."""
        self.at(max(self.now, threat.appear_s), "threat_appear", threat=threat)

    # ---- recon ends on the vehicle's own coverage
    def _on_target_appear(self, target: Target) -> None:
        before = {i for i, s in enumerate(self.st) if s.state == RECON}
        super()._on_target_appear(target)
        for i, s in enumerate(self.st):
            if s.state == RECON and i not in before:
                self.recon_of[i] = target

    def _on_recon_done(self, uav: int, target: Target) -> None:
        if uav in self.lost:
            return
        if self.is_live(uav) and not self._recon_covered(uav, target):
            self.at(self.now + RECHECK_S, "recon_done", uav=uav, target=target)
            return
        self.recon_of.pop(uav, None)
        super()._on_recon_done(uav, target)

    def _recon_covered(self, uav: int, target: Target) -> bool:
        u, r = self.uavs[uav], self.p.detect_radius_m
        span = u.speed_mps * target.recon_s / r
        flown = self.fleet.flown_since(uav, self.now - target.recon_s - 60.0)
        return arc_covered(flown, target.xy, r, target.recon_angle_rad, span)

    # ---- loss
    def vehicle_lost(self, i: int) -> None:
        """Vehicle i stopped reporting: it leaves the swarm; its recon or unfinished task is handed on."""
        if i in self.lost:
            return
        s = self.st[i]
        was, s.state = s.state, LOST
        self.lost.add(i)
        self.log("vehicle_lost", uav=self.uavs[i].id, state=was)
        if was == RECON and i in self.recon_of:
            self._on_target_appear(replace(self.recon_of.pop(i), recon_uav=None))
        award = self.tasks.pop(i, None)
        if award is not None:
            self._retender(award)

    def release(self, i: int, target_id: str) -> bool:
        """Vehicle i cannot make its award for target_id from where it really is (its live leg would
        be late, or early where no path of the right length is found): the task is re-tendered as
        a lost one's, and the vehicle, idle again, loiters
        where it is (then keeps station). False when it holds no such award."""
        award = self.tasks.get(i)
        if award is None or award.target_id != target_id or i in self.lost:
            return False
        del self.tasks[i]
        self.released.append(award)
        self.log("award_released", uav=self.uavs[i].id, target=target_id, task=award.task,
                 reason="its live leg cannot arrive on time")  # fmt: skip
        u, s = self.uavs[i], self.st[i]
        q = self.pose(i, [self.now, self.now + 1.0])
        hold = Leg(np.array([self.now, self.now + 1.0]), q[:, :2], q[:, 2], "transit", {})
        s.track.start_leg(hold, self._clear_loiter(*q[1], self.now + 1.0, u))
        s.state = IDLE
        self._retender(award)
        self._station(i)
        return True

    def _retender(self, award: Award) -> None:
        target = next(t for t in self.w.targets if t.id == award.target_id)
        strike = award.task == "strike"
        part = replace(
            target,
            strike_angles_rad=(award.angle_rad,) if strike else (),
            assess_angles_rad=() if strike else (award.angle_rad,),
        )
        self.parts.append(part)
        leader = self._new_leader(award.leader, target)
        angle_deg = round(math.degrees(award.angle_rad) % 360, 3)
        self.log("task_retendered", uav=self.uavs[award.uav].id, target=target.id, task=award.task,
                 angle_deg=angle_deg, leader=self.uavs[leader].id)  # fmt: skip
        self.at(self.now, "retender", uav=leader, target=part)

    def _new_leader(self, leader: int, target: Target) -> int:
        """The coalition's leader if it can tender now, else the nearest idle vehicle to the target."""
        if leader not in self.lost and self.st[leader].state in (IDLE, LEADER):
            return leader
        idle = [i for i, s in enumerate(self.st) if s.state == IDLE]
        if not idle:
            return leader
        d = [math.dist(self.position(i, self.now), target.xy) for i in idle]
        return idle[int(np.argmin(d))]

    # ---- formation: the awarded times allow for the award's upload
    def _on_close(self, key: int) -> None:
        """As the simulation's; in flight the CPU time of the formation is kept too (its wall time
        includes waits for the GIL held by the run's planning threads)."""
        t_cpu = time.thread_time()
        super()._on_close(key)
        if self.now >= self.live_from_s:
            self.live_cpu_s.append(time.thread_time() - t_cpu)

    def _candidates(self, tender):
        """As the simulation's, less the vehicles that already had an award for the target: a
        released member re-bids for the task it could not make, and a vehicle holds one award per
        target (the run and its report key awards by target and vehicle)."""
        had = self.awarded.get(tender.target.id, set())
        columns = super()._candidates(tender)
        keep = [k for k, i in enumerate(columns[0]) if i not in had]
        return tuple([column[k] for k in keep] for column in columns)

    def _formation(self, tender, cands, poses, munitions, assess, rleft):
        """As the simulation's, with the members starting ``award_lag_s`` after t_e^s from their
        poses predicted then: in flight an award is a mission upload, which takes that long for a
        whole coalition, and a member that must start at t_e^s would arrive late."""
        t_start = tender.t_es_s + self.award_lag_s
        if self.award_lag_s > 0.0:
            poses = np.array([self.pose(i, [t_start])[0] for i in cands])
        f = super()._formation(tender, cands, poses, munitions, assess, rleft)
        f.prob.t_start_s = t_start
        return f

    # ---- execution of awards: lost vehicles do nothing, their awards are handed on
    def _on_award_rx(self, award: Award, leg: Leg, k: int) -> None:
        if award.uav in self.lost:
            self._retender(award)
            return
        super()._on_award_rx(award, leg, k)
        self.tasks[award.uav] = award

    def _exclude(self, tender, f, base: np.ndarray, sol, bad: list[int]) -> None:
        """As the simulation's, but the member and its lookalikes leave every task of that kind:
        the simulation flies a leg that cannot clear as it is, but in flight the leg is planned
        around the threats from where the vehicle is, arrives late and is released."""
        super()._exclude(tender, f, base, sol, bad)
        for k in bad if self.now >= self.live_from_s else ():
            x = sol.assign[k]
            base[np.ix_([x, *lookalikes(f.poses, x, f.rmin[x])], f.kind == f.kind[k])] = np.inf

    def _award(self, tender, f, legs, compute_s: float) -> None:
        out = self.outcomes[tender.target.id]
        before = (out.pending, out.J, out.parts, out.members)
        formed = len(self.events)
        super()._award(tender, f, legs, compute_s)
        self.awarded.setdefault(tender.target.id, set()).update(int(f.cands[x]) for x in f.sol.assign)
        if any(tender.target is part for part in self.parts):  # a replacement: the task stays pending
            out.pending, out.J, out.parts, out.members = *before[:3], before[3] + out.members
            self.events[formed]["retender"] = True

    def _standing(self, uav: int, award: Award) -> bool:
        """Is this award still the vehicle's to fly (not lost, not released)?"""
        return uav not in self.lost and not any(award is r for r in self.released)

    def _on_strike(self, uav: int, award: Award) -> None:
        if self._standing(uav, award):
            super()._on_strike(uav, award)

    def _on_assess_start(self, uav: int, award: Award) -> None:
        if self._standing(uav, award):
            super()._on_assess_start(uav, award)

    def _on_task_done(self, uav: int, award: Award) -> None:
        if self._standing(uav, award):
            super()._on_task_done(uav, award)

    def _task_done(self, uav: int, award: Award) -> None:
        self.tasks.pop(uav, None)
        super()._task_done(uav, award)

    def _replan(self, i: int, leg: Leg) -> None:
        if i not in self.lost:
            super()._replan(i, leg)
