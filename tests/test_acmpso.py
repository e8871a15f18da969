"""ACMPSO planner (seed 001): environment, fitness terms, lower bound, determinism, validator, plan."""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path

import numpy as np
import pytest

from gcs_planner.missions.items import plan_to_items
from gcs_planner.model.plan import Plan
from gcs_planner.model.scenario import ScenarioError
from gcs_planner.planning import config_of, load_scenario, parse_scenario, plan_scenario
from gcs_planner.planning.acmpso import (
    Config,
    TrackProblem,
    follow_terrain,
    limit_gradient,
    problem_from_scenario,
    solve,
)
from gcs_planner.planning.threat_env import (
    FlatTerrain,
    GridTerrain,
    PeaksTerrain,
    ThreatEnv,
    resample_path,
    terrain_from_config,
    validate_path,
)

MISSION = Path(__file__).resolve().parents[1] / "missions" / "acmpso_paper.toml"
# the paper's peaks in km: h, x_o, y_o, x_s, y_s
PEAKS_KM = [(6, 25, 25, 6, 12), (4, 40, 45, 8, 6), (10, 70, 40, 12, 18), (8, 30, 70, 7, 5)]


@pytest.fixture(scope="module")
def scenario():
    return load_scenario(MISSION)


@pytest.fixture(scope="module")
def paper(scenario):
    problem, env_m = problem_from_scenario(scenario, scenario.vehicles[0], Config())
    return problem, env_m


def _z_km(x: float, y: float) -> float:
    return sum(h * math.exp(-(((x - xo) / xs) ** 2) - ((y - yo) / ys) ** 2) for h, xo, yo, xs, ys in PEAKS_KM)


def test_terrain_at_peak_centres_from_the_mission_file(paper):
    _, env_m = paper
    for h, xo, yo, _, _ in PEAKS_KM:
        z = float(env_m.terrain.elevation(xo * 1000.0, yo * 1000.0))
        assert z == pytest.approx(_z_km(xo, yo) * 1000.0, abs=1e-3)  # float32 exp: < 1 mm
        assert h * 1000.0 <= z < h * 1000.0 + 20.0  # the neighbours add at most ~19 m (peak 2)
    assert float(env_m.terrain.elevation(40e3, 45e3)) == pytest.approx(4018.59, abs=0.01)
    # the km environment of the fitness is the same terrain scaled
    problem, _ = paper
    assert float(problem.env.terrain.elevation(70.0, 40.0)) == pytest.approx(_z_km(70, 40), abs=1e-6)
    assert problem.env.h_safe == pytest.approx(0.5) and problem.radar_strength == pytest.approx(10.0)


def test_grid_terrain_matches_sampled_peaks_and_holds_edges():
    peaks = PeaksTerrain(*np.array(PEAKS_KM, dtype=float).T)
    xs = np.arange(0.25, 100.0, 0.5)  # cell centres, 0.5 km cells
    ys = np.arange(99.75, 0.0, -0.5)  # north-up raster: row 0 at the top
    grid = peaks.elevation(xs[None, :], ys[:, None])
    dem = GridTerrain(grid, (0.0, 0.5, 0.0, 100.0, 0.0, -0.5))
    np.testing.assert_allclose(dem.elevation(xs[7], ys[11]), grid[11, 7], rtol=1e-12)
    pts = np.random.default_rng(0).uniform(1.0, 99.0, (500, 2))
    np.testing.assert_allclose(
        dem.elevation(pts[:, 0], pts[:, 1]), peaks.elevation(pts[:, 0], pts[:, 1]), atol=0.05
    )
    assert dem.elevation(-50.0, 99.9) == pytest.approx(grid[0, 0])  # outside: edge value held
    scaled = dem.scaled(1000.0)
    assert scaled.elevation(70e3, 40e3) == pytest.approx(1000.0 * dem.elevation(70.0, 40.0))
    with pytest.raises(ValueError, match="geotransform"):
        GridTerrain(grid, (0.0, 0.0, 0.0, 0.0, 0.0, 1.0))


