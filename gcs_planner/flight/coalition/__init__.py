"""Coalition HIL run (seed 003): coalition awards flown by mock vehicles on legs planned from live telemetry.

The paper's hardware-in-the-loop test pushes each coalition's new paths to the vehicles while the
swarm flies. Two runs share this package:

- **Online** (``online_run.OnlineRun``, ``online.OnlineContractNet``; the CLI's default): the
  contract net itself runs in flight on the vehicles' telemetry; see those modules.
- **Offline** (this docstring, ``run``): the decisions come from the simulation. The coalition
  simulation (gcs_planner.planning.coalition) runs first for the seed. Its contract net decides
  every award: the winning vehicle, the target and task, the awarded time and the attack (or
  assessment) angle. The run keeps those decisions and logs them at their times.
- **The flown legs come from live state.** When an award's mission is about to be uploaded, the
  vehicle's leg is planned from its own newest GLOBAL_POSITION_INT reports, not from the
  simulated state: position, course and ground speed of the newest report, turn rate fitted over
  the last ``FIT_S`` of course (``live_legs.live_state``). That turn is propagated to the leg start
  t0 = now + the upload estimate + ``START_AHEAD_S``. From that pose the leg goes to the award's
  stand-off entry pose (strike) or assessment-arc start pose (assess), arriving at the awarded
  time at the awarded angle (``live_legs.plan_live_leg``). It uses the coalition path functions as sim.py's
  ``_replan`` does: ``paths.min_route`` for safe-point threat avoidance (threats known at the
  award), ``paths.timed_route`` for radius stretching with detour and loiter fallbacks,
  ``paths.sample_segments``, and for an assessment ``paths.arc_leg`` after the transit. The
  report gives, per award, the distance and heading between the simulated and the flown pose at
  the flown leg's start.

Flow:
1. Every vehicle awarded a task (of the chosen targets and UAVs) is a mock fixed wing; the fleet
   runs in its own process (the "mock-process" vehicle source, sitl_mock.plan_fleet). Its first
   mission is a straight ``LEAD_IN_S`` lead-in to its simulated position at the window start
   ``t_start`` = first award - ``lead_s``, then its simulated pre-award track (idle loiter, recon)
   up to its simulated leg start t_e^s, then ``PRE_AWARD_EXTEND_S`` more at the same turn rate (the
   loiter the bids predicted, flown until the award's mission starts). Its home is south of the
   lead-in start by the take-off's ground run (the mock climbs heading north), so the climb ends
   where the route starts. ``HilOptions.offset_m`` moves a vehicle's first mission (tests: its live
   state then differs from the simulated one).
2. The fleet takes off (flight.ops.take_off_all) and every route starts at once at route time 0 =
   scenario time ``t_start - LEAD_IN_S`` (flight.ops.start_routes).
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
   ``HilOptions.replay_legs`` uploads the simulation's own legs instead, for comparison (the test
   shows it missing where the live leg hits).
4. A ScheduleKeeper holds every vehicle to its current mission's timing (it is replaced at each
   upload), as in ``gcs-planner fly``; it gets the path every ``KEEPER_SAMPLE_S`` so that its
   60-sample look-ahead stays shorter than a loiter lap.
5. Report, one row per award (``report.measure_task``): the flown arrival at the goal point (strike:
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
become missions (``tracks.drop_spikes``). The mock fleet (sitl_mock.plan_fleet.MockVehiclesProcess)
climbs fast (the climb is not part of the measurement and a real fleet would be airborne before
the scenario starts) and banks enough for the minimum turn radius at the schedule keeper's top
speed, so catching up does not widen turns.

Modules, one job each:

- ``live_legs``: live state from telemetry (LiveState, live_state, Telemetry) and the legs planned
  from it (timed_leg, plan_live_leg, rejoin_leg, the onto-sim-leg fallback);
- ``missions``: simulated tracks and legs turned into VehiclePlans (waypoint selection, speeds,
  the per-UAV schedules, award and idle missions);
- ``tracks``: sampled-track helpers (slice, pose at a time, turn continuation, spike removal);
- ``report``: TaskRow, measure_task, the report rows and table;
- ``run``: HilOptions, HilResult and run_coalition_hil (the upload queue and schedule keeping);
- ``online``: the contract net on live state; ``online_run``: the online flight (OnlineRun, Fault).
"""

from gcs_planner.flight.coalition.live_legs import LiveState, live_state, plan_live_leg
from gcs_planner.flight.coalition.report import TaskRow, format_strike_report, measure_task
from gcs_planner.flight.coalition.run import UPLOAD_SAFETY, HilOptions, HilResult, run_coalition_hil

__all__ = [
    "UPLOAD_SAFETY",
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
