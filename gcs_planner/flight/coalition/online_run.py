"""The online coalition run: the contract net (online.OnlineContractNet) decides in flight, on telemetry.

Every UAV of the scenario flies. The engine runs as the simulation up to the window start
``t_start`` (the flight's lead-in ends there), so the first missions are its planned tracks; from
then on it advances with the telemetry's scenario clock and answers from live state. Each time
the engine starts a new leg for a vehicle (a station change, a recon, an award, a re-plan around a
pop-up threat) the vehicle's plan generation goes up and a mission is queued for it: an award's
leg is planned from the vehicle's live state to the award's goal at the awarded time and angle
(as in the offline run, around the threats the engine knows now); any other leg becomes an "idle"
mission that rejoins the engine's track. Idle missions follow the engine's track in 40 s chunks;
a job of an older generation than the vehicle's is dropped when its turn comes. A vehicle whose
newest report is ``LOSS_AFTER_S`` older than the fleet's clock is lost: the engine hands its
task on and its queued missions are dropped. The window ends as in the offline run, or later
(up to ``OVERRUN_S``) while a flown target still has a task to do.

An award reaches its vehicle as a mission upload: the engine's awarded times allow for the
uploads of a whole coalition behind the award uploads still queued (``award_lag_s`` = ceil((open
award uploads + tasks) / upload workers) x the measured upload estimate of an ``AWARD_ITEMS``
mission + ``START_AHEAD_S``): T3 forms 0.86 s after T1, while T1's ten uploads are under way.

The report is the offline run's, over the engine's awards (a lost vehicle's awards are listed,
not judged), plus the online and simulated formations side by side (``formation_rows``) and the
wall time of each formation made in flight.
"""

from __future__ import annotations

import asyncio
from dataclasses import dataclass
from typing import Literal

import numpy as np

from gcs_planner.core.lockstep import now_s
from gcs_planner.flight.coalition.live_legs import LEG_SPEED_FACTOR, LiveState, plan_live_leg
from gcs_planner.flight.coalition.missions import Award, Idle, VehicleSchedule, first_mission
from gcs_planner.flight.coalition.online import OnlineContractNet
from gcs_planner.flight.coalition.report import add_prediction_errors, formation_rows, task_rows
from gcs_planner.flight.coalition.run import (
    IDLE_LEAD_S,
    START_AHEAD_S,
    UPLOAD_WORKERS,
    CoalitionRun,
    HilOptions,
    HilResult,
    UploadJob,
    VehiclesFor,
    keep_current,
    run_coalition_hil,
)
from gcs_planner.flight.coalition.tracks import drop_spikes
from gcs_planner.flight.ops import KEEPER_PERIOD_S
from gcs_planner.mavlink.link import MavlinkLink
from gcs_planner.model.scenario import Scenario
from gcs_planner.planning.coalition.model import Threat
from gcs_planner.telemetry import FlightLogger

__all__ = ["Fault", "OnlineRun", "run_online"]

LOSS_AFTER_S = 3.0  # a vehicle whose newest report is this much older than the fleet's is lost [s]
OVERRUN_S = 90.0  # the window is extended by up to this while a flown target has a task left [s]
FIRST_SPAN_S = 45.0  # the first mission covers this much of the engine's track after t_start [s]
AWARD_ITEMS = 30  # items of a typical award mission (19-45), for the award lag
HISTORY_AHEAD_S = 120.0  # the engine's track is read this far past the window end [s]
THREAT_AHEAD_S = 8.0  # a fault's pop-up threat is put at least this far ahead on a leg [s]
THREAT_TRIES = 8  # points tried for a fault's pop-up threat


@dataclass(frozen=True)
class Fault:
    """An in-flight event tied to an award, ``after_s`` after the award of the ``member``-th vehicle
    awarded a task of ``target`` (award order): "cut" that vehicle's link (the mock stops its
    reports), or "threat": a pop-up threat of ``radius_m`` across the rest of its leg, or of the
    next member's, where the leg passes clear of the others and can go around it in time
    (``_threat_across_a_leg``: the fault tests one leg's avoidance, not a crowd's and not an
    impossible one), injected into the contract net."""

    kind: Literal["cut", "threat"]
    target: str
    member: int = 0
    after_s: float = 5.0
    radius_m: float = 120.0


