import numpy as np
import pytest

from gcs_planner.core.geo import Origin
from gcs_planner.model.plan import Plan, VehiclePlan
from gcs_planner.model.scenario import Cylinder
from gcs_planner.safety.conformance import (
    MovingObstacle,
    Track,
    conformance_report,
    format_report,
    point_to_polyline_m,
    schedule_errors_s,
)


def _vehicle(sysid, y, speed=10.0):
    wp = np.array([[0.0, y, 20.0], [200.0, y, 20.0]])
    t = np.array([0.0, 200.0 / speed])
    return VehiclePlan(f"uav{sysid}", sysid, wp, t, [speed, speed], wp, t)


def _flown(vp, offset=(0.0, 0.0, 0.0), completed=True):
    t = np.linspace(0, vp.path_times_s[-1], 201)
    pos = np.stack([np.interp(t, vp.path_times_s, vp.path[:, k]) for k in range(3)], axis=1)
    return Track(t, pos + np.asarray(offset), completed)


def test_point_to_polyline_matches_brute_force():
    rng = np.random.default_rng(3)
    poly = rng.uniform(-50, 50, (7, 3))
    pts = rng.uniform(-60, 60, (300, 3))
    dense = np.concatenate(
        [a + np.linspace(0, 1, 2001)[:, None] * (b - a) for a, b in zip(poly[:-1], poly[1:])]
    )
    brute = np.linalg.norm(pts[:, None] - dense[None], axis=2).min(axis=1)
    np.testing.assert_allclose(point_to_polyline_m(pts, poly, chunk=64), brute, atol=0.06)


def test_report_passes_on_plan_and_fails_on_drift_separation_obstacle_and_incomplete():
    plan = Plan(Origin(47.0, 8.0, 400.0), "test", [_vehicle(1, 0.0), _vehicle(2, 30.0)])
    good = {v.sysid: _flown(v) for v in plan.vehicles}
    reports = conformance_report(plan, good, {1: 5.0, 2: 5.0})
    assert all(r.passed for r in reports), format_report(reports)
    assert reports[0].min_separation_m == pytest.approx(30.0, abs=1e-6)
    assert reports[0].cross_track_max_m < 1e-6

    drift = {1: _flown(plan.vehicles[0], offset=(0, 8, 0)), 2: good[2]}
    r = conformance_report(plan, drift, {1: 5.0, 2: 5.0}, max_cross_track_m=5.0, acceptance_m=10.0)
    assert not r[0].passed and "cross-track" in r[0].failures[0] and r[1].passed

    close = {1: good[1], 2: _flown(plan.vehicles[1], offset=(0, -27, 0))}
    r = conformance_report(plan, close, {1: 5.0, 2: 5.0}, max_cross_track_m=50.0, acceptance_m=40.0)
    assert any("separation" in f for f in r[0].failures) and r[0].min_separation_m == pytest.approx(3.0)

    tower = [Cylinder(x=100.0, y=0.0, radius_m=2.0, z_max_m=50.0)]
    r = conformance_report(plan, good, {1: 5.0, 2: 5.0}, cylinders=tower)
    assert any("obstacle" in f for f in r[0].failures) and r[1].passed

    r = conformance_report(plan, {1: _flown(plan.vehicles[0], completed=False)}, {1: 5.0, 2: 5.0})
    assert r[0].failures == ["mission not completed"] and r[1].failures == ["never airborne"]
    assert "PASS" in format_report(conformance_report(plan, good, {1: 5.0, 2: 5.0}))


def test_manned_traffic_crossing_a_track_is_reported():
    plan = Plan(Origin(47.0, 8.0, 400.0), "test", [_vehicle(1, 0.0)])
    flown = {1: _flown(plan.vehicles[0])}
    # crosses y = 0 at x = 100 when uav1 is there (t = 10 s), 5 m above it
    heli = MovingObstacle("heli", (100.0, -300.0, 25.0), (0.0, 30.0, 0.0), 0.0, 10.0)
    r = conformance_report(plan, flown, {1: 5.0}, traffic=[heli])
    assert r[0].min_traffic_distance_m == pytest.approx(5.0, abs=0.5)
    assert any("heli within" in f for f in r[0].failures)
    late = MovingObstacle("heli", (100.0, -300.0, 25.0), (0.0, 30.0, 0.0), 30.0, 10.0)
    assert conformance_report(plan, flown, {1: 5.0}, traffic=[late])[0].passed


