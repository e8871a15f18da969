"""Sites (issue 34): a GeoJSON / KML + DEM site in geodetic terms plans with the priority swarm,
ACMPSO and the 4-D planner; the plan checker proves no path leaves the area, enters a no-fly
zone or comes closer to the DEM's ground than the clearance; the uploaded fence is what the plan
avoids; `fly` on the site passes; bad site input is one line, exit 2, nothing written."""

from __future__ import annotations

import json
import math
import shutil
import zipfile
from pathlib import Path
from xml.sax.saxutils import escape

import numpy as np
import pytest
import shapely
import tifffile
from cli_checks import refused

from gcs_planner.cli import main
from gcs_planner.core.geo import geodetic_to_enu
from gcs_planner.missions.items import scenario_fence_items
from gcs_planner.model.plan import Plan, VehiclePlan
from gcs_planner.model.sites.dem import read_dem
from gcs_planner.model.sites.geojson import read_geojson
from gcs_planner.model.sites.kml import read_kml
from gcs_planner.planning import load_scenario, plan_scenario
from gcs_planner.safety.geofence import breaches, overflown, vehicle_geofence
from gcs_planner.safety.separation import check_plan

MISSIONS = Path(__file__).resolve().parents[1] / "missions"
SWARM = MISSIONS / "site_valley_swarm.toml"
SITE = MISSIONS / "site_valley"
SCENARIOS = {
    "priority_swarm": SWARM,
    "acmpso": MISSIONS / "site_valley_acmpso.toml",
    "deconflict_4d": MISSIONS / "site_valley_4d.toml",
}


@pytest.fixture(scope="module")
def swarm():
    return load_scenario(SWARM)


def test_the_site_becomes_the_local_world(swarm):
    """Area -> bounds; each no-fly zone -> a cylinder holding its polygon; the mast stands on
    the DEM; the resampled terrain is the DEM's ground above the origin."""
    site = swarm.site
    x0, y0, x1, y1 = site.area.bounds
    assert swarm.bounds == {"x": (x0, x1), "y": (y0, y1)}
    assert {z.name for z in site.zones} == {"school", "substation", "helicopter approach"}
    for zone in site.zones:
        cyl = next(c for c in swarm.cylinders if c.zone == zone.name)
        corners = shapely.get_coordinates(zone.polygon)
        assert np.hypot(corners[:, 0] - cyl.x, corners[:, 1] - cyl.y).max() <= cyl.radius_m - site.margin_m
    sub = next(z for z in site.zones if z.name == "substation")
    heli = next(z for z in site.zones if z.name == "helicopter approach")
    assert sub.ceiling_m == pytest.approx(40.0) and sub.floor_m == -math.inf
    assert heli.floor_m == pytest.approx(100.0) and heli.ceiling_m == math.inf
    (mast,) = [c for c in swarm.cylinders if not c.zone]
    assert mast.radius_m == pytest.approx(8.0) and mast.buffer_m == 5.0
    assert mast.z_max_m == pytest.approx(float(site.ground(mast.x, mast.y)) + 60.0, abs=0.5)
    dem = read_dem(SITE / "valley_dem.tif", "dem")
    rng = np.random.default_rng(1)
    x, y = rng.uniform(x0, x1, 200), rng.uniform(y0, y1, 200)
    from gcs_planner.core.geo import enu_to_geodetic

    lat, lon, _ = enu_to_geodetic(x, y, 0.0, swarm.origin)
    assert np.abs(site.ground(x, y) - (dem.sample(lat, lon) - 488.0)).max() < 0.5
    assert site.ground(np.array(620.0), np.array(380.0)) > 65.0  # the hill


def test_start_lla_is_the_local_start(swarm):
    east, north, up = geodetic_to_enu(47.3968420, 8.5456000, 518.0, swarm.origin)
    assert swarm.vehicle("uav1").start == pytest.approx((east, north, up))
    assert up == pytest.approx(30.0) and north == pytest.approx(-100.0, abs=0.5)


