"""REP-103 conversion, mounting rotation, and unit plausibility (catalogue cases 23, 24)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from navreplay.ingest.config import GnssConfig, ImuConfig
from navreplay.ingest.errors import PlausibilityError
from navreplay.ingest.frames import (
    ACC,
    GYRO,
    dcm_from_rpy_deg,
    flu_to_frd,
    level_from_gravity,
    rpy_deg_from_dcm,
    tilt_deg,
)
from navreplay.ingest.plausibility import G0, decide_gnss, decide_imu

P = Path("log.mcap")
angles = st.floats(-179.0, 179.0)


def test_flu_to_frd_is_a_half_turn_about_x() -> None:
    cols = {n: np.array([1.0, -2.0]) for n in ACC + GYRO}
    changed = flu_to_frd(cols, "imu")
    assert sorted(changed) == sorted([ACC[1], ACC[2], GYRO[1], GYRO[2]])
    np.testing.assert_array_equal(cols[ACC[0]], [1.0, -2.0])
    np.testing.assert_array_equal(cols[ACC[2]], [-1.0, 2.0])
    veh = {"yaw_rate_radps": np.array([0.3]), "speed_mps": np.array([2.0])}
    flu_to_frd(veh, "vehicle")
    assert veh["yaw_rate_radps"][0] == -0.3  # left turn positive in FLU, negative in FRD
    assert veh["speed_mps"][0] == 2.0


def test_enu_velocity_becomes_ned() -> None:
    cols = {
        "vel_n_mps": np.array([1.0]),
        "vel_e_mps": np.array([2.0]),
        "vel_d_mps": np.array([3.0]),
    }
    flu_to_frd(cols, "gnss")  # columns hold E, N, U before
    assert (cols["vel_n_mps"][0], cols["vel_e_mps"][0], cols["vel_d_mps"][0]) == (2.0, 1.0, -3.0)


@settings(max_examples=50, deadline=None)
@given(angles, st.floats(-89.0, 89.0), angles)
def test_rpy_and_dcm_round_trip(r: float, p: float, y: float) -> None:
    c = dcm_from_rpy_deg((r, p, y))
    np.testing.assert_allclose(c @ c.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(c) == pytest.approx(1.0)
    np.testing.assert_allclose(rpy_deg_from_dcm(c), (r, p, y), atol=1e-7)


@settings(max_examples=50, deadline=None)
@given(angles, st.floats(-85.0, 85.0))
def test_levelling_from_gravity_puts_specific_force_on_minus_z(r: float, p: float) -> None:
    # A sensor at (roll, pitch) measures f = C^T (0, 0, -g); levelling recovers the mounting.
    c = dcm_from_rpy_deg((r, p, 0.0))
    f = c.T @ np.array([0.0, 0.0, -G0])
    rpy = level_from_gravity(f)
    np.testing.assert_allclose(rpy[:2], (r, p), atol=1e-7)
    np.testing.assert_allclose(dcm_from_rpy_deg(rpy) @ f, [0.0, 0.0, -G0], atol=1e-9)
    assert tilt_deg(dcm_from_rpy_deg(rpy) @ f) == pytest.approx(0.0, abs=1e-6)


def _imu_block(
    n: int = 2000,
    rate: float = 100.0,
    f_sensor: tuple[float, float, float] = (0.0, 0.0, -G0),
    gyro_bias: tuple[float, float, float] = (0.004, -0.003, 0.002),
    seed: int = 0,
) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    cols: dict[str, np.ndarray] = {"t_ns": (np.arange(n) * 1e9 / rate).astype(np.int64)}
    for k, name in enumerate(ACC):
        cols[name] = f_sensor[k] + rng.normal(0, 0.02, n)
    for k, name in enumerate(GYRO):
        cols[name] = gyro_bias[k] + rng.normal(0, 0.002, n)
    return cols


def test_level_imu_at_rest_passes_with_no_mounting() -> None:
    d = decide_imu(_imu_block(), ImuConfig(), P, "/imu")
    assert d.mounting_source == "none"
    assert d.report["rest_windows_1s"] == 20
    assert d.report["gravity_magnitude_mps2"] == pytest.approx(G0, abs=0.01)


def test_rotated_imu_is_levelled_and_reported() -> None:
    # The robot_localization case: gravity on the sensor's y axis.
    d = decide_imu(_imu_block(f_sensor=(0.2, -9.79, -0.3)), ImuConfig(), P, "/imu")
    assert d.mounting_source.startswith("detected from gravity")
    after = d.report["mounting"]["specific_force_body_mps2"]
    np.testing.assert_allclose(after[:2], [0.0, 0.0], atol=1e-9)
    assert after[2] == pytest.approx(-math.hypot(0.2, 9.79, 0.3), abs=0.01)
    cols = _imu_block(f_sensor=(0.2, -9.79, -0.3))
    d.apply(cols)
    assert np.mean(cols[ACC[2]]) == pytest.approx(-9.795, abs=0.01)
    assert abs(np.mean(cols[ACC[1]])) < 0.01


def test_mounting_from_the_descriptor_wins() -> None:
    cfg = ImuConfig(mounting_rpy_deg=(90.0, 0.0, 0.0))
    d = decide_imu(_imu_block(f_sensor=(0.0, -G0, 0.0)), cfg, P, "/imu")
    assert d.mounting_source == "dataset.yaml"
    np.testing.assert_allclose(
        d.report["mounting"]["specific_force_body_mps2"], [0, 0, -G0], atol=0.01
    )


def test_accel_in_g_is_fatal_and_the_override_scales_and_is_recorded() -> None:
    # Case 23: divide the accel columns by 9.80665.
    block = _imu_block(f_sensor=(0.0, 0.0, -1.0))
    with pytest.raises(PlausibilityError) as err:
        decide_imu(block, ImuConfig(), P, "/imu")
    assert "static |a| = 1.00" in str(err.value)
    assert "probable g units" in str(err.value)
    assert "accel_units: g" in str(err.value)
    d = decide_imu(block, ImuConfig(accel_units="g"), P, "/imu")
    assert d.accel_scale == G0
    assert "imu_accel_units" in d.provenance


@pytest.mark.parametrize("at_rest", [True, False])
def test_gyro_in_deg_per_s_is_fatal_unless_declared(at_rest: bool) -> None:
    # Case 24: multiply the gyro by 57.2958.
    block = _imu_block()
    if not at_rest:  # a moving vehicle: turning, vibrating, no rest window
        rng = np.random.default_rng(5)
        block[ACC[0]] = block[ACC[0]] + rng.normal(0, 1.0, len(block["t_ns"]))
        block[GYRO[2]] = block[GYRO[2]] + 0.4 * np.sin(np.arange(len(block["t_ns"])) / 50)
    for name in GYRO:
        block[name] = block[name] * 57.2958
    with pytest.raises(PlausibilityError, match="probable deg/s"):
        decide_imu(block, ImuConfig(), P, "/imu")
    d = decide_imu(block, ImuConfig(gyro_units="degps"), P, "/imu")
    assert d.gyro_scale == pytest.approx(math.pi / 180)


def test_latlon_in_radians_is_fatal_unless_declared() -> None:
    # Case 24: lat/lon stored in radians.
    lat = np.radians(np.array([37.5, 37.5001]))
    lon = np.radians(np.array([127.0, 127.0001]))
    cols = {"lat_deg": lat, "lon_deg": lon, "fix_type": np.array([3, 3], np.int8)}
    with pytest.raises(PlausibilityError, match="probable radians"):
        decide_gnss(cols, GnssConfig(), P, "/fix")
    d = decide_gnss(cols, GnssConfig(latlon_units="rad"), P, "/fix")
    d.apply(cols)
    np.testing.assert_allclose(cols["lat_deg"], [37.5, 37.5001])


def test_latlon_out_of_range_is_fatal() -> None:
    cols = {"lat_deg": np.array([375.0]), "lon_deg": np.array([12.0])}
    with pytest.raises(PlausibilityError, match="out of range"):
        decide_gnss(cols, GnssConfig(), P, "/fix")
