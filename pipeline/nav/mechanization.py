"""Strapdown mechanization in the local-level navigation frame (NED), paper 001 eq. 1-3.

The navigation state ``x`` is a float64 vector of ``NAV_DIM`` = 10 elements::

    x = [lat_rad, lon_rad, h_m, v_n_mps, v_e_mps, v_d_mps, q_w, q_x, q_y, q_z]

with ``q_wxyz`` rotating body FRD into NED (see ``pipeline.nav.rotations``). IMU samples are
instantaneous specific force ``f_b`` (m/s^2) and angular rate ``w_ib_b`` (rad/s) in body FRD.
Between two samples the inputs are interpolated linearly and the state is integrated with
classical Runge-Kutta 4 in ``substeps`` steps (paper 001 uses 10 for its sigma points); the
quaternion is renormalized after each step.

``imu_from_motion`` is the exact inverse of ``nav_derivative``: the synthesizers derive their
IMU from a trajectory with it, so forward integration of a noise-free synthesized IMU
reproduces the trajectory up to integration error. Everything is numba-compiled
(``cache=True``); estimator kernels call these functions directly. The integrators use IEEE
division semantics (``error_model="numpy"``): a division by zero (a state at a pole) yields
inf/NaN, which the estimators' NaN barrier reports, instead of a zero-check before every
division, which would cost about 40 % of an evaluation.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from pipeline.nav.earth import (
    E2,
    F64,
    GAMMA_E,
    I64,
    K_SOMIGLIANA,
    M_GRAV,
    OMEGA_IE,
    A,
    F,
    gravity,
    omega_en_n,
    omega_ie_n,
)
from pipeline.nav.rotations import quat_to_dcm

I_LAT, I_LON, I_H = 0, 1, 2
I_VN, I_VE, I_VD = 3, 4, 5
I_QW = 6
NAV_DIM = 10


@nb.njit(cache=True, inline="always", error_model="numpy")
def _sincos_near(lat: float, lat_ref: float, sin_ref: float, cos_ref: float) -> tuple[float, float]:
    """sin and cos of ``lat`` from those of a nearby ``lat_ref`` (angle-sum formula with the
    Taylor series of the difference; exact to d^7/5040, below 1e-20 for d < 1e-3 rad)."""
    d = lat - lat_ref
    d2 = d * d
    cd = 1.0 - 0.5 * d2 * (1.0 - d2 / 12.0 * (1.0 - d2 / 30.0))
    sd = d * (1.0 - d2 / 6.0 * (1.0 - d2 / 20.0 * (1.0 - d2 / 42.0)))
    return sin_ref * cd + cos_ref * sd, cos_ref * cd - sin_ref * sd


@nb.njit(cache=True, inline="always", error_model="numpy")
def _rates(
    h: float,
    vn: float,
    ve: float,
    vd: float,
    qw: float,
    qx: float,
    qy: float,
    qz: float,
    sl: float,
    cl: float,
    fx: float,
    fy: float,
    fz: float,
    wx: float,
    wy: float,
    wz: float,
) -> tuple[float, float, float, float, float, float, float, float, float, float]:
    """The right-hand side of eq. 1-3 from scalars (sin and cos of the latitude given)."""
    s2 = sl * sl
    inv_w = 1.0 / math.sqrt(1.0 - E2 * s2)
    rn = A * inv_w
    rm = rn * (1.0 - E2) * inv_w * inv_w
    # three reciprocals instead of six divisions (an evaluation is latency bound)
    i_rnh = 1.0 / (rn + h)
    i_rmh = 1.0 / (rm + h)
    i_cl = 1.0 / cl
    # earth rate and transport rate in NED
    ie_n, ie_d = OMEGA_IE * cl, -OMEGA_IE * sl
    en_n, en_e, en_d = ve * i_rnh, -vn * i_rmh, -ve * sl * i_cl * i_rnh
    # C_b^n from the quaternion
    c00 = qw * qw + qx * qx - qy * qy - qz * qz
    c01 = 2.0 * (qx * qy - qw * qz)
    c02 = 2.0 * (qx * qz + qw * qy)
    c10 = 2.0 * (qx * qy + qw * qz)
    c11 = qw * qw - qx * qx + qy * qy - qz * qz
    c12 = 2.0 * (qy * qz - qw * qx)
    c20 = 2.0 * (qx * qz - qw * qy)
    c21 = 2.0 * (qy * qz + qw * qx)
    c22 = qw * qw - qx * qx - qy * qy + qz * qz
    # eq. 2: velocity, with Coriolis and transport-rate terms and normal gravity
    cwn, cwe, cwd = 2.0 * ie_n + en_n, en_e, 2.0 * ie_d + en_d
    # normal gravity as earth.gravity (Somigliana + free-air), sharing sin(lat) and 1/w
    g = GAMMA_E * (1.0 + K_SOMIGLIANA * s2) * inv_w
    g *= 1.0 - 2.0 / A * (1.0 + F + M_GRAV - 2.0 * F * s2) * h + 3.0 * h * h / (A * A)
    # eq. 3: q_dot = 1/2 q * (0, w_nb_b), w_nb_b = w_ib_b - C_n^b (w_ie + w_en)
    in_n, in_e, in_d = ie_n + en_n, en_e, ie_d + en_d
    bx = wx - (c00 * in_n + c10 * in_e + c20 * in_d)
    by = wy - (c01 * in_n + c11 * in_e + c21 * in_d)
    bz = wz - (c02 * in_n + c12 * in_e + c22 * in_d)
    return (
        vn * i_rmh,  # eq. 1: position
        ve * i_rnh * i_cl,
        -vd,
        c00 * fx + c01 * fy + c02 * fz - (cwe * vd - cwd * ve),
        c10 * fx + c11 * fy + c12 * fz - (cwd * vn - cwn * vd),
        c20 * fx + c21 * fy + c22 * fz - (cwn * ve - cwe * vn) + g,
        0.5 * (-qx * bx - qy * by - qz * bz),
        0.5 * (qw * bx + qy * bz - qz * by),
        0.5 * (qw * by - qx * bz + qz * bx),
        0.5 * (qw * bz + qx * by - qy * bx),
    )


@nb.njit(cache=True, inline="always", error_model="numpy")
def _derivative_into(
    x: F64,
    fx: float,
    fy: float,
    fz: float,
    wx: float,
    wy: float,
    wz: float,
    out: F64,
    lat_ref: float,
    sin_ref: float,
    cos_ref: float,
) -> None:
    """Allocation-free core of ``nav_derivative``; writes dx/dt into ``out``.

    ``sin(lat)`` and ``cos(lat)`` come from those of ``lat_ref`` (the latitude at the start of
    the RK4 interval) by ``_sincos_near``; trigonometric calls are only made when the
    latitude moved more than 1e-3 rad. This halves the cost of an evaluation.
    """
    lat = x[I_LAT]
    if abs(lat - lat_ref) < 1e-3:
        sl, cl = _sincos_near(lat, lat_ref, sin_ref, cos_ref)
    else:
        sl, cl = math.sin(lat), math.cos(lat)
    r = _rates(x[I_H], x[I_VN], x[I_VE], x[I_VD], x[I_QW], x[I_QW + 1], x[I_QW + 2],
               x[I_QW + 3], sl, cl, fx, fy, fz, wx, wy, wz)  # fmt: skip
    for j in range(NAV_DIM):
        out[j] = r[j]


@nb.njit(cache=True)
def nav_derivative(x: F64, f_b: F64, w_ib_b: F64) -> F64:
    """Time derivative of the navigation state (paper 001 eq. 1-3).

    Args:
        x: navigation state, shape (10,).
        f_b: specific force in body FRD, m/s^2, shape (3,).
        w_ib_b: angular rate of body w.r.t. inertial space in body FRD, rad/s, shape (3,).

    Returns:
        dx/dt, shape (10,).
    """
    out = np.empty(NAV_DIM)
    lat = x[I_LAT]
    _derivative_into(
        x, f_b[0], f_b[1], f_b[2], w_ib_b[0], w_ib_b[1], w_ib_b[2], out,
        lat, math.sin(lat), math.cos(lat),
    )  # fmt: skip
    return out


@nb.njit(cache=True, error_model="numpy")
def propagate_into(
    x: F64, f0: F64, w0: F64, f1: F64, w1: F64, dt: float, substeps: int, out: F64
) -> None:
    """Allocation-free ``propagate``: writes the result into ``out`` (may alias ``x``).

    The state lives in scalars (registers) through the RK4 stages instead of scratch rows:
    the same operations in the same order as the array form (bitwise the same result), a
    third less time per derivative evaluation.
    """
    h = dt / substeps
    y0, y1, y2, y3, y4 = x[0], x[1], x[2], x[3], x[4]
    y5, y6, y7, y8, y9 = x[5], x[6], x[7], x[8], x[9]
    df0, df1, df2 = f1[0] - f0[0], f1[1] - f0[1], f1[2] - f0[2]
    dw0, dw1, dw2 = w1[0] - w0[0], w1[1] - w0[1], w1[2] - w0[2]
    lr = x[I_LAT]
    sr, cr = math.sin(lr), math.cos(lr)
    for k in range(substeps):
        s0 = s1 = s2 = s3 = s4 = s5 = s6 = s7 = s8 = s9 = 0.0
        k0 = k1 = k2 = k3 = k4 = k5 = k6 = k7 = k8 = k9 = 0.0
        # the four RK4 stages in one loop: one inlined copy of the derivative, not four
        for st in range(4):
            if st == 0:
                a = k / substeps
                p0, p2, p3, p4, p5 = y0, y2, y3, y4, y5
                p6, p7, p8, p9 = y6, y7, y8, y9
            else:
                a = (k + 0.5) / substeps if st < 3 else (k + 1.0) / substeps
                c = 0.5 * h if st < 3 else h
                p0, p2, p3, p4, p5 = y0 + c * k0, y2 + c * k2, y3 + c * k3, y4 + c * k4, y5 + c * k5
                p6, p7, p8, p9 = y6 + c * k6, y7 + c * k7, y8 + c * k8, y9 + c * k9
            if abs(p0 - lr) < 1e-3:  # as _derivative_into
                sl, cl = _sincos_near(p0, lr, sr, cr)
            else:
                sl, cl = math.sin(p0), math.cos(p0)
            k0, k1, k2, k3, k4, k5, k6, k7, k8, k9 = _rates(
                p2, p3, p4, p5, p6, p7, p8, p9, sl, cl,
                f0[0] + a * df0, f0[1] + a * df1, f0[2] + a * df2,
                w0[0] + a * dw0, w0[1] + a * dw1, w0[2] + a * dw2,
            )  # fmt: skip
            wgt = 2.0 if 0 < st < 3 else 1.0
            s0, s1, s2, s3, s4 = (
                s0 + wgt * k0,
                s1 + wgt * k1,
                s2 + wgt * k2,
                s3 + wgt * k3,
                s4 + wgt * k4,
            )
            s5, s6, s7, s8, s9 = (
                s5 + wgt * k5,
                s6 + wgt * k6,
                s7 + wgt * k7,
                s8 + wgt * k8,
                s9 + wgt * k9,
            )
        w6 = h / 6.0
        y0, y1, y2, y3, y4 = y0 + w6 * s0, y1 + w6 * s1, y2 + w6 * s2, y3 + w6 * s3, y4 + w6 * s4
        y5, y6, y7, y8, y9 = y5 + w6 * s5, y6 + w6 * s6, y7 + w6 * s7, y8 + w6 * s8, y9 + w6 * s9
        n = math.sqrt(y6 * y6 + y7 * y7 + y8 * y8 + y9 * y9)
        sc = 1.0 / n if y6 >= 0.0 else -1.0 / n
        y6, y7, y8, y9 = y6 * sc, y7 * sc, y8 * sc, y9 * sc
    out[0], out[1], out[2], out[3], out[4] = y0, y1, y2, y3, y4
    out[5], out[6], out[7], out[8], out[9] = y5, y6, y7, y8, y9


@nb.njit(cache=True)
def propagate(x: F64, f0: F64, w0: F64, f1: F64, w1: F64, dt: float, substeps: int) -> F64:
    """Integrate the navigation state over ``dt`` seconds from IMU sample 0 to sample 1.

    The inputs are interpolated linearly between the two samples; each of the ``substeps``
    steps is a classical RK4 step, after which the quaternion is renormalized (scalar >= 0).

    Returns:
        the state at the time of sample 1, shape (10,).
    """
    out = np.empty(NAV_DIM)
    propagate_into(x, f0, w0, f1, w1, dt, substeps, out)
    return out


@nb.njit(cache=True)
def integrate(x0: F64, t_ns: I64, acc: F64, gyro: F64, substeps: int) -> F64:
    """Free-inertial navigation: integrate IMU samples from the state ``x0`` at ``t_ns[0]``.

    Args:
        x0: navigation state at the first sample, shape (10,).
        t_ns: sample times, int64 ns, strictly increasing, shape (N,).
        acc: specific force, body FRD, m/s^2, shape (N, 3).
        gyro: angular rate, body FRD, rad/s, shape (N, 3).
        substeps: RK4 steps per sample interval.

    Returns:
        states at every sample time, shape (N, 10).
    """
    n = t_ns.shape[0]
    out = np.empty((n, NAV_DIM))
    out[0] = x0
    for i in range(1, n):
        dt = (t_ns[i] - t_ns[i - 1]) * 1e-9
        propagate_into(out[i - 1], acc[i - 1], gyro[i - 1], acc[i], gyro[i], dt, substeps, out[i])
    return out


@nb.njit(cache=True)
def imu_from_motion(x: F64, vdot_n: F64, w_nb_b: F64) -> tuple[F64, F64]:
    """Exact IMU readings of a body moving with the given state and derivatives.

    The inverse of ``nav_derivative``:
    ``f_b = C_n^b (v_dot^n + (2 w_ie^n + w_en^n) x v^n - g^n)`` and
    ``w_ib^b = w_nb^b + C_n^b (w_ie^n + w_en^n)``.

    Args:
        x: navigation state, shape (10,).
        vdot_n: time derivative of the NED velocity components, m/s^2, shape (3,).
        w_nb_b: angular rate of body w.r.t. NED, in body FRD, rad/s, shape (3,).

    Returns:
        (f_b, w_ib_b), each shape (3,).
    """
    lat, h = x[I_LAT], x[I_H]
    v = x[I_VN : I_VN + 3]
    c_bn = quat_to_dcm(x[I_QW : I_QW + 4])
    w_ie = omega_ie_n(lat)
    w_en = omega_en_n(lat, h, v[0], v[1])
    cw = 2.0 * w_ie + w_en
    cor = np.array(
        [cw[1] * v[2] - cw[2] * v[1], cw[2] * v[0] - cw[0] * v[2], cw[0] * v[1] - cw[1] * v[0]]
    )
    a_n = vdot_n + cor
    a_n[2] -= gravity(lat, h)
    f_b = c_bn.T @ a_n
    w_ib_b = w_nb_b + c_bn.T @ (w_ie + w_en)
    return f_b, w_ib_b