@pytest.mark.parametrize("planner", SCENARIOS)
def test_each_planner_plans_the_site_and_the_checker_proves_it(planner):
    scenario = load_scenario(SCENARIOS[planner])
    plan = plan_scenario(scenario)
    assert plan.planner == planner and plan.feasible
    # the 4-D planner's multirotors climb as steeply as their dynamics allow (its own limits)
    report = check_plan(plan, scenario, max_climb_rad=math.radians(90 if planner == "deconflict_4d" else 30))
    assert report.ok, report.summary()
    assert not (report.outside_area or report.no_fly or report.terrain or report.collisions)
    for vp in plan.vehicles:
        fence = vehicle_geofence(scenario, vp)
        assert breaches(fence, vp) == []
        assert shapely.Polygon(fence.inclusion).equals(scenario.site.area)
        items = scenario_fence_items(scenario, vp)  # validated as they are built
        assert len(items) == len(fence.inclusion) + sum(
            len(z.vertices) for z in fence.exclusion_polygons
        ) + len(fence.exclusions)


def _one_path(scenario, points) -> Plan:
    p = np.asarray(points, dtype=float)
    t = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1) / 10.0)])
    v = scenario.vehicles[0]
    vp = VehiclePlan(v.id, v.sysid, p, t, np.full(len(p), 10.0), p, t, turn_radius_m=0.0)
    return Plan(origin=scenario.origin, planner="test", vehicles=[vp])


@pytest.mark.parametrize(
    ("points", "finding", "what"),
    [
        ([[0, 80, 60], [700, 80, 60]], "no_fly", ["school"]),  # straight through the school
        ([[600, -100, 30], [900, -10, 30]], "no_fly", ["substation"]),  # under its 40 m ceiling
        ([[100, 400, 90], [500, 480, 110]], "no_fly", ["helicopter approach"]),  # climbs into it
        ([[450, 250, 80], [800, 500, 80]], "terrain", None),  # through the hill's top
        ([[0, 0, 40], [0, -400, 40]], "outside_area", None),  # south out of the area
    ],
)
def test_the_checker_catches_each_site_hazard(swarm, points, finding, what):
    report = check_plan(_one_path(swarm, points), swarm)
    assert not report.ok and report.bad_vehicles() == {"uav1"}
    found = getattr(report, finding)["uav1"]
    if what is not None:
        assert found == what


@pytest.mark.parametrize(
    ("dz", "points", "failure"),
    [
        (0.0, [[0, -200, 60], [350, 90, 60], [300, -200, 60]], "entered no-fly zone 'school'"),
        (-45.0, [[0, -200, 60], [300, -200, 60]], "under the terrain clearance"),  # flown 45 m low
        (0.0, [[0, -200, 60], [100, -350, 60], [300, -200, 60]], "left the site's area"),
    ],
)
def test_fly_conformance_holds_the_flown_route_to_the_site(swarm, dz, points, failure):
    """The flown route (a track from the plan's first to its last point, ``dz`` lower) is checked
    like the plan; the plan flown as planned passes."""
    from gcs_planner.safety.conformance import Track, conformance_report

    plan = _one_path(swarm, [[0, -200, 60], [300, -200, 60]])  # a clean plan
    flown = _one_path(swarm, points).vehicles[0]
    track = Track(flown.path_times_s, flown.path + [0.0, 0.0, dz], mission_completed=True)
    (report,) = conformance_report(plan, {1: track}, {}, max_cross_track_m=1e6, site=swarm.site)
    assert any(failure in f for f in report.failures), report.failures
    vp = plan.vehicles[0]
    (clean,) = conformance_report(plan, {1: Track(vp.path_times_s, vp.path, True)}, {}, site=swarm.site)
    assert clean.passed, clean.failures


@pytest.mark.parametrize(
    "points",
    [
        [[600, -100, 60], [900, -10, 60]],  # over the substation's ceiling (+ the 20 m clearance)
        [[100, 420, 60], [500, 480, 60]],  # under the helicopter approach's floor
    ],
)
def test_a_zone_with_a_ceiling_or_floor_may_be_passed_over_or_under_and_is_not_fenced(swarm, points):
    plan = _one_path(swarm, points)
    report = check_plan(plan, swarm)
    assert not report.no_fly and not report.outside_area, report.summary()
    vp = plan.vehicles[0]
    (passed,) = [
        z.name for z in swarm.site.zones if shapely.intersects(z.polygon, shapely.LineString(vp.path[:, :2]))
    ]
    assert f"no-fly zone {passed!r}" in overflown(swarm, vp)
    assert breaches(vehicle_geofence(swarm, vp), vp) == []
    # the full scenario fence (no vehicle) holds every zone, and this path breaches it
    assert any(passed in b for b in breaches(vehicle_geofence(swarm), vp))


