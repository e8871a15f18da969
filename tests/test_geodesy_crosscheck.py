"""The client's geodesy (gcs_planner.core.geo) and the mock world's (sitl_mock.geodesy) are written
separately, so that the mock autopilot shares no code with the GCS beyond the wire format; this
checks that they are the same frame: on 10,000 seeded random points about origins at latitudes
-80..80 and any longitude, up to 100 km out and -100..5000 m up, each round trip and each cross
conversion (one's geodetic into the other's ENU) agrees to 1 mm. A home moved by 1e-6 deg
(~0.1 m) is told apart, so the tolerance is tight enough to fail."""

from __future__ import annotations

import numpy as np
import pytest

from gcs_planner.core.geo import Origin, enu_to_geodetic, geodetic_to_enu
from gcs_planner.core.geo import wrap_pi as client_wrap_pi
from sitl_mock.geodesy import Home, to_enu, to_geodetic, wrap_pi

POINTS = 10_000
ORIGINS = 50  # POINTS / ORIGINS points about each
TOL_M = 1e-3


def _cases(seed: int = 20240601):
    """(origin lat, lon, alt, east, north, up) per point, origins repeated POINTS / ORIGINS times."""
    rng = np.random.default_rng(seed)
    lat0 = rng.uniform(-80.0, 80.0, ORIGINS)
    lon0 = rng.uniform(-180.0, 180.0, ORIGINS)
    alt0 = rng.uniform(-100.0, 3000.0, ORIGINS)
    per = POINTS // ORIGINS
    reach = rng.uniform(0.0, 100_000.0, (ORIGINS, per))
    bearing = rng.uniform(-np.pi, np.pi, (ORIGINS, per))
    up = rng.uniform(-100.0, 5000.0, (ORIGINS, per)) - alt0[:, None]  # AMSL -100..5000 m
    return lat0, lon0, alt0, reach * np.sin(bearing), reach * np.cos(bearing), up


def _metres(lat_a, lon_a, lat_b, lon_b, origin: Origin) -> np.ndarray:
    """Horizontal distance [m] between two geodetic point sets near ``origin`` (client's frame)."""
    ea, na, _ = geodetic_to_enu(lat_a, lon_a, 0.0, origin)
    eb, nb, _ = geodetic_to_enu(lat_b, lon_b, 0.0, origin)
    return np.hypot(ea - eb, na - nb)


def _worst_disagreement(perturb_deg: float = 0.0) -> float:
    """The largest difference [m] over every point between the two implementations, the mock's home
    moved north-east by ``perturb_deg``."""
    lat0, lon0, alt0, east, north, up = _cases()
    worst = 0.0
    for k in range(ORIGINS):
        origin = Origin(float(lat0[k]), float(lon0[k]), float(alt0[k]))
        home = Home(origin.lat_deg + perturb_deg, origin.lon_deg + perturb_deg, origin.alt_m)
        e, n, u = east[k], north[k], up[k]
        # each one's geodetic for the same ENU point
        lat_c, lon_c, alt_c = enu_to_geodetic(e, n, u, origin)
        lat_m, lon_m, alt_m = to_geodetic(e, n, u, home)
        worst = max(worst, _metres(lat_c, lon_c, lat_m, lon_m, origin).max(), np.abs(alt_c - alt_m).max())
        # cross conversions: the client's geodetic into the mock's ENU and back
        e_m, n_m, u_m = to_enu(lat_c, lon_c, alt_c, home)
        worst = max(worst, np.hypot(e_m - e, n_m - n).max(), np.abs(u_m - u).max())
        e_c, n_c, u_c = geodetic_to_enu(lat_m, lon_m, alt_m, origin)
        worst = max(worst, np.hypot(e_c - e, n_c - n).max(), np.abs(u_c - u).max())
        # the mock's own round trip
        e_r, n_r, u_r = to_enu(lat_m, lon_m, alt_m, home)
        worst = max(worst, np.hypot(e_r - e, n_r - n).max(), np.abs(u_r - u).max())
    return float(worst)


def test_the_mock_and_the_client_share_one_frame_to_a_millimetre():
    assert _worst_disagreement() <= TOL_M


def test_a_home_moved_by_a_micro_degree_is_told_apart():
    """The check can fail: 1e-6 deg of latitude is 0.11 m, a hundred times the tolerance."""
    assert _worst_disagreement(perturb_deg=1e-6) > 100 * TOL_M


def test_the_mock_takes_the_clients_origin_and_any_home_like_object():
    """The client passes its Origin to the mock's fleets: the mock converts about it as about its
    own Home with the same coordinates (its projections are keyed on the coordinates)."""

    class Plain:
        lat_deg, lon_deg, alt_m = 47.397742, 8.545594, 488.0

    home, origin = Home(47.397742, 8.545594, 488.0), Origin(47.397742, 8.545594, 488.0)
    for where in (origin, Plain()):
        assert to_geodetic(1234.5, -678.9, 12.0, where) == to_geodetic(1234.5, -678.9, 12.0, home)
        assert to_enu(47.4, 8.55, 500.0, where) == to_enu(47.4, 8.55, 500.0, home)
    lat, lon, alt = to_geodetic(0.0, 0.0, 0.0, home)
    assert isinstance(lat, float) and (lat, lon, alt) == pytest.approx((47.397742, 8.545594, 488.0))
    east, _, _ = to_enu([47.4, 47.5], [8.5, 8.6], [0.0, 0.0], origin)
    assert isinstance(east, np.ndarray) and east.shape == (2,)


@pytest.mark.parametrize(
    "bad", [(90.5, 0.0, 0.0), (0.0, -180.5, 0.0), (float("nan"), 0.0, 0.0), (0.0, 0.0, float("inf"))]
)
def test_home_refuses_what_origin_refuses(bad):
    with pytest.raises(ValueError):
        Origin(*bad)
    with pytest.raises(ValueError, match="home"):
        Home(*bad)


def test_wrap_pi_agrees():
    angles = np.random.default_rng(3).uniform(-50.0, 50.0, 1000)
    np.testing.assert_array_equal(wrap_pi(angles), client_wrap_pi(angles))
    assert np.all((wrap_pi(angles) >= -np.pi) & (wrap_pi(angles) < np.pi))
