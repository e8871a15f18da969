"""Shared test fixtures."""

from __future__ import annotations

from collections.abc import Callable

import pytest

from gcs_planner.wire.types import MissionItem

MissionOf = Callable[..., list[MissionItem]]


@pytest.fixture
def mission_of() -> MissionOf:
    """``mission_of(n, lat=..., z=...)``: n MAV_CMD_NAV_WAYPOINT items (frame GLOBAL_RELATIVE_ALT_INT)
    stepping north-east from Zurich, item 0 current: a plain mission for protocol tests."""

    def make(n: int, lat: int = 473_977_000, z: float = 30.0) -> list[MissionItem]:
        return [
            MissionItem(seq=i, frame=3, command=16, current=int(i == 0), x=lat + 41 * i, y=85_455_000, z=z)
            for i in range(n)
        ]

    return make