def test_grid_terrain_from_npz_and_config_errors(tmp_path):
    np.savez(
        tmp_path / "dem.npz",
        elevation_m=np.array([[0.0, 10.0], [20.0, 30.0]]),
        geotransform=[0, 100, 0, 0, 0, 100],
    )
    dem = terrain_from_config({"type": "grid", "file": "dem.npz"}, tmp_path, "t")
    assert dem.elevation(100.0, 100.0) == pytest.approx(15.0)  # midway between the 4 cell centres
    with pytest.raises(ScenarioError, match="terrain.type"):
        terrain_from_config({"type": "lidar"}, tmp_path, "t")
    with pytest.raises(ScenarioError, match=r"terrain.peaks\[0\].sx_m"):
        terrain_from_config(
            {"type": "peaks", "peaks": [{"h_m": 1, "x_m": 0, "y_m": 0, "sx_m": 0, "sy_m": 1}]}, tmp_path, "t"
        )
    with pytest.raises(ScenarioError, match="missing.npz"):
        terrain_from_config({"type": "grid", "file": "missing.npz"}, tmp_path, "t")


def _flat_problem(env: ThreatEnv, start, goal, collision="literal") -> TrackProblem:
    return TrackProblem(
        env, start, goal, [0, 0, 0], [100, 100, 10], n_waypoints=3, n_nodes=11, collision=collision
    )


def _on_line(problem: TrackProblem) -> np.ndarray:
    frac = np.arange(1, problem.n_waypoints + 1) / (problem.n_waypoints + 1)
    return (problem.start + frac[:, None] * (problem.goal - problem.start)).reshape(1, -1)


def test_fitness_terms_on_a_straight_climbing_path():
    problem = _flat_problem(ThreatEnv(FlatTerrain()), [0, 0, 1], [30, 40, 6])
    x = _on_line(problem)
    np.testing.assert_allclose(problem.nodes(x)[0], np.linspace([0, 0, 1], [30, 40, 6], 11), atol=1e-12)
    terms = {k: float(v[0]) for k, v in problem.terms(x).items()}
    assert terms["length"] == pytest.approx(math.sqrt(30**2 + 40**2 + 5**2))
    z = [1 + 0.5 * k for k in range(11)]
    mean = sum(z) / 11
    assert terms["height"] == pytest.approx(math.sqrt(sum((v - mean) ** 2 for v in z) / 11))
    assert terms["radar"] == 0.0 and terms["collision"] == 0.0
    f = float(problem.fitness(x)[0])
    assert f == pytest.approx(0.3 * terms["length"] + 0.07 * terms["height"])


def test_radar_and_collision_terms_by_hand():
    # path along y = 0 at z = 1 from x = 0 to x = 10: nodes at x = 0, 1, ..., 10
    env = ThreatEnv(
        FlatTerrain(),
        radar_xyz=[[5.0, 0.0, 0.0]],
        radar_r=[3.0],
        cyl_xy=[[2.0, 0.5]],
        cyl_r=[1.2],
        cyl_zmin=[0.0],
        cyl_zmax=[2.0],
    )
    problem = _flat_problem(env, [0, 0, 1], [10, 0, 1])
    x = _on_line(problem)
    terms = {k: float(v[0]) for k, v in problem.terms(x).items()}
    # radar: nodes x = 3..7 have D = sqrt((x-5)^2 + 1) <= 3 -> (10 / D)^4
    expected_r = sum((10.0 / math.sqrt((k - 5) ** 2 + 1)) ** 4 for k in range(11) if (k - 5) ** 2 + 1 <= 9)
    assert terms["radar"] == pytest.approx(expected_r)
    # cylinder: nodes x = 1, 2, 3 are within 1.2 of (2, 0.5) horizontally (d = 1.118, 0.5, 1.118)
    d = [math.hypot(k - 2, 0.5) for k in range(11) if math.hypot(k - 2, 0.5) < 1.2]
    assert len(d) == 3
    assert terms["collision"] == pytest.approx(sum(d))  # literal eq. 9: the distance itself
    depth = _flat_problem(env, [0, 0, 1], [10, 0, 1], collision="depth")
    assert float(depth.terms(x)["collision"][0]) == pytest.approx(sum(1.2 - v for v in d))
    # above the cylinder top there is no collision cost
    high = _flat_problem(env, [0, 0, 2.5], [10, 0, 2.5])
    assert float(high.terms(_on_line(high))["collision"][0]) == 0.0


