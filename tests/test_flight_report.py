"""The flight report PNG: drawn from a plan, flown tracks and the conformance rows it judges."""

from __future__ import annotations

import numpy as np
from matplotlib.image import imread

from gcs_planner.analysis.flight_report import write_flight_report
from gcs_planner.core.geo import Origin
from gcs_planner.model.plan import Plan, VehiclePlan
from gcs_planner.safety.conformance import Track, conformance_report

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


def fleet(count: int, off_route: set[int]) -> tuple[Plan, dict[int, Track]]:
    vehicles, tracks = [], {}
    t = np.linspace(0.0, 30.0, 61)
    for s in range(1, count + 1):
        wps = np.array([[0.0, 20.0 * s, 20.0], [300.0, 20.0 * s, 20.0]])
        vehicles.append(VehiclePlan(f"uav{s}", s, wps, [0.0, 30.0], [0.0, 10.0], wps, [0.0, 30.0]))
        pos = np.column_stack([10.0 * t, np.full_like(t, 20.0 * s), np.full_like(t, 20.0)])
        pos[20:40, 2] += 0.01 * s + (30.0 if s in off_route else 0.0)  # each its own error
        tracks[s] = Track(t, pos, mission_completed=True)
    return Plan(Origin(47.4, 8.5, 400.0), "straight", vehicles), tracks


def test_the_report_names_every_vehicle_of_a_fleet_of_40_and_500(tmp_path):
    """Past TABLE_ROWS the table keeps the failing and the worst rows and one line names the rest:
    every vehicle appears in the table or in that line; the PNG is drawn at 500 too."""
    from gcs_planner.analysis.flight_report import TABLE_ROWS, table_rows

    for count, off_route in ((40, {7, 33}), (500, {3, 250, 499})):
        plan, tracks = fleet(count, off_route)
        separation = {s: 5.0 for s in tracks}
        reports = conformance_report(plan, tracks, separation, [], [], max_cross_track_m=10.0)
        shown, more = table_rows(reports)
        assert len(shown) == TABLE_ROWS and {r.sysid for r in shown} >= off_route  # failing ones listed
        assert [r.sysid for r in shown] == sorted(r.sysid for r in shown)
        named = {r.sysid for r in shown}
        for part in more.split("sysid ")[1:]:
            for run in part.split(")")[0].split(";")[0].split(", "):
                a, _, b = run.partition("-")
                named |= set(range(int(a), int(b or a) + 1))
        assert named == set(tracks), sorted(set(tracks) - named)
        worst_passing = max((r for r in reports if r.passed), key=lambda r: r.cross_track_max_m)
        assert worst_passing.sysid in {r.sysid for r in shown}  # then the largest errors
        path = write_flight_report(
            tmp_path / f"fleet{count}.png", plan, tracks, reports, max_cross_track_m=10.0
        )
        assert imread(path).shape[:2] == (900, 1350)


def test_past_ten_vehicles_every_vehicle_has_its_own_colour():
    from gcs_planner.telemetry.colors import vehicle_color

    assert vehicle_color(1)[:3] == (31, 119, 180)  # the first ten keep Tableau-10
    assert len({vehicle_color(s) for s in range(1, 501)}) == 500
