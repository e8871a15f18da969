"""Flights: the one runner (runner.py) and the static plan it flies for ``fly`` (static_plan.py);
the coalition's online task plan is the other strategy (gcs_planner.flight.coalition)."""

from gcs_planner.flight.runner import (
    Flight,
    FlightStrategy,
    RunOptions,
    check_networks,
    end_summary,
    networks,
    run_flight,
)
from gcs_planner.flight.static_plan import (
    FlyOptions,
    FlyResult,
    StaticPlan,
    check_flight,
    fly,
    manned_traffic,
)

__all__ = [
    "Flight", "FlightStrategy", "FlyOptions", "FlyResult", "RunOptions", "StaticPlan", "check_flight",
    "check_networks", "end_summary", "fly", "manned_traffic", "networks", "run_flight",
]  # fmt: skip
