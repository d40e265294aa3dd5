"""Strapdown mechanization (paper 001 eq. 1-3) and its exact inverse."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from navreplay.pipeline.nav import earth
from navreplay.pipeline.nav import mechanization as m
from navreplay.pipeline.nav.rotations import euler_to_quat, quat_to_dcm


def state(
    lat_deg: float = 37.46,
    lon_deg: float = 126.95,
    h: float = 60.0,
    v: tuple[float, float, float] = (0.0, 0.0, 0.0),
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> np.ndarray:
    x = np.zeros(m.NAV_DIM)
    x[m.I_LAT], x[m.I_LON], x[m.I_H] = math.radians(lat_deg), math.radians(lon_deg), h
    x[m.I_VN : m.I_VN + 3] = v
    x[m.I_QW : m.I_QW + 4] = euler_to_quat(*rpy)
    return x


def test_at_rest_the_imu_reads_minus_gravity_and_earth_rate() -> None:
    x = state(rpy=(0.0, 0.0, 0.7))
    f, w = m.imu_from_motion(x, np.zeros(3), np.zeros(3))
    assert np.linalg.norm(f) == pytest.approx(earth.gravity(x[0], x[2]))
    assert f[2] < -9.7  # level body: specific force points up, i.e. negative down
    assert np.linalg.norm(w) == pytest.approx(earth.OMEGA_IE, rel=1e-12)


def test_stationary_integration_stays_put_for_ten_minutes() -> None:
    x0 = state(rpy=(0.02, -0.01, 2.0))
    f, w = m.imu_from_motion(x0, np.zeros(3), np.zeros(3))
    n = 600 * 100 + 1
    t = np.arange(n, dtype=np.int64) * 10_000_000
    out = m.integrate(x0, t, np.tile(f, (n, 1)), np.tile(w, (n, 1)), 1)
    np.testing.assert_allclose(out[-1], x0, atol=1e-10)


def test_constant_velocity_north_follows_the_meridian() -> None:
    speed = 20.0
    x0 = state(lat_deg=10.0, v=(speed, 0.0, 0.0))
    # Moving north at constant speed and height: v_dot^n = 0 in NED components, the body
    # (level, facing north) pitches about its y axis at the transport rate -vn/(R_M + h).
    dur, rate = 300.0, 100
    n = int(dur * rate) + 1
    t = np.arange(n, dtype=np.int64) * (10**9 // rate)
    acc, gyro = np.empty((n, 3)), np.empty((n, 3))
    lat = x0[m.I_LAT]
    lats = np.empty(n)
    for i in range(n):
        # exact: lat(t) solves dlat/dt = v / R_M(lat); integrate finely alongside
        xi = x0.copy()
        xi[m.I_LAT] = lat
        rm, _ = earth.radii(lat)
        xi[m.I_QW : m.I_QW + 4] = euler_to_quat(0.0, 0.0, 0.0)
        acc[i], gyro[i] = m.imu_from_motion(xi, np.zeros(3), np.zeros(3))
        lats[i] = lat
        for _ in range(10):
            rm, _ = earth.radii(lat)
            lat += speed / (rm + x0[m.I_H]) * (1.0 / rate / 10)
    out = m.integrate(x0, t, acc, gyro, 1)
    rm, _ = earth.radii(lats[-1])
    north_err_m = (out[-1, m.I_LAT] - lats[-1]) * rm
    assert abs(north_err_m) < 1e-3
    assert abs(out[-1, m.I_LON] - x0[m.I_LON]) * 6.4e6 < 1e-3
    assert abs(out[-1, m.I_H] - x0[m.I_H]) < 1e-3


@settings(max_examples=100, deadline=None)
@given(
    st.tuples(st.floats(-80, 80), st.floats(-179, 179), st.floats(-100, 5000)),
    st.tuples(st.floats(-50, 50), st.floats(-50, 50), st.floats(-5, 5)),
    st.tuples(st.floats(-0.5, 0.5), st.floats(-0.5, 0.5), st.floats(-3.1, 3.1)),
    st.tuples(st.floats(-3, 3), st.floats(-3, 3), st.floats(-3, 3)),
    st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1)),
)
def test_imu_from_motion_is_the_exact_inverse_of_nav_derivative(
    pos: tuple[float, float, float],
    vel: tuple[float, float, float],
    rpy: tuple[float, float, float],
    vdot: tuple[float, float, float],
    w_nb: tuple[float, float, float],
) -> None:
    x = state(*pos, v=vel, rpy=rpy)
    f, w = m.imu_from_motion(x, np.array(vdot), np.array(w_nb))
    xdot = m.nav_derivative(x, f, w)
    np.testing.assert_allclose(xdot[m.I_VN : m.I_VN + 3], vdot, atol=1e-9)
    # q_dot = 1/2 q * (0, w_nb): recover w_nb from the quaternion derivative.
    q = x[m.I_QW : m.I_QW + 4]
    qd = xdot[m.I_QW : m.I_QW + 4]
    conj = q * np.array([1.0, -1.0, -1.0, -1.0])
    w0 = conj[0] * qd[0] - conj[1] * qd[1] - conj[2] * qd[2] - conj[3] * qd[3]
    wv = conj[0] * qd[1:] + qd[0] * conj[1:] + np.cross(conj[1:], qd[1:])
    np.testing.assert_allclose(2.0 * wv, w_nb, atol=1e-9)
    assert abs(w0) < 1e-12
    rm, _ = earth.radii(x[m.I_LAT])
    assert xdot[m.I_LAT] == pytest.approx(vel[0] / (rm + x[m.I_H]))
    assert xdot[m.I_H] == pytest.approx(-vel[2])


def test_rk4_substeps_converge() -> None:
    x0 = state(v=(10.0, 2.0, 0.0), rpy=(0.05, 0.02, 0.3))
    f0, w0 = np.array([0.3, 0.1, -9.7]), np.array([0.01, -0.02, 0.2])
    f1, w1 = np.array([0.5, -0.1, -9.9]), np.array([0.02, -0.01, 0.25])
    coarse = m.propagate(x0, f0, w0, f1, w1, 0.5, 1)
    fine = m.propagate(x0, f0, w0, f1, w1, 0.5, 10)
    finer = m.propagate(x0, f0, w0, f1, w1, 0.5, 40)
    err_coarse = np.abs(coarse - finer).max()
    err_fine = np.abs(fine - finer).max()
    assert err_fine < err_coarse / 100
    np.testing.assert_allclose(np.linalg.norm(fine[m.I_QW :]), 1.0, atol=1e-15)
    assert np.allclose(quat_to_dcm(fine[m.I_QW :]) @ quat_to_dcm(fine[m.I_QW :]).T, np.eye(3))
