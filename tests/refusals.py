"""What a vehicle's refusal of a mission transfer looks like to the client."""

from gcs_planner.mavlink import errors
from gcs_planner.wire.enums import MissionResult


def refused(exc: BaseException | None, result: MissionResult) -> bool:
    """``exc`` is the one MissionError, carrying the vehicle's ``result``."""
    return type(exc) is errors.MissionError and exc.result is result
