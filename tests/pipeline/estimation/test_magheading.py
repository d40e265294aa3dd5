"""The magnetometer heading: a synthetic field (the WMM's, from pygeomag directly) seen by a
body at known attitudes (scipy's ZYX Euler rotation), level and tilted, with noise; the
declination's sign; the calibration check widening or refusing."""

from __future__ import annotations

import datetime as dt
import math

import numpy as np
import pytest
from pygeomag import GeoMag
from scipy.spatial.transform import Rotation

from navreplay.pipeline.estimation.ins.magheading import (
    CALIBRATED_FLOOR_DEG,
    UNCALIBRATED_FLOOR_DEG,
    decimal_year,
    mag_heading,
    wmm_field,
)

G = 9.80665
#: Bristol (UK), 2023-07-06: declination about -0.8 deg (west), inclination 67 deg down
BRISTOL = (51.42, -2.67, 80.0)
#: Seattle, 2025.25: the pygeomag docstring's example, declination +15.07 deg (east)
SEATTLE = (47.6205, -122.3493, 0.0)


def _field_ned(lat: float, lon: float, alt_m: float, year: float) -> np.ndarray:
    r = GeoMag(base_year=year).calculate(glat=lat, glon=lon, alt=alt_m / 1000.0, time=year)
    return np.array([r.x, r.y, r.z]) / 1e5  # nT -> gauss