def _timed(vp, stretch=1.0, t0=100.0, hover_s=5.0):
    """``vp`` flown from route time ``t0``, every planned time x ``stretch``, after hovering at the start."""
    t_plan = np.linspace(0, vp.path_times_s[-1], 201)
    pos = np.stack([np.interp(t_plan, vp.path_times_s, vp.path[:, k]) for k in range(3)], axis=1)
    hover = np.linspace(t0 - hover_s, t0, 20, endpoint=False)
    times = np.concatenate([hover, t0 + t_plan * stretch])
    return Track(times, np.concatenate([np.repeat(pos[:1], len(hover), axis=0), pos]), True)


@pytest.mark.parametrize(
    ("stretch", "passed", "words"),
    [(1.0, True, ""), (1.03, True, ""), (1.3, False, "s late"), (0.1, False, "s early")],
)
def test_the_schedule_is_bounded_in_time_as_well_as_space(stretch, passed, words):
    """A deconflicted plan is separated in time: a route flown on the planned line but 30 % late (or
    at a mock's 10x) fails; the error is reported signed, + late."""
    plan = Plan(Origin(47.0, 8.0, 400.0), "test", [_vehicle(1, 0.0)])  # 20 s route
    flown = {1: _timed(plan.vehicles[0], stretch)}
    r = conformance_report(plan, flown, {1: 5.0}, route_t0_s={1: 100.0})[0]
    assert r.passed is passed, r.failures
    assert all(words in f for f in r.failures if "schedule" in f)
    assert r.schedule_error_s == pytest.approx(20.0 * (stretch - 1.0), abs=0.4)  # + acceptance radius
    assert "late_s" in format_report([r])


def test_a_route_that_loops_back_near_a_point_is_timed_at_the_pass_due_then():
    """East through (50, 0), a 14 m loop that stays near it, and east through it again: flown
    0.5 s late, the first pass 1 m off the line and the second exactly on it. Every point is
    0.5 s late; taking the nearest sample of the whole stretch timed the first pass at the second."""
    arc = np.linspace(-np.pi / 2, np.pi / 2, 9)
    back = np.linspace(np.pi / 2, 3 * np.pi / 2, 9)
    out_loop = np.c_[60 + 4 * np.cos(arc), 4 + 4 * np.sin(arc)]
    back_loop = np.c_[40 + 4 * np.cos(back), 4 + 4 * np.sin(back)]
    xy = np.vstack([[[0.0, 0.0], [60.0, 0.0]], out_loop, [[40.0, 8.0]], back_loop, [[100.0, 0.0]]])
    path = np.c_[xy, np.full(len(xy), 20.0)]
    t = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1) / 10.0)])
    vp = VehiclePlan("uav1", 1, path, t, np.full(len(t), 10.0), path, t)
    flown_t = np.arange(0.0, t[-1], 0.05)
    pos = np.stack([np.interp(flown_t, t, path[:, k]) for k in range(3)], axis=1)
    pos[flown_t < t[1], 1] += 1.0  # the first pass along y = 0, 1 m to the side
    errors = schedule_errors_s(Track(100.5 + flown_t, pos), vp, 100.0, near_m=18.0)
    assert np.isfinite(errors).all()
    np.testing.assert_allclose(errors, 0.5, atol=0.06)


def test_a_completion_without_the_route_flown_never_passes():
    """One report of completion and a track that jumps to the goal: the route was not flown."""
    plan = Plan(Origin(47.0, 8.0, 400.0), "test", [_vehicle(1, 0.0)])
    vp = plan.vehicles[0]
    jump = Track(np.array([100.0, 100.05, 100.1]), np.array([vp.path[0], vp.path[0], vp.path[-1]]), True)
    r = conformance_report(plan, {1: jump}, {1: 5.0}, route_t0_s={1: 100.0})[0]
    assert not r.passed and any("schedule" in f or "not flown in order" in f for f in r.failures), r.failures


