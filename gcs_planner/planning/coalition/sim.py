"""Event-driven swarm simulation of online coalition planning (seed 003, sections 3-5).

Events (a time-ordered heap): target appears -> a recon UAV flies to the recon arc (eq. 16) ->
recon done, needs revealed -> that UAV leads: tender to one-hop neighbours -> bids -> bid book
closes -> formation (ACO / polynomial / global) and timed paths -> awards -> members fly, strike
(munition consumed) or assess -> idle again. A failed formation (needs not covered) keeps the
leader monitoring and re-tenders after ``retender_s``. Pop-up threats become known to the whole
swarm when they appear (choice: the paper detects them within C^r but does not say how the news
spreads); every executing leg that now crosses one is re-planned to the same goal and time.
Idle UAVs keep station (choice: the paper's swarm gathers near the targets, U1 has 20 neighbours at
T1): an idle UAV flies to a loiter circle centred on a ring of ``station_radius_m`` about the
nearest known unfinished target (at its own bearing from it) and loiters there; stations are
re-chosen when a target appears and whenever a UAV becomes idle.

Per-UAV state machine: idle -> recon -> leader (tendering) -> idle | executing;
idle -> locked (bid sent) -> executing (awarded) | idle (not awarded / timeout);
executing -> idle. Range used is speed x time (every UAV always flies); a task is only given when
the remaining range covers its path. Munitions are decremented at the strike and never go below 0.

Excluded members (choice; the paper does not say how a leader reacts when a member's timed path
cannot clear the threats): the member is excluded from that task and, with the ACO method, only
the excluded tasks are re-covered (``aco.repair``: a free candidate or a swap with another
member, schedule-keeping moves first, then the best J), instead of a new colony run. Members
that keep their task and required time keep their memoised paths (``paths.FormationPaths``).
The colony re-runs only when no move covers a task; the polynomial and global baselines re-run
their optimiser (effect: docs/coalition.md, Decisions).
Look-alike exclusion (choice, for compute): candidates that start within the excluded member's turn
radius and 30 deg of its heading (``lookalikes``; idle UAVs share loiter stations, so there are
often several) are excluded from the same task with it (logged as ``alike``). Their timed paths to
the same entry pose at the same time cross the same airspace, and finding out that each of them
fails too costs a whole attempt apiece (the risk: a look-alike that would have cleared
is lost, and if that leaves a task uncovered the formation fails and the leader re-tenders, as for
any exclusion; effect: docs/coalition.md, Decisions).

``SimResult.events`` is the timeline (tenders, bids, awards with time, vehicle, strike point,
arrival time and attack angle, failures, strikes, assessments, re-plans); ``SimResult.award_legs``
holds each awarded member's planned leg (for live upload, see ``leg_vehicle_plan``).
"""

from __future__ import annotations

import heapq
import logging
import math
import time
from dataclasses import dataclass, field

import numpy as np

from gcs_planner.core.geo import wrap_pi
from gcs_planner.planning.coalition import paths
from gcs_planner.planning.coalition.aco import CoalitionProblem, coverable, make_solution, repair, solve_aco
from gcs_planner.planning.coalition.baselines import GLOBAL_SCALE, solve_polynomial
from gcs_planner.planning.coalition.bus import MessageBus
from gcs_planner.planning.coalition.contract_net import Award, Bid, Tender, bid_for, tender_times
from gcs_planner.planning.coalition.model import STRIKE, Target, Threat, World
from gcs_planner.planning.coalition.track import Leg, Loiter, Track

__all__ = ["CoalitionSim", "SimResult"]

log = logging.getLogger(__name__)

IDLE, RECON, LEADER, LOCKED, EXECUTING = "idle", "recon", "leader", "locked", "executing"


@dataclass
class UavState:
    state: str
    munitions: int
    track: Track
    locked_to: int | None = None
    stored: list[Target] = field(default_factory=list)  # tenders postponed by the conflict rule
    strikes: int = 0


@dataclass
class TargetOutcome:
    target_id: str
    t_revealed_s: float | None = None
    t_formed_s: float | None = None
    tenders: int = 0
    J: float = 0.0
    parts: dict = field(default_factory=dict)
    t_done_s: float | None = None
    pending: int = 0
    members: tuple[str, ...] = ()
    sync_error_s: float = 0.0


@dataclass
class SimResult:
    events: list[dict]
    tracks: list[Track]
    states: list[UavState]
    outcomes: dict[str, TargetOutcome]
    compute_s: list[float]
    award_legs: dict[tuple[str, str], Leg]
    t_end_s: float

    @property
    def effectiveness(self) -> float:
        """Mean coalition effectiveness J over all targets (0 for a target never served)."""
        return float(np.mean([o.J if o.t_done_s is not None else 0.0 for o in self.outcomes.values()]))

    @property
    def completion_s(self) -> float:
        """Mean time from a target's reveal to its last task done, over completed targets."""
        done = [o.t_done_s - o.t_revealed_s for o in self.outcomes.values() if o.t_done_s is not None]
        return float(np.mean(done)) if done else math.nan