def test_fence_items_are_the_site_polygons_in_lat_lon(swarm):
    from pymavlink.dialects.v20 import ardupilotmega as mavlink

    items = scenario_fence_items(swarm)
    inc = [i for i in items if i.command == mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION]
    exc = [i for i in items if i.command == mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION]
    area = json.loads((SITE / "valley.geojson").read_text())["features"][0]["geometry"]["coordinates"][0][:-1]
    assert len(inc) == len(area) and all(i.param1 == len(area) for i in inc)
    got = {(i.y, i.x) for i in inc}  # (lon, lat) * 1e7
    assert got == {(round(lon * 1e7), round(lat * 1e7)) for lon, lat in area}
    assert len(exc) == 5 + 4 + 4  # school, substation, helicopter approach vertices


def test_site_missions_give_altitudes_amsl(swarm, tmp_path):
    """Each vehicle's home is on its own ground, not at the origin's altitude: a site plan's
    mission altitudes are AMSL (z + origin altitude), and plan.json keeps that."""
    from pymavlink.dialects.v20 import ardupilotmega as mavlink

    from gcs_planner.missions.items import plan_to_items

    plan = plan_scenario(swarm)
    assert {vp.altitude_frame for vp in plan.vehicles} == {"amsl"}
    vp = plan.vehicles[0]
    wps = [i for i in plan_to_items(vp, plan.origin, "px4") if i.command == mavlink.MAV_CMD_NAV_WAYPOINT]
    assert {i.frame for i in wps} == {mavlink.MAV_FRAME_GLOBAL}
    planned = vp.waypoints[:, 2] + 488.0
    assert all(np.isclose(i.z, planned, atol=1e-3).any() for i in wps) and wps[-1].z == pytest.approx(
        planned[-1]
    )
    plan.save(tmp_path / "p.json")
    assert Plan.load(tmp_path / "p.json").vehicles[0].altitude_frame == "amsl"
    plain = plan_scenario(load_scenario(MISSIONS / "swarm_small.toml"))
    assert "altitude_frame" not in plain.to_json()  # plans off a site are as before


def _kml(features: list[dict]) -> str:
    marks = []
    for f in features:
        props = f["properties"]
        data = "".join(
            f'<Data name="{k}"><value>{escape(str(v))}</value></Data>'
            for k, v in props.items()
            if k != "name"
        )
        geom = f["geometry"]
        if geom["type"] == "Point":
            lon, lat = geom["coordinates"]
            shape = f"<Point><coordinates>{lon},{lat},0</coordinates></Point>"
        else:
            ring = " ".join(f"{lon},{lat},0" for lon, lat in geom["coordinates"][0])
            ring = f"<LinearRing><coordinates>{ring}</coordinates></LinearRing>"
            shape = f"<Polygon><outerBoundaryIs>{ring}</outerBoundaryIs></Polygon>"
        marks.append(
            f"<Placemark><name>{escape(props['name'])}</name><ExtendedData>{data}</ExtendedData>{shape}</Placemark>"
        )
    return f'<?xml version="1.0" encoding="UTF-8"?><kml xmlns="http://www.opengis.net/kml/2.2"><Document>{"".join(marks)}</Document></kml>'


def test_kml_and_kmz_read_as_the_geojson(tmp_path):
    features = json.loads((SITE / "valley.geojson").read_text())["features"]
    (tmp_path / "site.kml").write_text(_kml(features))
    with zipfile.ZipFile(tmp_path / "site.kmz", "w") as kmz:
        kmz.writestr("doc.kml", _kml(features))
    expected = read_geojson(SITE / "valley.geojson")
    for got in (read_kml(tmp_path / "site.kml"), read_kml(tmp_path / "site.kmz")):
        assert [(f.kind, f.name, f.floor_m, f.ceiling_m, f.height_m, f.radius_m) for f in got] == [
            (f.kind, f.name, f.floor_m, f.ceiling_m, f.height_m, f.radius_m) for f in expected
        ]
        for a, b in zip(got, expected, strict=True):
            assert np.array_equal(a.rings[0], b.rings[0])


def test_a_kml_site_plans_like_the_geojson_one(tmp_path):
    features = json.loads((SITE / "valley.geojson").read_text())["features"]
    shutil.copy(SITE / "valley_dem.tif", tmp_path)
    (tmp_path / "valley.kml").write_text(_kml(features))
    text = SWARM.read_text().replace("site_valley/valley.geojson", "valley.kml").replace("site_valley/", "")
    (tmp_path / "s.toml").write_text(text)
    scenario = load_scenario(tmp_path / "s.toml")
    assert scenario.cylinders == load_scenario(SWARM).cylinders