class OnlineRun(CoalitionRun):
    """One online coalition run (module docstring); ``fly`` and ``result`` as the offline run's."""

    def __init__(self, scenario: Scenario, options: HilOptions) -> None:
        seed = self._simulate(scenario, options)  # the reference, and the window
        self.targets = {e["target"] for e in self.awards}
        self.engine = OnlineContractNet(self.world, np.random.default_rng(seed), self)
        self.engine.start()
        self.engine.advance(self.t_start)
        self.engine.go_live(self.t_start)
        self.by_sysid = {u.sysid: u for u in self.world.uavs}
        self.sched = {}
        for u in self.world.uavs:
            track = self._engine_track(u)
            vp = first_mission(u, track, self.t_start, self.t_start + FIRST_SPAN_S, options.waypoint_dt_s,
                               options.offset_m.get(u.id, (0.0, 0.0)))  # fmt: skip
            self.sched[u.sysid] = VehicleSchedule(u, vp, track, [], [])
        self._init_flight([s.initial for s in self.sched.values()])
        self.gen = {s: 0 for s in self.flying}
        self.locks = {s: asyncio.Lock() for s in self.flying}
        self.last_leg = {u.sysid: self._last_leg(u) for u in self.world.uavs}
        self.logged = len(self.engine.events)
        self.award_events: dict[tuple[str, str], dict] = {}
        self.faults = list(options.faults)
        self.awards_open = 0  # award jobs queued or uploading
        self.t_end = float("inf")
        first_chunk = self.t_start + FIRST_SPAN_S - IDLE_LEAD_S
        for s in self.sched.values():
            idle = Idle(first_chunk, {"uav": s.uav.id, "target": None, "task": "idle", "t_s": first_chunk},
                        self._end_s(), None)  # fmt: skip
            self.due.append(UploadJob(first_chunk, (2, first_chunk), "idle", s, idle, 0))

    def connect(self) -> None:
        super().connect()
        self.engine.approach_s = self.run_in_s

    # --- the engine's view of the fleet (online.LiveFleet) -----------------------------------
    def state(self, i: int) -> LiveState | None:
        uav = self.world.uavs[i]
        return self.vehicle_state(uav) if self.telemetry.rows[uav.sysid] else None

    def flown_since(self, i: int, t_s: float) -> np.ndarray:
        sysid = self.world.uavs[i].sysid
        return self.recorder.positions_since(sysid, t_s - self.t_route0 + self.route_t0)[:, :2]

    def known_threats(self, t_s: float) -> list:
        return list(self.engine.known)

    # --- the engine's plan -------------------------------------------------------------------
    def _end_s(self) -> float:
        return self.t_stop + OVERRUN_S

    def _engine_track(self, uav) -> tuple[np.ndarray, np.ndarray]:
        history = self.engine.st[uav.index].track.history(self._end_s() + HISTORY_AHEAD_S)
        return drop_spikes(history[0], history[1], uav.speed_mps)

    def _last_leg(self, uav):
        legs = self.engine.st[uav.index].track.legs
        return legs[-1] if legs else None

    async def _mission(self, job: UploadJob, entry: dict):
        """The job's mission over the engine's plan as it is now. An award leg that would be late
        (or early: no path of the right length, paths.timed_route) beyond the time bound releases
        the award (the engine re-tenders it); the mission is still
        sent, and the idle mission the release causes replaces it."""
        job.sched.track = self._engine_track(job.sched.uav)
        vp, leg = await super()._mission(job, entry)
        late = job.kind == "award" and abs(leg.info["late_s"]) > self.options.max_time_error_s
        if late and self.engine.release(job.sched.uav.index, job.payload.event["target"]):
            entry["released"] = True
            self._step_engine(self.scenario_now())
        return vp, leg

    def _leg_start_s(self, award: Award, earliest_s: float) -> float:
        """The engine's leg start, where the formation timed the member from (its predicted pose at
        t_e^s + award_lag_s), unless the upload cannot land by then: a loitering vehicle turns
        ~20 deg/s, and a pose a second off can need a whole extra turn to its goal."""
        return max(earliest_s, float(award.sim_leg.t[0]))

    def _queue_changes(self, now: float) -> None:
        """A job for every vehicle whose engine plan has a new leg: its award's, or an idle one."""
        award_of = {id(leg): key for key, leg in self.engine.award_legs.items()}
        for sysid in self.flying:
            uav = self.by_sysid[sysid]
            leg = self._last_leg(uav)
            if leg is self.last_leg[sysid] or uav.index in self.engine.lost:
                continue
            self.last_leg[sysid] = leg
            self.gen[sysid] += 1
            sched, key = self.sched[sysid], award_of.get(id(leg))
            if key is not None:
                self.awards_open += 1
                e = self.award_events[key]
                job = UploadJob(now, (False, self.deadline_s(uav, e, now)), "award", sched,
                           Award(e, leg, self._end_s()), self.gen[sysid])  # fmt: skip
            else:
                event = {"uav": uav.id, "target": leg.info.get("target"), "task": leg.kind, "t_s": now}
                idle = Idle(now, event, self._end_s(), None)
                job = UploadJob(now, (1, now), "idle", sched, idle, self.gen[sysid])
            self.queue.put_nowait((job.rank, next(self.order), job))

    def _check_losses(self) -> None:
        fleet_now = self.recorder.now_s()
        for sysid in self.flying:
            rows, i = self.telemetry.rows[sysid], self.by_sysid[sysid].index
            if rows and i not in self.engine.lost and fleet_now - rows[-1][0] > LOSS_AFTER_S:
                self.engine.vehicle_lost(i)
                self.gen[sysid] += 1
                self.current.pop(sysid, None)

    def _apply_faults(self, now: float) -> None:
        """Apply each Fault whose time has come (see Fault)."""
        for fault in list(self.faults):
            awarded = [e for e in self.award_events.values() if e["target"] == fault.target]
            if len(awarded) <= fault.member or now < awarded[fault.member]["t_s"] + fault.after_s:
                continue
            if fault.kind == "cut":
                self.vehicles.cut_link(awarded[fault.member]["sysid"])
            elif not self._threat_across_a_leg(awarded[fault.member :], fault.radius_m, now):
                continue
            self.faults.remove(fault)

    def _threat_across_a_leg(self, awarded: list[dict], radius_m: float, now: float) -> bool:
        """Put a pop-up threat on the rest of the first of these awards' legs (from THREAT_AHEAD_S to
        3 s before its end) at a point clear of every other award leg by the threat's avoidance
        radius (kappa x r) + 50 m, around which the vehicle's live leg can still arrive on time
        (``THREAT_TRIES`` such points tried, the clearest first). False when none has one yet."""
        need = self.world.params.kappa * radius_m + 50.0
        for e in awarded:
            leg = self.engine.award_legs.get((e["target"], e["uav"]))
            if leg is None:
                continue
            rest = leg.xy[(leg.t >= now + THREAT_AHEAD_S) & (leg.t <= leg.t[-1] - 3.0)]
            clearance = self._clearance_to_other_legs(rest, leg, now) if len(rest) else np.zeros(0)
            uav = self.by_sysid[e["sysid"]]
            t0 = now + START_AHEAD_S
            q0 = self.vehicle_state(uav).predict([t0])[0]
            for j in np.argsort(-clearance)[:THREAT_TRIES]:
                if clearance[j] < need:
                    break
                threat = Threat(float(rest[j, 0]), float(rest[j, 1]), radius_m, now)
                known = [*self.engine.known, threat]
                live = plan_live_leg(self.world, e, q0, t0, LEG_SPEED_FACTOR, known, self.run_in_s,
                                     self.turn_factor)  # fmt: skip
                if live.info["clear"] and live.info["late_s"] <= 0.1:
                    self.engine.inject_threat(threat)
                    return True
        return False

    def _clearance_to_other_legs(self, points: np.ndarray, leg, now: float) -> np.ndarray:
        """Each point's distance [m] to the rest of every other award leg (inf without any)."""
        others = [lg.xy[lg.t >= now] for lg in self.engine.award_legs.values() if lg is not leg]
        others = np.vstack([o for o in others if len(o)] or [np.full((1, 2), np.inf)])
        return np.hypot(*(points[:, None, :] - others[None, :, :]).transpose(2, 0, 1)).min(axis=1)

    def _log_events(self, logger: FlightLogger) -> None:
        for e in self.engine.events[self.logged :]:
            if e["event"] == "award":
                self.award_events[(e["target"], e["uav"])] = e
            logger.log_event({**e, "source": "online_contract_net"})
        self.logged = len(self.engine.events)

    def _open(self, now: float) -> bool:
        """Is the window still open: before its end, or with a flown target's task left (overrun)?"""
        if now < self.t_stop:
            return True
        undone = any(self.engine.outcomes[t].t_done_s is None for t in self.targets)
        return undone and now < self._end_s()

    def _step_engine(self, now: float) -> None:
        """Advance the engine to now, log its new events, queue the missions of its new legs."""
        self.engine.advance(now)
        self._log_events(self.logger)
        self._queue_changes(now)

    def _award_lag_s(self) -> float:
        """The flight time a new coalition's award uploads may take: ceil((award uploads still
        queued or running + the most tasks of a target) / workers) uploads of AWARD_ITEMS items."""
        tasks = max(len(t.strike_angles_rad) + len(t.assess_angles_rad) for t in self.world.targets)
        rounds = -(-(self.awards_open + tasks) // UPLOAD_WORKERS)
        return rounds * self.upload_estimate_s(AWARD_ITEMS) + START_AHEAD_S

    # --- the loop ----------------------------------------------------------------------------
    async def _serve(self, link: MavlinkLink, logger: FlightLogger) -> None:
        options = self.options
        self.logger = logger
        workers = [asyncio.create_task(self._worker(link, logger)) for _ in range(UPLOAD_WORKERS)]
        self.due.sort()
        deadline = now_s() + (self._end_s() - self.t_route0 + 10.0) * 2.0 / self.vehicles.speedup + 10.0
        while self._open(self.scenario_now()) and now_s() < deadline:
            now = self.scenario_now()
            if now >= self.t_start:
                self._check_losses()
                self.engine.award_lag_s = self._award_lag_s()
                self._step_engine(now)
                self._apply_faults(now)
            while self.due and self.due[0].t_s <= now:
                job = self.due.pop(0)
                self.queue.put_nowait((job.rank, next(self.order), job))
            if options.keep_schedule:
                keep_current(link, self.recorder, self.keeper, self.current, self.route_t0, self.quirks)
            await asyncio.sleep(KEEPER_PERIOD_S / self.vehicles.speedup)
        self.t_end = self.scenario_now()
        await self._drain(workers, deadline)

    async def _upload(self, link: MavlinkLink, logger: FlightLogger, job: UploadJob) -> dict | None:
        """One vehicle's jobs one at a time (a vehicle takes one mission transfer at a time); a job
        superseded by a newer plan of the engine, or of a lost vehicle, is dropped."""
        sysid = job.sched.uav.sysid
        try:
            async with self.locks[sysid]:
                if job.gen != self.gen[sysid]:
                    return None
                entry = await super()._upload(link, logger, job)
        finally:
            self.awards_open -= job.kind == "award"
        if job.kind == "award" and entry["ok"]:  # back onto the engine's track after the leg
            t_end = float(job.payload.sim_leg.t[-1])
            idle = Idle(t_end, job.payload.event, self._end_s(), None)
            self.due.append(UploadJob(t_end, (2, t_end), "idle", job.sched, idle, job.gen))
            self.due.sort()
        return entry

    # --- the report --------------------------------------------------------------------------
    def _result(self, lag_events: int, wall_s: float) -> HilResult:
        tracks = self.recorder.tracks()
        flown = {s: (tr.times_s - self.route_t0 + self.t_route0, tr.positions) for s, tr in tracks.items()}
        lost = {self.world.uavs[i].id for i in self.engine.lost}
        released = {(a.target_id, self.world.uavs[a.uav].id) for a in self.engine.released}
        awards = [e for e in self.award_events.values() if e["target"] in self.targets]
        judged = [e for e in awards if e["uav"] not in lost and e["t_s"] <= self.t_end
                  and (e["target"], e["uav"]) not in released]  # fmt: skip
        engine_tracks = {s.uav.id: s.track for s in self.sched.values()}
        limits = (self.options.max_time_error_s, self.options.max_angle_error_deg)
        rows, missing = task_rows(self.world, judged, flown, self.flown_legs, engine_tracks, limits)
        missing += [f"{t}: a task was still undone when the window closed at {self.t_end:.1f} s"
                    for t in self.targets if self.engine.outcomes[t].t_done_s is None]  # fmt: skip
        add_prediction_errors(self.uploads, flown)
        result = HilResult(
            rows, self.uploads, self.mcap_path, self.t_start, wall_s, lag_events, self.failures + missing,
            flown, self.flown_legs,
        )  # fmt: skip
        result.events = list(self.engine.events)
        result.formations = formation_rows(self.sim.events, self.engine.events, self.targets)
        result.lost_awards = [e for e in awards if e["uav"] in lost]
        result.released_awards = [e for e in awards if (e["target"], e["uav"]) in released]
        result.tender_compute_s = list(self.engine.live_compute_s)
        result.tender_cpu_s = list(self.engine.live_cpu_s)
        return result


async def run_online(scenario: Scenario, options: HilOptions, vehicles_for: VehiclesFor) -> HilResult:
    """The online coalition run (module docstring) on ``vehicles_for``'s fleet."""
    return await run_coalition_hil(scenario, options, vehicles_for, OnlineRun)
