"""``fly``: a static plan flown by the one runner (flight/runner.py) and judged by conformance.

Mirrors the seed papers' HIL setup (planner -> datalink -> flight controller -> telemetry ->
display): the plan's missions are uploaded to every vehicle concurrently, the fleet takes off and
each route starts at its planned time, and the flown tracks are checked against the plan
(gcs_planner.safety.conformance: cross-track, separation, obstacles, manned traffic, schedule).

Choices:
- Two-phase start (gcs_planner.flight.ops), so that the plan's timing (and with it the planned
  separation) holds in the air: take off, then start each route at the common start plus its
  planned delay, less the time it loses accelerating (delayed take-off as a timed start; the
  mission's NAV_DELAY is then skipped). Fixed wings climb straight into their routes.
- While the routes run, a ScheduleKeeper (gcs_planner.flight.timekeeping) sends each vehicle ground
  speed set-points (MAV_CMD_DO_CHANGE_SPEED) that hold it to the plan's timing; autopilots slow
  for corners and would otherwise fall behind the schedule the separation was planned on.
  ``keep_schedule=False`` flies the bare missions.
- A mission is complete when the vehicle reports it (MISSION_CURRENT COMPLETE or the last item
  reached) where its track shows it at the mission's end (flight.ops.wait_until_done).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from gcs_planner.analysis.flight_report import write_flight_report
from gcs_planner.autopilots import quirks_named
from gcs_planner.core.errors import UserError
from gcs_planner.core.fleet_ids import network_of, wire_sysid
from gcs_planner.flight.ops import accel_lead_s, build_missions, wait_until_done
from gcs_planner.flight.runner import Flight, RunOptions, networks, run_flight
from gcs_planner.flight.timekeeping import ScheduleKeeper
from gcs_planner.flight.vehicles import VehicleSource
from gcs_planner.geometry.ramp import ramp_loss_s
from gcs_planner.mavlink.fleet import VehicleResult
from gcs_planner.mavlink.transfer import Timing
from gcs_planner.missions.items import AUTOPILOTS
from gcs_planner.model.plan import Plan
from gcs_planner.model.scenario import Scenario
from gcs_planner.safety.conformance import (
    MAX_SCHEDULE_ERROR_S,
    MovingObstacle,
    VehicleReport,
    conformance_report,
)

__all__ = ["FlyOptions", "FlyResult", "StaticPlan", "check_flight", "fly", "manned_traffic"]


@dataclass
class FlyOptions:
    out_dir: Path = Path("out")
    workers: int = 8
    tlog: bool = False
    rrd: bool = True
    max_cross_track_m: float = 15.0
    max_schedule_error_s: float = MAX_SCHEDULE_ERROR_S
    drift_mps: dict[int, tuple[float, float]] = field(default_factory=dict)  # mock fault injection
    timeout_factor: float = 2.0
    keep_schedule: bool = True
    live: object | None = None  # a rerun.RecordingStream: the Rerun views streamed while flying
    in_flight: int = Timing.window  # mission items sent ahead of a vehicle's requests


@dataclass
class FlyResult:
    reports: list[VehicleReport]
    uploads: dict[int, VehicleResult]
    mcap_path: Path
    rrd_path: Path | None
    tlog_paths: list[Path]  # one .tlog per MAVLink network (FlightLogger), empty without --tlog
    wall_time_s: float
    end_states: dict[int, str] = field(default_factory=dict)  # safe end: sysid -> what was done
    report_path: Path | None = None  # the flight report PNG (analysis/flight_report.py)
    log_error: str | None = None  # the flight log could not be written (full disk); the report stands
    frames_received: int = 0  # MAVLink frames the link delivered (every one is handed to the log)
    interrupted: str | None = None  # the signal that ended the flight early (SIGINT, SIGTERM, SIGHUP)

    @property
    def passed(self) -> bool:
        uploaded = all(u.ok for u in self.uploads.values())
        return all(r.passed for r in self.reports) and uploaded and self.interrupted is None


async def fly(
    scenario: Scenario,
    plan: Plan,
    options: FlyOptions,
    vehicles: VehicleSource,
    progress: Callable[[str, float, float], None] | None = None,
) -> FlyResult:
    """Upload, start and record the whole fleet; return the per-vehicle conformance report.

    ``progress(stage, done, total)`` reports "upload" (vehicles) and "fly" (completed vehicles);
    ``progress("wait", sysid, reason)`` while a vehicle is not ready to arm.
    """
    run = RunOptions(
        options.out_dir,
        options.workers,
        options.tlog,
        options.timeout_factor,
        options.live,
        options.in_flight,
    )
    return await run_flight(StaticPlan(scenario, plan, options), vehicles, run, progress)


def manned_traffic(scenario: Scenario, route_t0_s: float) -> list[MovingObstacle]:
    """The scenario's [[manned]] aircraft as constant-velocity traffic from the route start.

    Their bound is the planner's ``safety_m`` when given, else the largest vehicle separation.
    """
    bound = float(
        scenario.planner.get("safety_m", max((v.separation_m for v in scenario.vehicles), default=0))
    )
    return [
        MovingObstacle(
            str(m.get("id", f"manned{k}")),
            tuple(m["position_m"]),
            tuple(m["velocity_mps"]),
            route_t0_s,
            bound,
        )
        for k, m in enumerate(scenario.raw.get("manned", []))
        if "position_m" in m and "velocity_mps" in m
    ]


def check_flight(plan: Plan) -> None:
    """What must hold before anything is sent: one sysid in 1..255 per vehicle (per network: fleet
    ids, mavlink/networks.py), and every vehicle's mission valid in both autopilots' conventions."""
    sysids = [vp.sysid for vp in plan.vehicles]
    if any(wire_sysid(s) == 0 for s in sysids) or len(set(sysids)) != len(sysids):
        raise UserError(f"every vehicle needs its own MAVLink sysid in 1..255 to fly, got {sysids}")
    empty = sorted(set(range(networks(plan))) - {network_of(s) for s in sysids})
    if empty:
        raise UserError(f"network {empty[0]} has no vehicle; number the networks 0, 1, ... without gaps")
    for conventions in AUTOPILOTS:
        build_missions(plan, {s: quirks_named(conventions) for s in sysids})


class StaticPlan:
    """The FlightStrategy of a static plan: every mission known before take-off, flown to its end
    on the plan's schedule, judged by conformance."""

    command = "fly"
    start_bound_m = 0.0  # each vehicle's own bound (starts.py)
    speed_factor = 1.0  # the plan's own speeds
    limit_hint = ""
    climb_into_route = True

    def __init__(self, scenario: Scenario, plan: Plan, options: FlyOptions) -> None:
        self.scenario, self.plan, self.options = scenario, plan, options
        self.schedule_bound_s = options.max_schedule_error_s

    def check(self, vehicles: VehicleSource) -> None:
        check_flight(self.plan)
        sysids = [vp.sysid for vp in self.plan.vehicles]
        unknown = sorted(set(self.options.drift_mps) - set(sysids))
        if unknown:
            raise UserError(f"drift for sysid {unknown[0]}, which is not in the plan {sorted(sysids)}")
        if self.options.drift_mps and not vehicles.simulated:
            raise UserError("--drift injects a fault into mock vehicles; it cannot act on connected vehicles")

    def attach(self, flight: Flight) -> None:
        pass

    async def prepare(self, flight: Flight) -> None:
        for sysid, drift in self.options.drift_mps.items():
            flight.vehicles.set_drift(sysid, *drift)

    def leads(self, flight: Flight) -> tuple[float, dict[int, float]]:
        """Each route starts early by its acceleration lead (flight.ops.accel_lead_s): a mock tuned to
        the plan at its airframe's acceleration; a vehicle that flies by its own parameters on the
        S-curve they give, after its autopilot's start latency (docs/real-autopilots.md). Route
        time 0 after the largest."""
        leads = {vp.sysid: accel_lead_s(vp, *_ramp(flight, vp.sysid), _latency_s(flight, vp.sysid))
                 for vp in self.plan.vehicles}  # fmt: skip
        return max(leads.values()), leads

    async def fly(self, flight: Flight) -> None:
        """Keep the schedule until every mission is done (or the plan's time x timeout_factor)."""
        keeper = None
        if self.options.keep_schedule:
            keeper = ScheduleKeeper()
            for vp in self.plan.vehicles:
                ramp = _ramp(flight, vp.sysid)
                settle_s = ramp_loss_s(vp.first_leg_speed_mps, *ramp)  # >= where it ends
                change = (keeper.max_factor - 1.0) * vp.first_leg_speed_mps  # its largest speed change
                response_s = 2.0 * ramp_loss_s(change, *ramp) + _latency_s(flight, vp.sysid)
                keeper.add(vp, settle_s, response_s)
            for sysid, lim in flight.limits.items():
                keeper.limit(sysid, lim.min_mps, lim.max_mps)
        await wait_until_done(
            flight.link, flight.recorder, flight.status, self.plan, flight.speedup,
            self.options.timeout_factor, flight.progress, keeper, flight.route_t0, flight.quirks,
        )  # fmt: skip

    def done(self, flight: Flight) -> bool:
        return all(flight.recorder.completed.get(s, False) for s in flight.sysids)

    def result(self, flight: Flight, wall_s: float) -> FlyResult:
        """The conformance report, the flight report PNG and the .rrd of the flown log."""
        plan, scenario, options = self.plan, self.scenario, self.options
        tracks = flight.recorder.tracks()
        reports = conformance_report(
            plan,
            tracks,
            {v.sysid: v.separation_m for v in scenario.vehicles},
            scenario.cylinders,
            scenario.hemispheres,
            manned_traffic(scenario, flight.route_t0_s),
            max_cross_track_m=options.max_cross_track_m,
            route_t0_s=flight.route_t0 or None,
            max_schedule_error_s=options.max_schedule_error_s,
            site=scenario.site,
            ramps={vp.sysid: _ramp(flight, vp.sysid) for vp in plan.vehicles},
        )
        for r in reports:
            upload = flight.uploads.get(r.sysid)
            if upload is not None and not upload.ok:
                r.failures.insert(0, f"upload failed: {upload.error}")
            impossible = flight.recorder.impossible.get(r.sysid, 0)
            if impossible:
                r.failures.append(f"{impossible} impossible positions reported (ignored)")
        report_path = write_flight_report(
            options.out_dir / "report.png", plan, tracks, reports, scenario, options.max_cross_track_m
        )
        rrd_path = None
        if options.rrd and not flight.log_errors:
            from gcs_planner.telemetry import log_flight_to_rerun, read_flight

            rrd_path = options.out_dir / "flight.rrd"
            log_flight_to_rerun(read_flight(flight.mcap_path), rrd_path)
        log_error = flight.log_errors[0] if flight.log_errors else None
        return FlyResult(
            reports, flight.uploads, flight.mcap_path, rrd_path, flight.tlog_paths, wall_s, flight.end_states,
            report_path, log_error, flight.frames_received,
        )  # fmt: skip


def _latency_s(flight: Flight, sysid: int) -> float:
    """From a command to the vehicle moving by it: its autopilot's, where it flies by its own
    parameters (AutopilotQuirks.start_latency_s), else none (a mock tuned to the plan)."""
    return flight.quirks[sysid].start_latency_s if flight.vehicles.own_parameters else 0.0


def _ramp(flight: Flight, sysid: int) -> tuple[float, float]:
    """(acceleration, jerk) of the vehicle's speed ramps: its own S-curve parameters where it flies
    by them and has them (limits.read_ramps), else its airframe's acceleration."""
    if not flight.vehicles.own_parameters or sysid not in flight.ramps:
        return flight.vehicles.accel_mps2(sysid), math.inf
    return flight.ramps[sysid]