@dataclass
class _Formation:
    """A coalition being formed: the candidates, the task poses, the problem and its solution."""

    cands: list[int]
    poses: np.ndarray  # (n, 3) candidate poses at t_e^s
    goals: np.ndarray  # (K, 3) task entry poses
    kind: np.ndarray
    angle: np.ndarray
    speed: np.ndarray
    rmin: np.ndarray
    L: np.ndarray  # (n, K) shortest lengths, threats ignored
    prob: CoalitionProblem
    plans: paths.FormationPaths
    sol: object = None
    segs: list = field(default_factory=list)
    clear: list = field(default_factory=list)
    opt_s: float = 0.0


class CoalitionSim:
    def __init__(self, world: World, rng: np.random.Generator) -> None:
        self.w, self.p, self.rng = world, world.params, rng
        self.uavs = world.uavs
        self.approach_s = 0.0  # flight time each member's leg is given on top of its shortest route [s]
        self.now = 0.0
        self.heap: list = []
        self.seq = 0
        self.events: list[dict] = []
        self.known: list[Threat] = [t for t in world.threats if t.appear_s <= 0]
        self.tenders: dict[int, Tender] = {}
        self.outcomes = {t.id: TargetOutcome(t.id) for t in world.targets}
        self.compute_s: list[float] = []  # wall time of every formation (optimiser + paths), failed ones too
        self.optimiser_s: list[float] = []  # optimiser runs and repairs per formed coalition
        self.award_legs: dict[tuple[str, str], Leg] = {}
        self.st: list[UavState] = []
        for u in self.uavs:
            lo = self._clear_loiter(u.xy0[0], u.xy0[1], u.heading0_rad, 0.0, u)
            self.st.append(UavState(IDLE, u.munitions, Track([], lo)))
        extra = np.array([world.extra_delay_s.get(u.id, 0.0) for u in self.uavs])
        self.bus = MessageBus(
            self.positions,
            self.position,
            self.p.link_range_m,
            self.p.delay_s,
            rng,
            self.p.delay_jitter_s,
            extra if extra.any() else None,
        )

    # ---- plumbing
    def pose(self, i: int, t_s) -> np.ndarray:
        """(len(t), 3) x, y, heading of UAV i at times t_s, from its planned track (the online
        engine, flight.coalition.online, answers from live telemetry instead)."""
        return self.st[i].track.state_at(t_s)

    def positions(self, t_s: float) -> np.ndarray:
        return np.array([self.pose(i, t_s)[0, :2] for i in range(len(self.st))])

    def position(self, i: int, t_s: float) -> np.ndarray:
        return self.pose(i, t_s)[0, :2]

    def at(self, t_s: float, kind: str, **data) -> None:
        heapq.heappush(self.heap, (t_s, self.seq, kind, data))
        self.seq += 1

    def log(self, kind: str, **data) -> None:
        self.events.append({"t_s": round(self.now, 4), "event": kind, **data})

    def range_left(self, i: int, t_s: float) -> float:
        return self.uavs[i].range_max_m - self.uavs[i].speed_mps * t_s

    def run(self) -> SimResult:
        self.start()
        self.advance(self.p.t_end_s)
        return self.result()

    def start(self) -> None:
        """Put the scenario's timeline on the event heap: targets, pop-up threats, station keeping."""
        self.at(0.0, "restation")
        for t in self.w.targets:
            self.at(t.appear_s, "target_appear", target=t)
        for th in self.w.threats:
            if th.appear_s > 0:
                self.at(th.appear_s, "threat_appear", threat=th)

    def advance(self, t_s: float) -> None:
        """Handle every event due up to t_s (and the scenario's end)."""
        stop = min(t_s, self.p.t_end_s)
        while self.heap and self.heap[0][0] <= stop:
            t, _, kind, data = heapq.heappop(self.heap)
            self.now = t
            getattr(self, "_on_" + kind)(**data)
        self.now = max(self.now, stop)

    def result(self) -> SimResult:
        return SimResult(
            self.events,
            [s.track for s in self.st],
            self.st,
            self.outcomes,
            self.compute_s,
            self.award_legs,
            self.p.t_end_s,
        )

    # ---- idle station keeping
    def _on_restation(self) -> None:
        for i, s in enumerate(self.st):
            if s.state == IDLE:
                self._station(i)

    def _station(self, i: int) -> None:
        open_ = [t for t in self.w.targets if t.appear_s <= self.now and self.outcomes[t.id].t_done_s is None]
        if not open_:
            return
        u, s = self.uavs[i], self.st[i]
        q0 = self.pose(i, self.now)[0]
        c = np.array([t.approx_xy for t in open_])
        d = np.hypot(*(c - q0[:2]).T)
        tgt = c[int(np.argmin(d))]
        bearing = math.atan2(q0[1] - tgt[1], q0[0] - tgt[0])
        for turn in np.radians([0, 20, -20, 40, -40, 60, -60, 90, -90, 135, -135, 180]):
            b = bearing + turn  # rotate along the ring until the loiter circle clears the threats by kappa
            station = tgt + self.p.station_radius_m * np.array([math.cos(b), math.sin(b)])
            margin = [
                math.hypot(station[0] - t.x, station[1] - t.y)
                - self._loiter_radius(u)
                - self.p.kappa * t.radius_m
                for t in self.known
            ]
            if min(margin, default=1.0) > 0:
                break
        a = math.atan2(q0[1] - station[1], q0[0] - station[0])
        goal = paths.arc_start_pose(station, a, self._loiter_radius(u))[0]
        if math.hypot(*(goal[:2] - q0[:2])) < 2 * self._loiter_radius(u):
            return  # already there
        route = paths.min_route(q0, goal, u.r_min_m, self.known, self.p.kappa)
        segs, clear = paths.timed_route(route, route.length_m, self.known)
        leg = paths.sample_segments(
            segs, self.now, u.speed_mps, self.p.sample_ds_m, "transit", {"clear": clear}
        )
        s.track.start_leg(leg, self._circle_loiter(station, self._loiter_radius(u), leg, u.speed_mps))

    # ---- recon
    def _on_target_appear(self, target: Target) -> None:
        ids = [u.id for u in self.uavs]
        if target.recon_uav is not None and self.st[ids.index(target.recon_uav)].state == IDLE:
            i = ids.index(target.recon_uav)
        else:
            idle = [u.index for u in self.uavs if u.recon and self.st[u.index].state == IDLE]
            if not idle:
                self.at(self.now + self.p.retender_s, "target_appear", target=target)
                return
            poses = np.array([self.pose(i, self.now)[0] for i in idle])
            r = np.array([self.uavs[i].r_min_m for i in idle])
            i = idle[int(np.argmin(paths.free_heading_lengths(poses, np.asarray(target.approx_xy), r)))]
        u, s = self.uavs[i], self.st[i]
        s.state = RECON
        q0 = self.pose(i, self.now)[0]
        arc0 = paths.arc_start_pose(target.xy, target.recon_angle_rad, self.p.detect_radius_m)[0]
        route = paths.min_route(q0, arc0, u.r_min_m, self.known, self.p.kappa)
        segs, _ = paths.timed_route(route, route.length_m, self.known)
        leg = paths.sample_segments(
            segs, self.now, u.speed_mps, self.p.sample_ds_m, "transit", {"target": target.id}
        )
        arc = paths.arc_leg(
            target.xy,
            self.p.detect_radius_m,
            target.recon_angle_rad,
            leg.t[-1],
            target.recon_s,
            u.speed_mps,
            self.p.sample_ds_m,
            "recon",
            {"target": target.id},
        )
        full = _join(leg, arc, "recon", {"target": target.id, "arc_t0_s": float(arc.t[0])})
        s.track.start_leg(full, self._circle_loiter(target.xy, self.p.detect_radius_m, full, u.speed_mps))
        self.log("recon_start", uav=u.id, target=target.id, arrive_s=round(float(leg.t[-1]), 3))
        self.at(float(arc.t[-1]), "recon_done", uav=i, target=target)
        self._on_restation()

    def _loiter_radius(self, u) -> float:
        """The idle loiter radius of a UAV: the scenario's, or its r_min where that is wider (no UAV
        turns tighter than r_min; a real plane told to loiter tighter flies wider and out of step)."""
        return max(self.p.loiter_radius_m, u.r_min_m)

    def _circle_loiter(self, centre, radius, leg: Leg, speed) -> Loiter:
        end = leg.xy[-1]
        return Loiter(
            (float(centre[0]), float(centre[1])),
            radius,
            1.0,
            float(leg.t[-1]),
            float(math.atan2(end[1] - centre[1], end[0] - centre[0])),
            speed,
        )

    def _on_recon_done(self, uav: int, target: Target) -> None:
        out = self.outcomes[target.id]
        out.t_revealed_s = self.now
        self.log("recon_done", uav=self.uavs[uav].id, target=target.id)
        self.st[uav].state = LEADER
        self._tender(uav, target)

    # ---- contract net
    def _tender(self, leader: int, target: Target) -> None:
        p = self.p
        key = self.seq
        glob = p.method == "global"
        if glob:  # no link limits, no message delays: formation right away, paths from t0 + t_TA
            t_close, t_es = self.now, self.now + p.t_ta_s
        else:
            t_close, t_es = tender_times(self.now, p)
        loiter = self.st[leader].track.loiter
        tender = Tender(
            key,
            leader,
            target,
            self.now,
            t_close,
            t_es,
            loiter,
            target.reward * (len(target.strike_angles_rad) + len(target.assess_angles_rad)),
            len(target.strike_angles_rad),
            len(target.assess_angles_rad),
        )
        self.tenders[key] = tender
        self.outcomes[target.id].tenders += 1
        if glob:
            receivers = [i for i in range(len(self.uavs)) if i != leader]
            for j in receivers:
                self._on_tender_rx(j, key)
        else:
            receivers = list(self.bus.neighbours(leader, self.now))
            for j in receivers:
                t_arr = self.bus.arrival_s(leader, j, self.now)
                if t_arr is not None:
                    self.at(t_arr, "tender_rx", uav=j, key=key)
        self.log(
            "tender",
            uav=self.uavs[leader].id,
            target=target.id,
            neighbours=len(receivers),
            t_close_s=round(t_close, 4),
            t_es_s=round(t_es, 4),
            reward=tender.reward,
        )
        self.at(t_close, "close", key=key)

    def _on_tender_rx(self, uav: int, key: int) -> None:
        tender, s = self.tenders[key], self.st[uav]
        if tender.cancelled:
            return
        own = []
        if s.state == LEADER:
            own = [
                t
                for t in self.tenders.values()
                if t.leader == uav and not t.cancelled and t.t_close_s >= self.now
            ]
            if not own or own[0].reward >= tender.reward:
                return
        elif s.state != IDLE:
            return
        u = self.uavs[uav]
        bid, why = bid_for(
            uav,
            _PoseView(self, uav),
            u.speed_mps,
            u.r_min_m,
            s.munitions,
            u.assess,
            self.range_left(uav, self.now),
            tender,
            self.now,
            self.p,
            check_range=self.p.method != "global",
        )
        if bid is None:
            if why != "no matching capability":
                self.log("not_bidding", uav=u.id, target=tender.target.id, reason=why)
            return
        if own:  # conflicting tenders: bid on the richer one, keep ours for later
            own[0].cancelled = True
            s.stored.append(own[0].target)
            self.log("tender_postponed", uav=u.id, target=own[0].target.id, for_target=tender.target.id)
            self._release_bidders(own[0])
        s.state, s.locked_to = LOCKED, key
        self.at(tender.t_es_s + self.p.delta_max_s, "unlock", uav=uav, key=key)
        if self.p.method == "global":
            tender.bids.append(bid)
            return
        t_arr = self.bus.arrival_s(uav, tender.leader, self.now)
        self.log(
            "bid",
            uav=u.id,
            target=tender.target.id,
            eta_s=round(bid.eta_s, 3),
            arrive_s=None if t_arr is None else round(t_arr, 4),
        )
        if t_arr is not None:
            self.at(t_arr, "bid_rx", bid=bid)

    def _on_bid_rx(self, bid: Bid) -> None:
        tender = self.tenders[bid.tender_key]
        if tender.cancelled:
            return
        if self.now > tender.t_close_s + 1e-9:
            self.log(
                "late_bid_ignored",
                uav=self.uavs[bid.uav].id,
                target=tender.target.id,
                t_close_s=round(tender.t_close_s, 4),
            )
            return
        tender.bids.append(bid)

    def _on_unlock(self, uav: int, key: int) -> None:
        s = self.st[uav]
        if s.state == LOCKED and s.locked_to == key:
            s.state, s.locked_to = IDLE, None
            self._resume_stored(uav)
            if s.state == IDLE:
                self._station(uav)

    def _release_bidders(self, tender: Tender) -> None:
        for b in tender.bids:
            self._on_unlock(b.uav, tender.key)

    # ---- formation
    def _on_close(self, key: int) -> None:
        """The tender closes: form the coalition from the bids (eqs. 24-31) and award its tasks."""
        tender = self.tenders[key]
        if tender.cancelled:
            return
        t_wall = time.perf_counter()
        cands, poses, munitions, assess, rleft, etas = self._candidates(tender)
        if not cands:
            return self._fail(tender, "no candidates", t_wall)
        f = self._formation(tender, cands, np.array(poses), munitions, assess, rleft)
        if not coverable(f.prob):
            return self._fail(tender, f"needs not covered by {len(cands)} candidates", t_wall)
        why = self._solve(tender, f, np.array(etas))
        if why:
            return self._fail(tender, why, t_wall)
        kind, p = f.kind, self.p
        legs = paths.sample_legs(  # the last attempt's legs (all clear unless attempts ran out)
            f.segs,
            f.prob.t_start_s,
            f.speed[f.sol.assign],
            p.sample_ds_m,
            ["strike" if kind[k] == STRIKE else "transit" for k in range(len(kind))],
            [{"target": tender.target.id, "clear": f.clear[k]} for k in range(len(kind))],
        )
        dt = time.perf_counter() - t_wall
        self.compute_s.append(dt)
        self.optimiser_s.append(f.opt_s)
        self._award(tender, f, legs, dt)

    def _candidates(self, tender: Tender) -> tuple[list[int], list, list, list, list, list]:
        """Candidates with their pose, munitions, assessment payload, range left and ETA at t_e^s:
        the leader itself (eq. 24) while it leads, then every bidder."""
        cands: list[int] = []
        poses, munitions, assess, rleft, etas = [], [], [], [], []
        leader = tender.leader
        if self.st[leader].state == LEADER:
            u = self.uavs[leader]
            pose = self.pose(leader, tender.t_es_s)[0]
            d = float(paths.free_heading_lengths(pose[None], np.asarray(tender.target.xy), u.r_min_m)[0])
            cands.append(leader)
            poses.append(pose)
            munitions.append(self.st[leader].munitions)
            assess.append(u.assess)
            rleft.append(self.range_left(leader, tender.t_es_s))
            etas.append(tender.t_es_s + d / u.speed_mps)
        for b in tender.bids:
            cands.append(b.uav)
            poses.append(b.pose_at_tes)
            munitions.append(b.munitions)
            assess.append(b.can_assess)
            rleft.append(b.range_left_m)
            etas.append(b.eta_s)
        return cands, poses, munitions, assess, rleft, etas

    def _formation(self, tender: Tender, cands: list[int], poses, munitions, assess, rleft) -> _Formation:
        """The coalition problem of the candidates for the target's tasks (shortest Dubins lengths)."""
        target = tender.target
        kind, angle, offset = target.tasks()
        n, K = len(cands), len(kind)
        goals = self._task_poses(target, kind, angle)
        speed = np.array([self.uavs[i].speed_mps for i in cands])
        rmin = np.array([self.uavs[i].r_min_m for i in cands])
        L = (
            paths.shortest_lengths(
                np.repeat(poses, K, 0), np.tile(goals, (n, 1)), np.repeat(rmin, K)
            ).reshape(n, K)
            + self.approach_s * speed[:, None]
        )
        prob = CoalitionProblem(
            length_m=L,
            speed_mps=speed,
            range_left_m=np.array(rleft),
            range_max_m=np.array([self.uavs[i].range_max_m for i in cands]),
            can_strike=np.array(munitions) > 0,
            can_assess=np.array(assess),
            kind=kind,
            offset_s=offset,
            reward=np.full(K, target.reward),
            decay_per_s=target.decay_per_s,
            assess_delay_s=target.assess_delay_s,
            assess_duration_s=target.assess_duration_s,
            t0_s=self.outcomes[target.id].t_revealed_s,
            t_start_s=tender.t_es_s,
        )
        plans = paths.FormationPaths(poses, goals, rmin, self.known, self.p.kappa, self.p.sample_ds_m)
        return _Formation(cands, poses, goals, kind, angle, speed, rmin, L, prob, plans)

    def _solve(self, tender: Tender, f: _Formation, etas: np.ndarray) -> str | None:
        """Assign the tasks (the colony, or a baseline) and time the members' legs; a member whose
        timed leg cannot clear the threats is excluded (with its lookalikes) and the tasks
        re-covered, up to three attempts. The reason it failed, or None."""
        p, prob, kind, n = self.p, f.prob, f.kind, len(f.cands)
        base = f.L.copy()
        sol, bad = None, []
        for _attempt in range(3):
            prob.length_m = base.copy()
            if not coverable(prob):
                return f"needs not covered by {n} candidates clear of threats"
            t_opt = time.perf_counter()
            fixed = None
            if sol is not None and p.method == "aco":  # re-cover only the excluded members' tasks
                allowance = self.approach_s * f.speed[:, None]  # routed lengths, with _formation's allowance
                prob.length_m = np.where(np.isinf(base), np.inf, f.plans.lengths(f.L - allowance) + allowance)
                fixed = repair(sol.assign, bad, sol.t_required_s, prob, p)
                prob.length_m = base.copy()
            if fixed is not None:
                sol = make_solution(fixed, prob, p)
            elif p.method == "polynomial":
                sol = solve_polynomial(prob, p, etas)
            else:
                sol = solve_aco(prob, p, self.rng, scale=GLOBAL_SCALE if p.method == "global" else 1)
            f.opt_s += time.perf_counter() - t_opt  # the colony run plus any repairs
            if not sol.covered:
                return f"needs not covered by {n} candidates"
            sol = self._time_legs(f, sol)
            bad = [k for k in range(len(kind)) if not f.clear[k]]
            if not bad:
                return None
            self._exclude(tender, f, base, sol, bad)
        return None  # attempts ran out: the legs are flown as they are, marked not clear

    def _time_legs(self, f: _Formation, sol):
        """Exact threat-avoiding routes of the assignment, the solution re-evaluated on them (the
        latest member is the reference of lambda) and each leg stretched to its required time."""
        routes = f.plans.routes(sol.assign)
        exact = f.L.copy()
        for k in range(len(f.kind)):
            exact[sol.assign[k], k] = routes[k].length_m + self.approach_s * f.speed[sol.assign[k]]
        f.prob.length_m = exact
        sol = make_solution(sol.assign, f.prob, self.p)
        want = np.array(
            [
                max(routes[k].length_m, f.speed[sol.assign[k]] * (sol.t_required_s[k] - f.prob.t_start_s))
                if f.kind[k] == STRIKE
                else routes[k].length_m
                for k in range(len(f.kind))
            ]
        )
        f.segs, f.clear = f.plans.timed(sol.assign, want)
        f.sol = sol
        return sol

    def _exclude(self, tender: Tender, f: _Formation, base: np.ndarray, sol, bad: list[int]) -> None:
        for k in bad:
            x = sol.assign[k]
            alike = [i for i in lookalikes(f.poses, x, f.rmin[x]) if np.isfinite(base[i, k])]
            base[[x, *alike], k] = np.inf
            self.log(
                "member_excluded",
                uav=self.uavs[f.cands[x]].id,
                target=tender.target.id,
                reason="timed path cannot clear the threats",
                alike=[self.uavs[f.cands[i]].id for i in alike],
            )

    def _award(self, tender: Tender, f: _Formation, legs: list[Leg], compute_s: float) -> None:
        """Log the coalition and send each member its award (lost on a broken link); release the
        bidders that were not chosen and a leader that is not a member."""
        target, p, sol, leader, key = tender.target, self.p, f.sol, tender.leader, tender.key
        members = tuple(int(f.cands[i]) for i in sol.assign)
        out = self.outcomes[target.id]
        out.t_formed_s, out.J, out.parts = self.now, sol.J, sol.parts
        out.members = tuple(self.uavs[m].id for m in members)
        out.pending = len(f.kind)
        self.log(
            "formed",
            uav=self.uavs[leader].id,
            target=target.id,
            candidates=len(f.cands),
            members=list(out.members),
            J=round(sol.J, 4),
            compute_s=round(compute_s, 4),
            optimiser_s=round(f.opt_s, 4),
        )
        t_send = tender.t_es_s - p.delay_s
        # an assessor that cannot reach its arc by the required start starts when it gets there
        x = sol.assign
        eta = f.prob.t_start_s + f.prob.length_m[x, np.arange(len(x))] / f.speed[x]
        start = np.where(f.kind == STRIKE, sol.t_required_s, np.fmax(sol.t_required_s, eta))
        for k, i in enumerate(members):
            task = "strike" if f.kind[k] == STRIKE else "assess"
            at_s = float(start[k])
            award = Award(leader, i, key, target.id, members, task, float(f.angle[k]), at_s)
            direct = p.method == "global" or i == leader
            t_arr = tender.t_es_s if direct else self.bus.arrival_s(leader, i, t_send)
            entry = f.goals[k]
            self.log(
                "award",
                uav=self.uavs[i].id,
                sysid=self.uavs[i].sysid,
                target=target.id,
                task=award.task,
                angle_deg=round(math.degrees(award.angle_rad) % 360, 3),
                time_s=round(award.time_s, 4),
                entry_xy=[round(float(entry[0]), 3), round(float(entry[1]), 3)],
                strike_point=list(target.xy),
                arrive_s=None if t_arr is None else round(t_arr, 4),
            )
            if t_arr is None:
                out.pending -= 1
                self.log("award_lost", uav=self.uavs[i].id, target=target.id)
                continue
            self.at(max(t_arr, self.now), "award_rx", award=award, leg=legs[k], k=k)
        for b in tender.bids:  # not awarded: released by the award broadcast
            if b.uav not in members:
                self.at(tender.t_es_s, "unlock", uav=b.uav, key=key)
        if leader not in members:
            self.st[leader].state = IDLE
            self._resume_stored(leader)

    def _task_poses(self, target: Target, kind: np.ndarray, angle: np.ndarray) -> np.ndarray:
        strike = paths.entry_poses(target.xy, angle, self.p.standoff_m)
        arc = paths.arc_start_pose(target.xy, angle, self.p.assess_radius_m)
        return np.where((kind == STRIKE)[:, None], strike, arc)

    def _fail(self, tender: Tender, why: str, t_wall: float) -> None:
        self.compute_s.append(time.perf_counter() - t_wall)
        self.log(
            "formation_failed",
            uav=self.uavs[tender.leader].id,
            target=tender.target.id,
            reason=why,
            candidates=len(tender.bids),
        )
        self._release_bidders(tender)
        self.at(self.now + self.p.retender_s, "retender", uav=tender.leader, target=tender.target)

    def _on_retender(self, uav: int, target: Target) -> None:
        s = self.st[uav]
        if s.state == LEADER:
            self._tender(uav, target)
        elif s.state == IDLE:
            s.state = LEADER
            self._tender(uav, target)
        elif target not in s.stored:
            s.stored.append(target)

    def _resume_stored(self, uav: int) -> None:
        s = self.st[uav]
        if s.state == IDLE and s.stored:
            self.at(self.now, "retender", uav=uav, target=s.stored.pop(0))

    # ---- execution
    def _on_award_rx(self, award: Award, leg: Leg, k: int) -> None:
        i, s, u = award.uav, self.st[award.uav], self.uavs[award.uav]
        s.state, s.locked_to = EXECUTING, None
        target = next(t for t in self.w.targets if t.id == award.target_id)
        key = (award.target_id, u.id)
        if award.task == "strike":
            s.track.start_leg(leg, self._safe_loiter(leg, u))
            self.award_legs[key] = leg
            self.at(float(leg.t[-1]), "strike", uav=i, award=award)
        else:
            arc = paths.arc_leg(
                target.xy,
                self.p.assess_radius_m,
                award.angle_rad,
                max(float(leg.t[-1]), award.time_s),
                target.assess_duration_s,
                u.speed_mps,
                self.p.sample_ds_m,
                "assess",
                {"target": target.id},
            )
            if arc.t[0] > leg.t[-1] + 1e-9:  # early: circle on the assessment circle until the start time
                wait = paths.arc_leg(
                    target.xy,
                    self.p.assess_radius_m,
                    award.angle_rad - u.speed_mps * (arc.t[0] - leg.t[-1]) / self.p.assess_radius_m,
                    float(leg.t[-1]),
                    arc.t[0] - leg.t[-1],
                    u.speed_mps,
                    self.p.sample_ds_m,
                    "transit",
                )
                leg = _join(leg, wait, leg.kind, leg.info)
            full = _join(
                leg,
                arc,
                "assess",
                {"target": target.id, "clear": leg.info.get("clear", True), "arc_t0_s": float(arc.t[0])},
            )
            s.track.start_leg(full, self._circle_loiter(target.xy, self.p.assess_radius_m, full, u.speed_mps))
            self.award_legs[key] = full
            self.at(float(arc.t[0]), "assess_start", uav=i, award=award)
            self.at(float(arc.t[-1]), "task_done", uav=i, award=award)

    def _safe_loiter(self, leg: Leg, u) -> Loiter:
        """Break-off loiter after a strike (see _clear_loiter)."""
        return self._clear_loiter(leg.xy[-1, 0], leg.xy[-1, 1], leg.heading[-1], float(leg.t[-1]), u)

    def _clear_loiter(self, x: float, y: float, h: float, t_s: float, u) -> Loiter:
        """Loiter through a pose: turn left or right, whichever circle clears the known threats."""
        for direction in (1.0, -1.0):
            lo = Loiter.through(x, y, h, t_s, self._loiter_radius(u), u.speed_mps, direction)
            ring = lo.state(np.linspace(lo.t0_s, lo.t0_s + 2 * math.pi * lo.radius_m / u.speed_mps, 64))
            if paths.clearance_m(ring[:, :2], self.known) >= 0:
                return lo
        return Loiter.through(x, y, h, t_s, self._loiter_radius(u), u.speed_mps, 1.0)

    def _on_strike(self, uav: int, award: Award) -> None:
        s = self.st[uav]
        if s.munitions <= 0:
            raise RuntimeError(f"{self.uavs[uav].id} was awarded a strike without munitions")
        s.munitions -= 1
        s.strikes += 1
        pose = self.pose(uav, self.now)[0]
        self.log(
            "strike",
            uav=self.uavs[uav].id,
            target=award.target_id,
            planned_s=round(award.time_s, 4),
            error_s=round(self.now - award.time_s, 4),
            heading_deg=round(math.degrees(pose[2]) % 360, 3),
            angle_deg=round(math.degrees(award.angle_rad) % 360, 3),
            munitions_left=s.munitions,
        )
        self._task_done(uav, award)

    def _on_assess_start(self, uav: int, award: Award) -> None:
        self.log(
            "assess_start",
            uav=self.uavs[uav].id,
            target=award.target_id,
            planned_s=round(award.time_s, 4),
            error_s=round(self.now - award.time_s, 4),
        )

    def _on_task_done(self, uav: int, award: Award) -> None:
        self.log("assess_done", uav=self.uavs[uav].id, target=award.target_id)
        self._task_done(uav, award)

    def _task_done(self, uav: int, award: Award) -> None:
        out = self.outcomes[award.target_id]
        out.pending -= 1
        if award.task == "strike":
            out.sync_error_s = max(out.sync_error_s, abs(self.now - award.time_s))
        if out.pending == 0:
            out.t_done_s = self.now
            self.log("target_done", target=award.target_id, J=round(out.J, 4))
            self.at(self.now, "restation")
        self.st[uav].state = IDLE
        self._resume_stored(uav)
        if self.st[uav].state == IDLE:
            self._station(uav)

    # ---- pop-up threats
    def _on_threat_appear(self, threat: Threat) -> None:
        self.known.append(threat)
        self.log("threat_appear", x=threat.x, y=threat.y, radius_m=threat.radius_m)
        for i, s in enumerate(self.st):
            if not s.track.legs or s.track.legs[-1].t[-1] <= self.now:
                continue
            leg = s.track.legs[-1]
            ahead = leg.t >= self.now
            if paths.clearance_m(leg.xy[ahead], [threat]) >= 0:
                continue
            self._replan(i, leg)

    def _replan(self, i: int, leg: Leg) -> None:
        """Re-route the rest of leg from the current pose around the known threats, same goal and time."""
        u, s = self.uavs[i], self.st[i]
        q0 = self.pose(i, self.now)[0]
        # goal: the leg's own end for strikes/transits; the arc start for recon/assess legs
        kinds = leg.kind
        j_goal = len(leg.t) - 1
        if kinds in ("assess", "recon"):
            j_goal = int(np.searchsorted(leg.t, leg.info.get("arc_t0_s", leg.t[-1])))
        q1 = (
            np.r_[leg.xy[-1], leg.heading[-1]]
            if j_goal >= len(leg.t) - 1
            else np.r_[leg.xy[j_goal], leg.heading[j_goal]]
        )
        route = paths.min_route(q0, q1, u.r_min_m, self.known, self.p.kappa)
        t_goal = float(leg.t[min(j_goal, len(leg.t) - 1)])
        length = max(route.length_m, u.speed_mps * (t_goal - self.now))
        segs, clear = paths.timed_route(route, length, self.known)
        new = paths.sample_segments(
            segs, self.now, u.speed_mps, self.p.sample_ds_m, leg.kind, {**leg.info, "clear": clear}
        )
        late = float(new.t[-1] - t_goal)
        if j_goal < len(leg.t) - 1:
            rest = slice(j_goal + 1, None)
            new = Leg(
                np.r_[new.t, leg.t[rest] + late],
                np.r_[new.xy, leg.xy[rest]],
                np.r_[new.heading, leg.heading[rest]],
                leg.kind,
                new.info,
            )
        s.track.start_leg(new, s.track.loiter)
        for (tid, uid), old in list(self.award_legs.items()):
            if old is leg:
                self.award_legs[(tid, uid)] = new
        self.log("replan", uav=u.id, clear=clear, late_s=round(late, 4))