def _body(
    yaw_deg: float,
    pitch_deg: float,
    roll_deg: float,
    m_n: np.ndarray,
    n: int,
    noise: float,
    f_noise: float = 0.02,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Time, specific force (n, 3) and field (n, 3) in body FRD for the attitude."""
    rng = np.random.default_rng(7)
    c_bn = Rotation.from_euler("ZYX", [yaw_deg, pitch_deg, roll_deg], degrees=True)
    f_b = c_bn.inv().apply(np.array([0.0, 0.0, -G]))
    m_b = c_bn.inv().apply(m_n)
    t = np.arange(n, dtype=np.int64) * 10_000_000
    f = f_b + rng.normal(0.0, f_noise, (n, 3))
    m = m_b + rng.normal(0.0, noise, (n, 3))
    return t, f, m


def _err_deg(a_rad: float, b_deg: float) -> float:
    return abs(math.degrees(math.remainder(a_rad - math.radians(b_deg), 2 * math.pi)))


@pytest.mark.parametrize(
    ("yaw", "pitch", "roll"),
    [(0.0, 0.0, 0.0), (37.0, 0.0, 0.0), (-120.0, 0.0, 0.0), (179.0, 0.0, 0.0)],
)
def test_level_heading_is_exact(yaw: float, pitch: float, roll: float) -> None:
    when = dt.date(2023, 7, 6)
    m_n = _field_ned(*BRISTOL, decimal_year(when))
    t, f, m = _body(yaw, pitch, roll, m_n, 200, 0.0, 0.0)
    out = mag_heading(t, f, m, *BRISTOL, when)
    assert out is not None
    assert out.usable
    assert _err_deg(out.yaw_rad, yaw) < 1e-9
    assert (out.samples, out.t_start_ns, out.t_ns) == (200, 0, int(t[-1]))
    assert abs(out.field_gauss / out.wmm_field_gauss - 1) < 1e-3
    assert out.floor_rad == pytest.approx(math.radians(CALIBRATED_FLOOR_DEG))
    assert "consistent with the WMM" in out.check


@pytest.mark.parametrize(
    ("yaw", "pitch", "roll"), [(60.0, 20.0, -15.0), (-150.0, -25.0, 30.0), (95.0, 5.0, 40.0)]
)
def test_tilted_heading_is_compensated(yaw: float, pitch: float, roll: float) -> None:
    when = dt.datetime(2023, 7, 6, 9, 12)
    m_n = _field_ned(*BRISTOL, decimal_year(when))
    t, f, m = _body(yaw, pitch, roll, m_n, 300, 0.002)
    out = mag_heading(t, f, m, *BRISTOL, when)
    assert out is not None
    assert out.usable
    assert out.roll_rad == pytest.approx(math.radians(roll), abs=2e-3)
    assert out.pitch_rad == pytest.approx(math.radians(pitch), abs=2e-3)
    assert _err_deg(out.yaw_rad, yaw) < 0.5
    # without tilt compensation (the field taken as level) the heading is far off
    flat = mag_heading(t, f, m, *BRISTOL, when, roll_pitch_rad=(0.0, 0.0))
    assert flat is not None
    assert flat.tilt_source == "given"
    assert _err_deg(flat.yaw_rad, yaw) > 10.0


def test_given_roll_pitch_level_the_field() -> None:
    when = 2023.5
    m_n = _field_ned(*BRISTOL, when)
    t, _, m = _body(-70.0, 12.0, -8.0, m_n, 50, 0.0)
    out = mag_heading(
        t, np.full(3, np.nan), m, *BRISTOL, when, roll_pitch_rad=(math.radians(-8), 0.2094395)
    )
    assert out is not None
    assert _err_deg(out.yaw_rad, -70.0) < 0.01


def test_declination_sign_against_pygeomag() -> None:
    """East declination: magnetic north lies east of true north, a body pointing at magnetic
    north (magnetic heading 0) has a true heading of +D."""
    year = 2025.25
    ref = GeoMag(base_year=year).calculate(
        glat=SEATTLE[0], glon=SEATTLE[1], alt=SEATTLE[2] / 1000.0, time=year
    )
    assert ref.d == pytest.approx(15.0656, abs=1e-3)  # the pygeomag docstring's value
    wmm = wmm_field(*SEATTLE, year)
    assert math.degrees(wmm.declination_rad) == pytest.approx(ref.d)
    assert wmm.model == "WMM-2025"
    m_n = _field_ned(*SEATTLE, year)
    t, f, m = _body(ref.d, 0.0, 0.0, m_n, 20, 0.0, 0.0)
    out = mag_heading(t, f, m, *SEATTLE, year)
    assert out is not None
    assert math.degrees(out.magnetic_yaw_rad) == pytest.approx(0.0, abs=1e-6)
    assert math.degrees(out.yaw_rad) == pytest.approx(ref.d, abs=1e-6)
    assert out.declination_rad == pytest.approx(math.radians(ref.d))


def test_southern_hemisphere_field_points_up() -> None:
    """Canberra: inclination negative (the field points up), the heading still right."""
    place = (-35.36, 149.16, 600.0)
    when = dt.date(2015, 11, 21)
    m_n = _field_ned(*place, decimal_year(when))
    assert m_n[2] < 0
    t, f, m = _body(-3.5, 1.0, 3.0, m_n, 100, 0.001)
    out = mag_heading(t, f, m, *place, when)
    assert out is not None
    assert out.usable
    assert out.model == "WMM-2015v2"
    assert math.degrees(out.inclination_rad) < -60
    assert _err_deg(out.yaw_rad, -3.5) < 0.5


def test_sigma_covers_scatter_and_floor() -> None:
    when = 2023.5
    m_n = _field_ned(*BRISTOL, when)
    t, f, m = _body(10.0, 0.0, 0.0, m_n, 400, 0.02)  # noisy: ~6 deg per sample
    out = mag_heading(t, f, m, *BRISTOL, when)
    assert out is not None
    assert math.degrees(out.scatter_rad) > 3.0
    assert out.sigma_rad >= math.hypot(out.scatter_rad, out.floor_rad)
    assert _err_deg(out.yaw_rad, 10.0) < 3 * math.degrees(out.sigma_rad)


def test_hard_iron_widens_then_refuses() -> None:
    when = 2023.5
    m_n = _field_ned(*BRISTOL, when)
    t, f, m = _body(45.0, 0.0, 0.0, m_n, 100, 0.0)
    total = float(np.linalg.norm(m_n))
    # an offset of 10 % of the field along body x (uncalibrated hard iron)
    off = mag_heading(t, f, m + np.array([0.10 * total, 0, 0]), *BRISTOL, when)
    assert off is not None
    assert off.usable
    assert off.floor_rad >= math.radians(UNCALIBRATED_FLOOR_DEG)
    assert "disagrees with the WMM" in off.check
    assert "widened" in off.check
    # the floor covers the error the offset makes
    assert _err_deg(off.yaw_rad, 45.0) < math.degrees(off.sigma_rad)
    # a field twice as strong as the WMM's: refused
    bad = mag_heading(t, f, 2.0 * m, *BRISTOL, when)
    assert bad is not None
    assert not bad.usable
    assert bad.check.startswith("refused")
    assert bad.field_gauss / bad.wmm_field_gauss == pytest.approx(2.0, rel=1e-3)


def test_nothing_to_compute() -> None:
    t = np.arange(5, dtype=np.int64)
    f = np.tile([0.0, 0.0, -G], (5, 1))
    m = np.full((5, 3), np.nan)
    assert mag_heading(t, f, m, *BRISTOL, 2023.5) is None
    m[:2] = 0.2
    assert mag_heading(t, f, m, *BRISTOL, 2023.5) is None  # 2 finite samples
    with pytest.raises(ValueError, match=r"mag_b must be \(n, 3\)"):
        mag_heading(t, f, np.zeros((4, 3)), *BRISTOL, 2023.5)


def test_date_outside_every_model_is_said() -> None:
    wmm = wmm_field(*BRISTOL, 2008.0)
    assert wmm.model == "WMM-2010"
    assert "outside" in wmm.note
    assert decimal_year(dt.date(2024, 7, 2)) == pytest.approx(2024 + 183 / 366)
