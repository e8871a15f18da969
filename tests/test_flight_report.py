"""The flight report PNG: drawn from a plan, flown tracks and the conformance rows it judges."""

from __future__ import annotations

import numpy as np
from matplotlib.image import imread

from gcs_planner.conformance import Track, conformance_report
from gcs_planner.flight_report import write_flight_report
from gcs_planner.geo import Origin
from gcs_planner.plan import Plan, VehiclePlan

FAILED_ROW = np.array([0xF8, 0xD0, 0xD0]) / 255


def plan_and_tracks(offset_m: float) -> tuple[Plan, dict[int, Track]]:
    vehicles, tracks = [], {}
    for s in (1, 2):
        wps = np.array([[0.0, 40.0 * s, 20.0], [300.0, 40.0 * s, 20.0]])
        vehicles.append(VehiclePlan(f"uav{s}", s, wps, [0.0, 30.0], [0.0, 10.0], wps, [0.0, 30.0]))
        t = np.linspace(0.0, 30.0, 61)
        pos = np.column_stack([10.0 * t, np.full_like(t, 40.0 * s), np.full_like(t, 20.0)])
        if s == 2:
            pos[20:40, 1] += offset_m  # uav2 leaves its path mid-route
        tracks[s] = Track(t, pos, mission_completed=True)
    return Plan(Origin(47.4, 8.5, 400.0), "straight", vehicles), tracks


def test_report_draws_the_conformance_judgement(tmp_path):
    for offset, expect_red in ((0.0, False), (25.0, True)):
        plan, tracks = plan_and_tracks(offset)
        reports = conformance_report(plan, tracks, {1: 5.0, 2: 5.0}, [], [], max_cross_track_m=10.0)
        assert [r.passed for r in reports] == [True, not expect_red]
        path = write_flight_report(
            tmp_path / f"r{offset:g}.png", plan, tracks, reports, max_cross_track_m=10.0
        )
        image = imread(path)[..., :3]
        assert image.shape[:2] == (900, 1350)
        red = np.all(np.abs(image - FAILED_ROW) < 0.02, axis=-1).sum()
        assert (red > 1000) == expect_red  # the failing row is shaded