def test_altitude_repair_lifts_nodes_to_terrain_plus_h_safe():
    env = ThreatEnv(PeaksTerrain([5.0], [50.0], [50.0], [10.0], [10.0]), h_safe=0.5)
    problem = _flat_problem(env, [0, 50, 1], [100, 50, 1])
    nodes = problem.nodes(_on_line(problem))[0]
    floor = env.terrain.elevation(nodes[:, 0], nodes[:, 1]) + 0.5
    np.testing.assert_allclose(nodes[:, 2], np.maximum(1.0, floor))
    assert nodes[5, 2] == pytest.approx(5.5)  # over the summit


def test_straight_line_lower_bound(paper):
    problem, _ = paper
    straight = _on_line(problem)
    assert float(problem.terms(straight)["length"][0]) >= 124.463
    swarm = np.vstack([straight, np.random.default_rng(0).uniform(*problem.bounds(), (200, problem.dim))])
    assert np.all(problem.fitness(swarm) >= 0.3 * 124.463 - 1e-9)
    res = solve(problem, "acmpso", np.random.default_rng(5), "tuned", particles=20, iterations=30)
    assert 37.339 <= res.fitness < float(problem.fitness(straight)[0])


def test_runs_are_deterministic_per_seed(paper):
    problem, _ = paper
    for algorithm, variant in (("acmpso", "literal"), ("lpso", "tuned")):
        a = solve(problem, algorithm, np.random.default_rng(11), variant, particles=10, iterations=15)
        b = solve(problem, algorithm, np.random.default_rng(11), variant, particles=10, iterations=15)
        c = solve(problem, algorithm, np.random.default_rng(12), variant, particles=10, iterations=15)
        np.testing.assert_array_equal(a.pso.history, b.pso.history)
        np.testing.assert_array_equal(a.nodes, b.nodes)
        assert not np.array_equal(a.pso.history, c.pso.history)
        assert a.pso.evaluations == 150 + (14 if (algorithm, variant) == ("acmpso", "tuned") else 0)


def test_validator_catches_planted_violations(paper):
    _, env = paper
    # a clean high path: 9.5 km up, far above every peak, radar and obstacle
    clean = np.array([[3e3, 3e3, 9.5e3], [90e3, 92e3, 9.5e3]])
    report = validate_path(env, clean, spacing=100.0)
    assert report.ok and report.samples >= 10 * 124  # >= 10 samples per km
    # through radar 3 (38, 30) at 2 km altitude: inside the 9 km dome
    radar = np.array([[20e3, 30e3, 9.5e3], [30e3, 30e3, 2e3], [46e3, 30e3, 2e3], [60e3, 30e3, 9.5e3]])
    kinds = {(v.kind, v.index) for v in validate_path(env, radar, 100.0).violations}
    assert ("radar", 2) in kinds
    # a leg whose ends are clear but which grazes obstacle 1 (55, 65, r 2 km, 6 km high) at 3 km
    wide = np.array([[52e3, 60e3, 3e3], [52e3, 70e3, 3e3]])  # 3 km from the axis: clear
    assert not [v for v in validate_path(env, wide, 100.0).violations if v.kind == "obstacle"]
    graze = np.array([[54e3, 60e3, 3e3], [54e3, 70e3, 3e3]])  # passes 1 km from the axis
    obstacle = [v for v in validate_path(env, graze, 100.0).violations if v.kind == "obstacle"]
    assert len(obstacle) == 1 and obstacle[0].index == 0
    assert obstacle[0].depth == pytest.approx(1e3, abs=1.0)
    assert obstacle[0].where[1] == pytest.approx(65e3, abs=100.0)
    # ends above terrain + h_safe, middle cuts through peak 3's summit (10 km)
    terrain = np.array([[60e3, 40e3, 10.2e3], [80e3, 40e3, 10.2e3]])
    low = [v for v in validate_path(env, terrain, 100.0).violations if v.kind == "terrain"]
    assert len(low) == 1 and low[0].depth == pytest.approx(_z_km(70, 40) * 1e3 + 500.0 - 10.2e3)
    assert low[0].where[0] == pytest.approx(70e3)


