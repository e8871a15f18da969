"""A multirotor flying the waypoint samples of Dubins arcs keeps its schedule: a mock tuned to its
plan (sitl_mock.plan_fleet.airframe_for) has the acceleration to hold the planned speed through
them and to catch up there, so schedule keeping holds it within the conformance bound."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from gcs_planner.core import lockstep
from gcs_planner.flight import FlyOptions, fly
from gcs_planner.planning import load_scenario, plan_scenario
from sitl_mock.plan_fleet import MockVehicles

MISSIONS = Path(__file__).resolve().parents[1] / "missions"
SPEED_MPS, RADIUS_M, SAMPLE_S = 12.0, 20.0, 0.8  # swarm500's vehicles and waypoint spacing


def _s_turns(half_turns: int = 8, z: float = 30.0) -> np.ndarray:
    """Waypoints every SAMPLE_S of flight along alternating half circles of RADIUS_M (an S chain)."""
    step = SPEED_MPS * SAMPLE_S / RADIUS_M
    n = int(np.pi / step)
    points, pos, heading = [np.zeros(2)], np.zeros(2), 0.0
    for k in range(half_turns):
        side = 1.0 if k % 2 == 0 else -1.0
        centre = pos + RADIUS_M * side * np.array([-np.sin(heading), np.cos(heading)])
        a0 = np.arctan2(pos[1] - centre[1], pos[0] - centre[0])
        a = a0 + side * step * np.arange(1, n + 1)
        points += list(centre + RADIUS_M * np.column_stack([np.cos(a), np.sin(a)]))
        pos, heading = points[-1], heading + side * n * step
    xy = np.array(points)
    return np.column_stack([xy, np.full(len(xy), z)])


@pytest.mark.parametrize("autopilot", ["ardupilot", "px4"])
def test_a_multirotor_on_arc_samples_keeps_its_schedule(tmp_path, autopilot):
    scenario = load_scenario(MISSIONS / "straight_4uav.toml")
    plan = plan_scenario(scenario)
    wp = _s_turns()
    t = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(wp, axis=0), axis=1) / SPEED_MPS)])
    plan.vehicles = [replace(plan.vehicles[0], waypoints=wp, times_s=t, speeds_mps=np.full(len(t), SPEED_MPS),
                             path=wp, path_times_s=t, turn_radius_m=RADIUS_M)]  # fmt: skip
    vehicles = MockVehicles(plan.vehicles, plan.origin, autopilot=autopilot)
    result = lockstep.run(
        fly(scenario, plan, FlyOptions(out_dir=tmp_path, rrd=False), vehicles), vehicles.lockstep
    )
    report = result.reports[0]
    assert report.passed, report.failures
    assert abs(report.schedule_error_s) < 1.0  # 9 s late with v^2 / R (1440 degrees of turning in 38 s)
