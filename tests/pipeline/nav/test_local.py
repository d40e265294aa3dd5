"""Local East/North map around an origin."""

from __future__ import annotations

import math

import numpy as np
import pytest

from navreplay.ingest.typed import FieldError
from navreplay.pipeline.nav.earth import geodetic_to_ecef
from navreplay.pipeline.nav.local import LocalFrame


def test_to_geodetic_and_to_ned_are_inverse() -> None:
    frame = LocalFrame(40.47, -86.99, 160.0)
    n = np.array([0.0, 240.0, -13.5])
    e = np.array([3.0, -2.0, 100.0])
    lat, lon, alt = frame.to_geodetic(n, e, -1.0)
    assert lat[1] > frame.lat_deg
    assert lon[2] > frame.lon_deg
    assert np.all(alt == 161.0)
    back = frame.to_ned(lat, lon, alt)
    np.testing.assert_allclose(back[0], n, atol=1e-9)
    np.testing.assert_allclose(back[1], e, atol=1e-9)
    np.testing.assert_allclose(back[2], -1.0, atol=1e-12)


def test_metres_are_metres_on_the_ellipsoid_near_the_origin() -> None:
    frame = LocalFrame(40.47, -86.99, 160.0)
    origin = geodetic_to_ecef(math.radians(40.47), math.radians(-86.99), 160.0)
    for n, e in ((240.0, 0.0), (0.0, 240.0), (170.0, 170.0)):
        lat, lon, alt = frame.to_geodetic(n, e)
        p = geodetic_to_ecef(math.radians(float(lat)), math.radians(float(lon)), float(alt))
        # chord vs map distance: equal to the curvature drop, < 5 mm at 240 m
        assert np.linalg.norm(p - origin) == pytest.approx(math.hypot(n, e), abs=5e-3)


def test_origin_is_checked() -> None:
    with pytest.raises(FieldError, match="lat_deg"):
        LocalFrame(91.0, 0.0, 0.0)