def test_follow_terrain_cleans_a_grazing_track(paper):
    _, env = paper
    track = np.array([[54e3, 60e3, 3e3], [54e3, 70e3, 3e3], [80e3, 40e3, 9e3]])
    assert not validate_path(env, track, 100.0).ok
    waypoints = follow_terrain(env, track, 100.0, 50.0)
    assert validate_path(env, waypoints, 100.0).ok
    assert len(waypoints) < len(resample_path(track, 100.0)) / 3  # thinned, not every sample


def test_plan_is_registered_flies_clean_and_round_trips(scenario, tmp_path):
    raw = copy.deepcopy(scenario.raw)
    raw["planner"].update(particles=20, iterations=25)
    small = parse_scenario(raw, "small")
    progress = []
    result = plan_scenario(small, seed=3, progress=lambda f, m: progress.append(f))
    assert result.planner == "acmpso" and progress[-1] == pytest.approx(1.0)
    v = result.vehicles[0]
    np.testing.assert_allclose(v.waypoints[0, :2], [3e3, 3e3])  # over the start; the climb limit may
    assert 1e3 <= v.waypoints[0, 2] <= 1e3 + 50.0  # raise it (limit_gradient), never lower it
    np.testing.assert_allclose(v.waypoints[-1, :2], [90e3, 92e3], atol=1.0)
    assert 2e3 - 1.0 <= v.waypoints[-1, 2] <= 2e3 + 50.0
    assert v.feasible and validate_path(ThreatEnv.from_scenario(small, 500.0), v.waypoints, 100.0).ok
    assert np.all(np.diff(v.times_s) > 0) and v.times_s[-1] == pytest.approx(v.cost["length_m"] / 25.0)
    assert v.cost["fitness"] >= 37.339 and v.cost["flown_radar_violations"] == 0.0
    flown = resample_path(v.waypoints, 50.0)  # the clearance margin (25 m) is kept, at least half of it
    env = ThreatEnv.from_scenario(small, 500.0)
    assert np.min(flown[1:, 2] - env.floor(flown[1:, 0], flown[1:, 1])) >= 12.5 - 1e-6
    d = np.diff(v.waypoints, axis=0)
    assert np.all(np.abs(d[:, 2]) <= np.tan(np.radians(10.0)) * np.hypot(d[:, 0], d[:, 1]) + 1e-6)
    again = plan_scenario(small, seed=3)
    np.testing.assert_array_equal(again.vehicles[0].waypoints, v.waypoints)
    # the terrain-following waypoints become a valid mission (altitudes relative to home = origin)
    items = plan_to_items(v, result.origin, "ardupilot")
    nav = [it for it in items if it.command == 16]  # MAV_CMD_NAV_WAYPOINT (item 0 is home)
    np.testing.assert_allclose([it.z for it in nav[1:]], v.waypoints[1:, 2], atol=1e-3)
    path = tmp_path / "plan.json"
    path.write_text(json.dumps(result.to_dict()))
    assert Plan.from_dict(json.loads(path.read_text())).vehicles[0].waypoints.shape == v.waypoints.shape


def test_bad_parameters_name_the_field(scenario):
    for key, value, match in (
        ("algorithm", "gwo", "planner.algorithm is not one of the allowed values, got 'gwo'"),
        ("particles", 0, "planner.particles must be an integer >= 1, got 0"),
        ("weights", [1, 2], r"planner.weights must be a list of length 4, got \[1, 2\]"),
        ("h_safe_m", -1.0, "planner.h_safe_m must be a number > 0.0, got -1.0"),
        ("colour", 1, "unknown key 'colour'"),
    ):
        raw = copy.deepcopy(scenario.raw)
        raw["planner"][key] = value
        with pytest.raises(ScenarioError, match=match):
            config_of(parse_scenario(raw, "bad"))
    raw = copy.deepcopy(scenario.raw)
    del raw["bounds"]["z"]
    bad = parse_scenario(raw, "nobounds")
    with pytest.raises(ScenarioError, match="bounds.z"):
        problem_from_scenario(bad, bad.vehicles[0], Config())