def _plane(lat, lon):
    """A tilted plane [m AMSL]: bilinear interpolation reproduces it exactly."""
    return 480.0 + 3000.0 * (lat - 47.39) + 2000.0 * (lon - 8.54)


def test_hgt_tile_is_read_on_its_nodes(tmp_path):
    n = 121
    lat = 48.0 - np.arange(n) / (n - 1)  # row 0 is the north edge
    lon = 8.0 + np.arange(n) / (n - 1)
    grid = np.round(_plane(lat[:, None], lon[None, :])).astype(">i2")
    grid[0, 0] = -32768  # a void in the north-west corner
    (tmp_path / "N47E008.hgt").write_bytes(grid.tobytes())
    dem = read_dem(tmp_path / "N47E008.hgt", "dem")
    q_lat, q_lon = np.array([47.3, 47.61, 47.05]), np.array([8.5, 8.02, 8.97])
    assert np.abs(dem.sample(q_lat, q_lon) - _plane(q_lat, q_lon)).max() < 1.0
    assert np.isnan(dem.sample(np.array([47.999, 46.9]), np.array([8.001, 8.5]))).all()  # void, outside
    # as a site's DEM, without features: the terrain is the tile's ground above the origin
    text = SWARM.read_text().replace('features = ["site_valley/valley.geojson"]\n', "")
    (tmp_path / "s.toml").write_text(text.replace("site_valley/valley_dem.tif", "N47E008.hgt"))
    scenario = load_scenario(tmp_path / "s.toml")
    assert scenario.site.area is None and scenario.site.zones == () and scenario.cylinders == []
    lat, lon, alt = scenario.origin.lat_deg, scenario.origin.lon_deg, scenario.origin.alt_m
    assert float(scenario.site.ground(0.0, 0.0)) == pytest.approx(_plane(lat, lon) - alt, abs=1.0)
    assert check_plan(plan_scenario(scenario), scenario).ok


@pytest.mark.parametrize("pixel_is_point", [False, True])
def test_geotiff_registration(tmp_path, pixel_is_point):
    """PixelIsArea: the tie point is the first pixel's corner, samples at pixel centres;
    PixelIsPoint: the tie point is the first sample."""
    step, lon0, lat0 = 0.001, 8.5, 47.5
    half = 0.0 if pixel_is_point else 0.5
    lat = lat0 - (np.arange(20) + half) * step
    lon = lon0 + (np.arange(30) + half) * step
    keys = [1, 1, 0, 3, 1024, 0, 1, 2, 1025, 0, 1, 2 if pixel_is_point else 1, 2048, 0, 1, 4326]
    tifffile.imwrite(
        tmp_path / "d.tif",
        _plane(lat[:, None], lon[None, :]).astype(np.float64),
        extratags=[
            (33550, "d", 3, (step, step, 0.0), False),
            (33922, "d", 6, (0.0, 0.0, 0.0, lon0, lat0, 0.0), False),
            (34735, "H", len(keys), keys, False),
        ],
    )
    dem = read_dem(tmp_path / "d.tif", "dem")
    q_lat, q_lon = np.array([47.49, 47.485, 47.4815]), np.array([8.51, 8.5205, 8.52])
    assert dem.sample(q_lat, q_lon) == pytest.approx(_plane(q_lat, q_lon), abs=1e-6)


# -- bad input: one line naming the field / file and the value, exit 2, nothing written -----------


def _site_scenario(tmp_path, features=None, dem=None, edit=None):
    """The swarm site scenario copied into tmp_path with its files, optionally replaced."""
    shutil.copytree(SITE, tmp_path / "site_valley", dirs_exist_ok=True)
    text = SWARM.read_text()
    if features is not None:
        (tmp_path / "site_valley" / "bad.geojson").write_text(features)
        text = text.replace("valley.geojson", "bad.geojson")
    if dem is not None:
        text = text.replace("site_valley/valley_dem.tif", dem)
    if edit is not None:
        text = edit(text)
    (tmp_path / "s.toml").write_text(text)
    return str(tmp_path / "s.toml")


def _polygon_feature(coords, kind="no_fly"):
    return json.dumps(
        {
            "type": "FeatureCollection",
            "features": [
                {
                    "type": "Feature",
                    "properties": {"kind": kind},
                    "geometry": {"type": "Polygon", "coordinates": [coords]},
                }
            ],
        }
    )


