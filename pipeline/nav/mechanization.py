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

import numpy as np

from navreplay.pipeline._jit import njit
from navreplay.pipeline.nav.earth import (
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
from navreplay.pipeline.nav.rotations import quat_to_dcm

I_LAT, I_LON, I_H = 0, 1, 2
I_VN, I_VE, I_VD = 3, 4, 5
I_QW = 6
NAV_DIM = 10


@njit(cache=True, inline="always", error_model="numpy")
def _sincos_near(lat: float, lat_ref: float, sin_ref: float, cos_ref: float) -> tuple[float, float]:
    """sin and cos of ``lat`` from those of a nearby ``lat_ref`` (angle-sum formula with the
    Taylor series of the difference; exact to d^7/5040, below 1e-20 for d < 1e-3 rad)."""
    d = lat - lat_ref
    d2 = d * d
    cd = 1.0 - 0.5 * d2 * (1.0 - d2 / 12.0 * (1.0 - d2 / 30.0))
    sd = d * (1.0 - d2 / 6.0 * (1.0 - d2 / 20.0 * (1.0 - d2 / 42.0)))
    return sin_ref * cd + cos_ref * sd, cos_ref * cd - sin_ref * sd


@njit(cache=True, inline="always", error_model="numpy")
def quat_dcm(
    qw: float, qx: float, qy: float, qz: float
) -> tuple[float, float, float, float, float, float, float, float, float]:
    """C_b^n of the unit quaternion ``(qw, qx, qy, qz)``, its entries row by row (as
    ``rotations.quat_to_dcm``)."""
    c00 = qw * qw + qx * qx - qy * qy - qz * qz
    c01 = 2.0 * (qx * qy - qw * qz)
    c02 = 2.0 * (qx * qz + qw * qy)
    c10 = 2.0 * (qx * qy + qw * qz)
    c11 = qw * qw - qx * qx + qy * qy - qz * qz
    c12 = 2.0 * (qy * qz - qw * qx)
    c20 = 2.0 * (qx * qz - qw * qy)
    c21 = 2.0 * (qy * qz + qw * qx)
    c22 = qw * qw - qx * qx - qy * qy + qz * qz
    return c00, c01, c02, c10, c11, c12, c20, c21, c22


@njit(cache=True, inline="always", error_model="numpy")
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
    c00, c01, c02, c10, c11, c12, c20, c21, c22 = quat_dcm(qw, qx, qy, qz)
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


@njit(cache=True, inline="always", error_model="numpy")
def _derivative_into(
    x: F64, f_b: F64, w_ib_b: F64, out: F64, lat_ref: float, sin_ref: float, cos_ref: float
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
               x[I_QW + 3], sl, cl, f_b[0], f_b[1], f_b[2],
               w_ib_b[0], w_ib_b[1], w_ib_b[2])  # fmt: skip
    for j in range(NAV_DIM):
        out[j] = r[j]


@njit(cache=True)
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
    _derivative_into(x, f_b, w_ib_b, out, lat, math.sin(lat), math.cos(lat))
    return out


@njit(cache=True, error_model="numpy")
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


# The lane workspace of ``propagate_lanes_into``: a flat float64 array of ``LN_DIM`` rows of
# ``LANES`` values, row r of lane b at ``r * LANES + b`` (a constant row stride is what lets the
# compiler prove the rows apart and vectorize over lanes).
LANES = 40  # at most this many lanes (a UKF with 17 states has 35 sigma points)
LN_X = 0  # rows 0..9: the navigation state
LN_K = 10  # rows 10..19: the derivative of the current RK4 stage
LN_S = 20  # rows 20..29: the weighted sum of the stage derivatives
LN_F0, LN_W0 = 30, 33  # specific force and angular rate at the interval start (3 rows each)
LN_DF, LN_DW = 36, 39  # their change over the interval (3 rows each)
LN_SIN, LN_COS, LN_LAT = 42, 43, 44  # the reference latitude, its sine and cosine
LN_SL, LN_CL = 45, 46  # the sine and cosine of the current stage point's latitude
LN_DIM = 47


@njit(cache=True, inline="always", error_model="numpy")
def _lane_point(Y: F64, b: int, c: float) -> tuple[float, ...]:
    """The RK4 stage point ``y + c k`` of lane ``b`` (lat, h, v, q: longitude is not needed)."""
    L, K = LANES, LN_K * LANES
    return (
        Y[b] + c * Y[K + b],
        Y[2 * L + b] + c * Y[K + 2 * L + b],
        Y[3 * L + b] + c * Y[K + 3 * L + b],
        Y[4 * L + b] + c * Y[K + 4 * L + b],
        Y[5 * L + b] + c * Y[K + 5 * L + b],
        Y[6 * L + b] + c * Y[K + 6 * L + b],
        Y[7 * L + b] + c * Y[K + 7 * L + b],
        Y[8 * L + b] + c * Y[K + 8 * L + b],
        Y[9 * L + b] + c * Y[K + 9 * L + b],
    )


@njit(cache=True, inline="always", error_model="numpy")
def _lane_rates(Y: F64, b: int, a: float, p: tuple[float, ...], sl: float, cl: float) -> None:
    """``_rates`` at stage point ``p`` and input fraction ``a`` into lane ``b``'s K rows."""
    L = LANES
    f0, w0, df, dw = LN_F0 * L + b, LN_W0 * L + b, LN_DF * L + b, LN_DW * L + b
    r = _rates(
        p[1], p[2], p[3], p[4], p[5], p[6], p[7], p[8], sl, cl,
        Y[f0] + a * Y[df], Y[f0 + L] + a * Y[df + L], Y[f0 + 2 * L] + a * Y[df + 2 * L],
        Y[w0] + a * Y[dw], Y[w0 + L] + a * Y[dw + L], Y[w0 + 2 * L] + a * Y[dw + 2 * L],
    )  # fmt: skip
    K = LN_K * L + b
    Y[K], Y[K + L], Y[K + 2 * L], Y[K + 3 * L], Y[K + 4 * L] = r[0], r[1], r[2], r[3], r[4]
    Y[K + 5 * L], Y[K + 6 * L], Y[K + 7 * L] = r[5], r[6], r[7]
    Y[K + 8 * L], Y[K + 9 * L] = r[8], r[9]


@njit(cache=True, inline="always", error_model="numpy")
def _lanes_sincos(Y: F64, m: int, c: float) -> None:
    """The sine and cosine of every lane's stage-point latitude into rows ``LN_SL``/``LN_CL``,
    chosen as in ``_derivative_into``: by ``_sincos_near`` from the reference latitude, or by
    ``math.sin``/``cos`` where it moved 1e-3 rad or more (or is not finite)."""
    L, K = LANES, LN_K * LANES
    far = 0  # an integer count keeps the first loop branch-free: it vectorizes
    for b in range(m):
        lat, lr = Y[b] + c * Y[K + b], Y[LN_LAT * L + b]
        sl, cl = _sincos_near(lat, lr, Y[LN_SIN * L + b], Y[LN_COS * L + b])
        Y[LN_SL * L + b], Y[LN_CL * L + b] = sl, cl
        far += 0 if abs(lat - lr) < 1e-3 else 1
    if far > 0:
        for b in range(m):
            lat = Y[b] + c * Y[K + b]
            if not abs(lat - Y[LN_LAT * L + b]) < 1e-3:
                Y[LN_SL * L + b], Y[LN_CL * L + b] = math.sin(lat), math.cos(lat)


@njit(cache=True, inline="always", error_model="numpy")
def _lanes_step_end(Y: F64, m: int, w6: float) -> None:
    """The end of an RK4 step in every lane: ``y += h/6 sum``, the quaternion renormalized."""
    L = LANES
    for j in range(NAV_DIM * L):
        Y[j] = Y[j] + w6 * Y[LN_S * L + j]
    for b in range(m):
        y6, y7, y8, y9 = Y[6 * L + b], Y[7 * L + b], Y[8 * L + b], Y[9 * L + b]
        n = math.sqrt(y6 * y6 + y7 * y7 + y8 * y8 + y9 * y9)
        sc = 1.0 / n if y6 >= 0.0 else -1.0 / n
        Y[6 * L + b], Y[7 * L + b] = y6 * sc, y7 * sc
        Y[8 * L + b], Y[9 * L + b] = y8 * sc, y9 * sc


@njit(cache=True, error_model="numpy")
def propagate_lanes_into(Y: F64, m: int, dt: float, substeps: int) -> None:
    """``propagate_into`` for ``m`` (<= ``LANES``) independent states at once, in place.

    ``Y`` (``LN_DIM * LANES``, flat; see ``LANES``) holds one state per lane: the navigation
    state in rows ``LN_X``, the interval's inputs in rows ``LN_F0`` ... ``LN_DW`` (the start
    value and the change over the interval: the input at fraction ``a`` is ``f0 + a df``),
    the reference latitude with its sine and cosine in rows ``LN_SIN``/``LN_COS``/``LN_LAT``,
    and rows ``LN_K`` finite (zeros, or the previous interval's values); the others are
    workspace.

    Every lane undergoes the operations of ``propagate_into`` in the same order, so with
    finite states the results are bitwise equal (tested). The loop order differs: each RK4
    stage runs over all lanes before the next, and the lanes vectorize (SIMD) instead of each
    evaluation waiting on the previous one. The first stage's point is written ``y + 0 k``,
    which is ``y`` exactly for finite ``k``, so all four stages share one branch-free loop.
    The sine and cosine of each lane's latitude are taken before it (``_lanes_sincos``), as
    ``_derivative_into`` takes them: from the reference by ``_sincos_near``, exactly where
    the latitude moved 1e-3 rad or more.
    """
    L = LANES
    h = dt / substeps
    w6 = h / 6.0
    for k in range(substeps):
        for j in range(LN_S * L, (LN_S + NAV_DIM) * L):
            Y[j] = 0.0
        for st in range(4):
            if st == 0:
                a, c = k / substeps, 0.0
            else:
                a = (k + 0.5) / substeps if st < 3 else (k + 1.0) / substeps
                c = 0.5 * h if st < 3 else h
            wgt = 2.0 if 0 < st < 3 else 1.0
            _lanes_sincos(Y, m, c)
            for b in range(m):  # the vectorized loop: no calls, no branches
                p = _lane_point(Y, b, c)
                _lane_rates(Y, b, a, p, Y[LN_SL * L + b], Y[LN_CL * L + b])
            for j in range(NAV_DIM * L):
                Y[LN_S * L + j] += wgt * Y[LN_K * L + j]
        _lanes_step_end(Y, m, w6)


@njit(cache=True)
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


@njit(cache=True)
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


@njit(cache=True)
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