def test_plan_over_a_gridded_elevation_model(scenario, tmp_path):
    # the paper's peaks sampled on a 1 km DEM: the planner works the same behind the Terrain interface
    xs = np.arange(500.0, 100e3, 1000.0)
    peaks = ThreatEnv.from_scenario(scenario, 500.0).terrain
    grid = peaks.elevation(xs[None, :], xs[:, None])  # row r at y = xs[r]: geotransform dy > 0
    np.savez(tmp_path / "dem.npz", elevation_m=grid, geotransform=[0.0, 1000.0, 0.0, 0.0, 0.0, 1000.0])
    raw = copy.deepcopy(scenario.raw)
    raw["terrain"] = {"type": "grid", "file": str(tmp_path / "dem.npz")}
    raw["planner"].update(particles=15, iterations=20)
    dem = parse_scenario(raw, "dem")
    env = ThreatEnv.from_scenario(dem, 500.0)
    assert isinstance(env.terrain, GridTerrain)
    assert float(env.terrain.elevation(70e3, 40e3)) == pytest.approx(
        float(peaks.elevation(70e3, 40e3)), abs=30.0
    )
    v = plan_scenario(dem, seed=2).vehicles[0]
    assert v.feasible and validate_path(env, v.waypoints, 100.0).ok
    assert np.all(v.waypoints[:, 2] >= env.floor(v.waypoints[:, 0], v.waypoints[:, 1]) - 1e-6)


def test_limit_gradient_only_raises_to_the_lowest_flyable_profile():
    x = np.arange(0.0, 2001.0, 100.0)
    z = np.where(np.abs(x - 1000.0) <= 100.0, 500.0, 0.0)  # a 500 m wall, 200 m wide
    out = limit_gradient(np.column_stack([x, np.zeros_like(x), z]), 0.5)
    assert np.all(out >= z)
    assert np.all(np.abs(np.diff(out)) <= 0.5 * 100.0 + 1e-9)
    # climbs start exactly 1000 m ahead of the wall (500 m at gradient 0.5) and end as late
    np.testing.assert_allclose(out, np.maximum(z, 500.0 - 0.5 * np.maximum(np.abs(x - 1000.0) - 100.0, 0.0)))


def test_safe_variant_tracks_clear_every_threat_between_nodes(paper):
    """The tuned variant's tracks meet Table 3 but cut radars and terrain between nodes; the safe
    variant's own optimised track passes the dense re-check (benchmarks/acmpso_table3.py runs 100)."""
    problem, env = paper
    cut = 0
    for r in range(3):
        tuned = solve(problem, "acmpso", np.random.default_rng([7, r]), "tuned")
        safe = solve(problem, "acmpso", np.random.default_rng([7, r]), "safe")
        cut += not validate_path(env, tuned.nodes * 1000.0, spacing=100.0).ok
        assert validate_path(env, safe.nodes * 1000.0, spacing=100.0).ok, r
        assert safe.terms["safety"] < 1000.0  # at most inside the margin, never inside a volume
        assert 37.339 <= safe.fitness == pytest.approx(float(problem.objective(safe.x[None])[0]), abs=0.05)
    assert cut >= 2  # the paper's fitness alone is not safe (what the safe variant fixes)


def test_safety_penalty_sees_a_chord_the_nodes_do_not(paper):
    problem, _ = paper
    from dataclasses import replace

    safe = replace(problem, safety_spacing=0.3, safety_margin=0.015)
    # two far-apart waypoint sets: the straight line crosses radar 3 and the terrain between nodes
    straight = _on_line(problem)
    assert float(safe.safety_penalty(straight)[0]) > 1000.0
    high = np.tile([50.0, 50.0, 9.5], problem.n_waypoints)  # every waypoint high over the middle
    assert float(safe.safety_penalty(high[None])[0]) < float(safe.safety_penalty(straight)[0])