@pytest.mark.parametrize(
    ("features", "dem", "edit", "words"),
    [
        ("not json at all", None, None, ["bad.geojson", "not valid JSON"]),
        ('{"type": "Topology", "objects": {}}', None, None, ["bad.geojson", "not GeoJSON", "Topology"]),
        (
            _polygon_feature([[8.54, 47.39], [8.55, 47.39]]),
            None,
            None,
            ["bad.geojson", "features[0]", "3 distinct vertices, got 2"],
        ),
        (
            _polygon_feature([[8.54, 95.0], [8.55, 47.39], [8.55, 47.40]]),
            None,
            None,
            ["features[0]", "lat", "95.0"],
        ),
        (
            _polygon_feature([[8.54, 47.39], [8.55, 47.40], [8.55, 47.39], [8.54, 47.40]]),
            None,
            None,
            ["not a valid polygon", "Self-intersection"],
        ),
        (
            _polygon_feature([[8.54, 47.39], [8.55, 47.39], [8.55, 47.40]], kind="lake"),
            None,
            None,
            ["kind", "'lake'"],
        ),
        (None, "site_valley/missing.tif", None, ["site.dem", "missing.tif", "no such file"]),
        (None, None, lambda t: t.replace("valley.geojson", "nope.geojson"), ["nope.geojson", "no such file"]),
        (
            None,
            None,
            lambda t: t.replace("47.3968420, 8.5456000", "91.0, 8.5456000"),
            ["vehicles[0].start_lla lat", "91.0"],
        ),
        (None, None, lambda t: t.replace("margin_m = 5.0", "margin_m = -1.0"), ["site.margin_m", "-1.0"]),
        (None, None, lambda t: t.replace("margin_m = 5.0", "margin = 5.0"), ["site", "'margin'"]),
    ],
)
def test_bad_site_input_is_one_line_and_exit_2(tmp_path, capsys, features, dem, edit, words):
    scenario = _site_scenario(tmp_path, features, dem, edit)
    out = tmp_path / "plan.json"
    refused(["plan", scenario, "-o", str(out)], capsys, *words)
    assert not out.exists()


def test_4d_vehicles_outside_the_site_area_are_one_line(tmp_path, capsys):
    """The origin moved off the site: the 4-D planner's box of the vehicles and the site's area no
    longer overlap (once a zero-size array error, after a warning line)."""
    shutil.copytree(SITE, tmp_path / "site_valley")
    text = (MISSIONS / "site_valley_4d.toml").read_text().replace("lat_deg = 47.397742", "lat_deg = 47.5")
    (tmp_path / "s.toml").write_text(text)
    refused(
        ["plan", str(tmp_path / "s.toml"), "-o", str(tmp_path / "p.json")], capsys, "outside the site's area"
    )
    assert not (tmp_path / "p.json").exists()


def test_a_dem_that_does_not_cover_the_site_is_refused(tmp_path, capsys):
    dem = read_dem(SITE / "valley_dem.tif", "dem")
    ny, nx = dem.elevation.shape
    keys = [1, 1, 0, 3, 1024, 0, 1, 2, 1025, 0, 1, 1, 2048, 0, 1, 4326]
    tifffile.imwrite(  # the western half of the tile only
        tmp_path / "half.tif",
        dem.elevation[:, : nx // 2].astype(np.float32),
        extratags=[
            (33550, "d", 3, (dem.dlon, -dem.dlat, 0.0), False),
            (33922, "d", 6, (0.0, 0.0, 0.0, dem.lon0 - dem.dlon / 2, dem.lat0 - dem.dlat / 2, 0.0), False),
            (34735, "H", len(keys), keys, False),
        ],
    )
    scenario = _site_scenario(tmp_path, dem=str(tmp_path / "half.tif"))
    refused(
        ["plan", scenario, "-o", str(tmp_path / "p.json")], capsys, "site.dem", "half.tif", "does not cover"
    )
    assert not (tmp_path / "p.json").exists()


def test_fly_on_the_site_passes(tmp_path, capsys):
    """Acceptance: plan the site with the priority swarm, upload mission and fence (the site's
    polygons) to mock vehicles, fly, and every vehicle conforms."""
    assert main(["fly", str(SWARM), "-o", str(tmp_path), "--no-rrd"]) == 0
    out = capsys.readouterr().out
    assert "PASS: 5/5 vehicles conform" in out
    plan = json.loads((tmp_path / "plan.json").read_text())
    assert [v["vehicle_id"] for v in plan["vehicles"]] == ["uav1", "uav2", "uav3", "uav4", "uav5"]
