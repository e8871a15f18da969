import numpy as np
import pytest

from gcs_planner.core.geo import Origin, enu_to_geodetic, geodetic_to_enu

ORIGINS = [
    Origin(47.397742, 8.545594, 488.0),
    Origin(31.522062, 105.044327, 500.0),
    Origin(-33.9, 151.2, 0.0),
    Origin(69.9, -20.0, 10.0),
]


@pytest.mark.parametrize("origin", ORIGINS)
def test_round_trip_below_1mm_within_100km(origin):
    rng = np.random.default_rng(0)
    r = 1e5 * np.sqrt(rng.random(2000))
    a = rng.uniform(0, 2 * np.pi, 2000)
    e, n, u = r * np.cos(a), r * np.sin(a), rng.uniform(-100, 3000, 2000)
    lat, lon, alt = enu_to_geodetic(e, n, u, origin)
    e2, n2, u2 = geodetic_to_enu(lat, lon, alt, origin)
    err = np.sqrt((e2 - e) ** 2 + (n2 - n) ** 2 + (u2 - u) ** 2)
    assert err.max() < 1e-3


def test_scalars_stay_scalars_and_origin_maps_to_zero():
    o = ORIGINS[0]
    e, n, u = geodetic_to_enu(o.lat_deg, o.lon_deg, o.alt_m, o)
    assert isinstance(e, float) and abs(e) < 1e-9 and abs(n) < 1e-9 and u == 0.0


def test_distance_and_bearing_true_against_geodesic():
    from pyproj import Geod

    o = ORIGINS[1]
    lat, lon, _ = enu_to_geodetic(30_000.0, 40_000.0, 0.0, o)
    az, _, dist = Geod(ellps="WGS84").inv(o.lon_deg, o.lat_deg, lon, lat)
    assert dist == pytest.approx(50_000.0, abs=1e-3)
    assert az == pytest.approx(np.degrees(np.arctan2(30_000.0, 40_000.0)), abs=1e-6)


def test_up_is_altitude_above_origin_at_any_range():
    o = ORIGINS[0]
    _, _, alt = enu_to_geodetic(80_000.0, 0.0, 100.0, o)
    assert alt == pytest.approx(o.alt_m + 100.0)


@pytest.mark.parametrize(
    "field,kw",
    [("lat_deg", dict(lat_deg=91.0, lon_deg=0.0)), ("lon_deg", dict(lat_deg=0.0, lon_deg=float("nan")))],
)
def test_bad_origin_names_field(field, kw):
    with pytest.raises(ValueError, match=field):
        Origin(**kw)
