"""WGS-84 earth model against pymap3d and published values."""

from __future__ import annotations

import math

import numpy as np
import pymap3d
import pytest

from navreplay.pipeline.nav import earth


@pytest.mark.parametrize(
    ("lat", "lon", "h"),
    [
        (37.46, 126.95, 60.0),
        (-35.36, 149.16, 584.0),
        (0.0, 0.0, 0.0),
        (89.9, -70.0, 3000.0),
        (63.417, 10.4, -20.0),
    ],
)
def test_geodetic_ecef_round_trip_matches_pymap3d(lat: float, lon: float, h: float) -> None:
    ecef = earth.geodetic_to_ecef(math.radians(lat), math.radians(lon), h)
    ref = np.array(pymap3d.geodetic2ecef(lat, lon, h))
    np.testing.assert_allclose(ecef, ref, atol=1e-6)
    lat2, lon2, h2 = earth.ecef_to_geodetic(*ecef)
    assert math.degrees(lat2) == pytest.approx(lat, abs=1e-10)
    assert math.degrees(lon2) == pytest.approx(lon, abs=1e-10)
    assert h2 == pytest.approx(h, abs=1e-6)


def test_ecef_to_geodetic_at_satellite_altitude() -> None:
    # pymap3d 3.2's ecef2geodetic is ~20 m off at GPS orbit height, so check self-consistency.
    xyz = np.array([15_600e3, 7_540e3, 20_140e3])
    lat, lon, h = earth.ecef_to_geodetic(*xyz)
    np.testing.assert_allclose(earth.geodetic_to_ecef(lat, lon, h), xyz, atol=1e-6)
    assert h == pytest.approx(20_201_635.6, abs=1.0)


def test_normal_gravity_published_values() -> None:
    # TR8350.2: gamma_e = 9.7803253359, gamma_p = 9.8321849378 m/s^2
    assert earth.gravity(0.0, 0.0) == pytest.approx(9.7803253359, abs=1e-9)
    assert earth.gravity(math.pi / 2, 0.0) == pytest.approx(9.8321849378, abs=1e-8)
    # free-air gradient about -3.086e-6 /s^2 per metre
    lat = math.radians(45.0)
    grad = (earth.gravity(lat, 100.0) - earth.gravity(lat, 0.0)) / 100.0
    assert grad == pytest.approx(-3.086e-6, rel=2e-3)


def test_radii_of_curvature() -> None:
    rm, rn = earth.radii(0.0)
    assert rn == pytest.approx(earth.A)
    assert rm == pytest.approx(earth.A * (1 - earth.E2))
    rm, rn = earth.radii(math.pi / 2)
    assert rm == pytest.approx(rn)


def test_ecef_to_ned_rotation_is_orthonormal_and_points_down() -> None:
    lat, lon = math.radians(37.46), math.radians(126.95)
    c = earth.dcm_ecef_to_ned(lat, lon)
    np.testing.assert_allclose(c @ c.T, np.eye(3), atol=1e-15)
    up_ecef = earth.geodetic_to_ecef(lat, lon, 1.0) - earth.geodetic_to_ecef(lat, lon, 0.0)
    np.testing.assert_allclose(c @ up_ecef, [0.0, 0.0, -1.0], atol=1e-9)
    n, e, d = pymap3d.ecef2ned(
        *(earth.geodetic_to_ecef(lat, lon, 0.0) + np.array([10.0, -3.0, 7.0])), 37.46, 126.95, 0.0
    )
    np.testing.assert_allclose(c @ np.array([10.0, -3.0, 7.0]), [n, e, d], atol=1e-6)