def test_nan_is_never_within_a_bound():
    plan = Plan(Origin(47.0, 8.0, 400.0), "test", [_vehicle(1, 0.0)])
    flown = _flown(plan.vehicles[0])
    flown.positions[50:60, 0] = np.nan  # impossible positions (e.g. lat 91 deg) dropped to NaN
    r = conformance_report(plan, {1: flown}, {1: 5.0})[0]
    assert not r.passed and any("cross-track" in f for f in r.failures)


def test_the_report_says_where_a_landing_touched_down_against_the_plan():
    """A fixed wing's land point is one 5-degree glide ahead of its last waypoint (an approach it can
    fly); the report measures the touchdown from it."""
    from gcs_planner.model.plan import LAND_GLIDE_DEG, land_point

    vp = _vehicle(1, 0.0)
    vp.vehicle_type = "fixed_wing"
    run = 20.0 / np.tan(np.radians(LAND_GLIDE_DEG))
    np.testing.assert_allclose(land_point(vp), [200.0 + run, 0.0, 0.0])
    flown = _flown(vp)
    landing = np.array([[200.0 + run / 2, 0.0, 10.0], [200.0 + run + 40.0, 0.0, 0.0]])
    times = np.r_[flown.times_s, flown.times_s[-1] + np.array([10.0, 20.0])]
    track = Track(times, np.vstack([flown.positions, landing]), True)
    plan = Plan(Origin(47.0, 8.0, 400.0), "test", [vp])
    r = conformance_report(plan, {1: track}, {1: 5.0})[0]
    assert r.touchdown_m == pytest.approx(40.0) and r.passed
    assert np.isnan(conformance_report(plan, {1: flown}, {1: 5.0})[0].touchdown_m)  # never came down


RAMP = {1: (3.0, np.inf)}


@pytest.mark.parametrize(("vehicle_type", "ramps", "passed"), [
    ("multirotor", None, False), ("multirotor", RAMP, True), ("fixed_wing", RAMP, False),
])  # fmt: skip
def test_a_multirotor_on_its_speed_ramps_is_on_time(vehicle_type, ramps, passed):
    """A copter that leaves its start from the hover v / 2a = 1.67 s early (the route lead), cruises
    on schedule and brakes at 3 m/s^2 for its last waypoint is early at the start and late at the
    end by up to 1.67 s against a plan at constant speed: with its ramp known that is its ramps,
    not a schedule error (a plane flies through its route's ends, so no ramp is allowed for)."""
    vp = _vehicle(1, 0.0)  # 200 m at 10 m/s
    vp.vehicle_type = vehicle_type
    plan = Plan(Origin(47.0, 8.0, 400.0), "test", [vp])
    done = np.linspace(0.0, 200.0, 401)
    ramp_m = 10.0**2 / 6.0
    times = 100.0 + done / 10.0
    times = np.where(done < ramp_m, 100.0 - 10.0 / 6.0 + np.sqrt(2.0 * done / 3.0), times)
    to_go = 200.0 - done
    times = np.where(to_go < ramp_m, times + 10.0 / 6.0 - (np.sqrt(2.0 * to_go / 3.0) - to_go / 10.0), times)
    track = Track(times, np.stack([done, np.zeros_like(done), np.full_like(done, 20.0)], axis=1), True)
    r = conformance_report(plan, {1: track}, {1: 5.0}, route_t0_s={1: 100.0}, max_schedule_error_s=1.0,
                           acceptance_m=0.5, ramps=ramps)[0]  # fmt: skip
    assert r.passed is passed, r.failures
    # the first and last points are timed where the route counts as left / reached (0.5 m out):
    # 1.14 s into the ramps
    assert abs(r.schedule_error_s) == pytest.approx(0.05 if passed else 1.14, abs=0.1)