@dataclass(frozen=True)
class _PoseView:
    """UAV i's poses as a track (``state_at``) for the bid functions: its planned track, or live."""

    sim: CoalitionSim
    i: int

    def state_at(self, t_s) -> np.ndarray:
        return self.sim.pose(self.i, t_s)


def lookalikes(
    poses: np.ndarray, x: int, radius_m: float, max_turn_rad: float = math.radians(30.0)
) -> list[int]:
    """Candidates (indices into poses (n, 3), x excluded) that start within radius_m and max_turn_rad
    of candidate x's pose: their timed paths to one entry pose at one time cross the same airspace,
    so when x's cannot clear the threats theirs are presumed not to either (choice, see above)."""
    d = np.hypot(poses[:, 0] - poses[x, 0], poses[:, 1] - poses[x, 1])
    turn = np.abs(wrap_pi(poses[:, 2] - poses[x, 2]))
    return [int(i) for i in np.flatnonzero((d < radius_m) & (turn < max_turn_rad)) if i != x]


def _join(a: Leg, b: Leg, kind: str, info: dict) -> Leg:
    """Leg a then leg b (b starts where a ends)."""
    return Leg(np.r_[a.t, b.t[1:]], np.r_[a.xy, b.xy[1:]], np.r_[a.heading, b.heading[1:]], kind, info)
