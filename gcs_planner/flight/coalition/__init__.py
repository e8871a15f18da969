"""The coalition strategy of the flight runner (seed 003): awards flown on legs planned from live telemetry.

Online (``online_run.OnlineRun``, the CLI's default) the contract net runs in flight on the
vehicles' telemetry; offline (``run.OfflineRun``) its decisions come from the simulation. Either
way each award's leg is planned from the vehicle's newest reports and uploaded while it flies.
docs/coalition.md ("HIL run", "Online run") says how and why. Modules: ``live_legs`` (live state
and the legs planned from it), ``missions`` (tracks and legs as VehiclePlans), ``tracks`` (sampled
tracks), ``report`` (one row per award), ``run`` (the upload queue and schedule keeping),
``online`` and ``online_run`` (the contract net on live state and its flight).
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
