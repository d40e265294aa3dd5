"""The strapdown INS model shared by every INS/GNSS estimator (paper 001 eq. 1-6).

**Full state** ``X`` (float64, ``FULL_DIM`` = 18), what the filters estimate::

    X = [lat_rad, lon_rad, h_m, v_n, v_e, v_d (m/s), q_w, q_x, q_y, q_z,
         ba_x, ba_y, ba_z (m/s^2), bg_x, bg_y, bg_z (rad/s), cb_m, cd_mps]

The first ten elements are the navigation state of ``pipeline.nav.mechanization``; ``ba`` and
``bg`` are accelerometer and gyro biases (the sensor reads truth + bias + noise), ``cb`` and
``cd`` the receiver clock bias and drift (zero and unused under loose coupling).

**Error state** ``dx`` (``n`` = 15 loose, 17 tight), the EKF's state and the coordinates of the
UKF covariance::

    dx = [dr_n, dr_e, dr_d (m), dv_n, dv_e, dv_d (m/s), phi_n, phi_e, phi_d (rad),
          dba (3), dbg (3), dcb, dcd]

defined by ``X_true = inject(X, dx)``: position offsets in NED metres, velocity and biases
additive, attitude as a rotation vector in the navigation frame applied on the left,
``q_true = Exp(phi) * q`` (so ``C_true = Exp(phi) C``). ``difference`` is its exact inverse.

**UKF coordinates** ``s`` (``n``), the UKF's own state: the same layout as ``dx`` except the
position block holds ``lat_rad, lon_rad, h_m`` (total state, paper 001) and the attitude block
a rotation vector relative to a reference quaternion, ``q = Exp(a) * q_ref`` (a multiplicative,
USQUE-style attitude parametrisation: the sigma-point arithmetic never touches a quaternion).

**Propagation.** ``propagate_span`` integrates a full state through the IMU samples between two
stop times with the mechanization's allocation-free RK4 (inputs interpolated linearly, bias
corrected with the state's own biases, so each UKF sigma point sees its own bias);
``propagate_sigmas`` does the same for a stack of states at once (the UKF's sigma points),
vectorized over the states, with bitwise the same result. The error dynamics over a span are
in ``models.ins_errors``.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from navreplay.pipeline._jit import njit
from navreplay.pipeline.nav.earth import F64, I64, radii
from navreplay.pipeline.nav.mechanization import (
    LANES,
    LN_COS,
    LN_DF,
    LN_DW,
    LN_F0,
    LN_K,
    LN_LAT,
    LN_SIN,
    LN_W0,
    NAV_DIM,
    propagate_into,
    propagate_lanes_into,
    quat_dcm,
)

FULL_DIM = 18
X_LAT, X_LON, X_H, X_VEL, X_Q, X_BA, X_BG, X_CB, X_CD = 0, 1, 2, 3, 6, 10, 13, 16, 17
E_POS, E_VEL, E_ATT, E_BA, E_BG, E_CB, E_CD = 0, 3, 6, 9, 12, 15, 16
N_LOOSE, N_TIGHT = 15, 17

# Layout of the per-span accumulator filled by ``propagate_span``.
ACC_FN = 0  # 0..2: integral of C_b^n f_b dt (nav-frame specific force), m/s
ACC_C = 3  # 3..11: integral of C_b^n dt (row-major), s
ACC_T = 12  # span duration, s
ACC_GAP = 13  # total duration of IMU gaps inside the span, s
ACC_SO = 14  # 14..16: white velocity noise densities of the second-order term, m^2/s^3
ACC_DIM = 17


class ImuSpan(NamedTuple):
    """The IMU input of one span between two stops (``propagate_span``).

    Attributes:
        imu_t: sample times, int64 ns, strictly increasing, (N,).
        imu: samples ``[f_x, f_y, f_z, w_x, w_y, w_z]`` in body FRD, (N, 6).
        i: index of the first sample later than ``t_start``.
        t_start: span start, int64 ns.
        u_start: the input at ``t_start`` (interpolated), (6,).
        t_end: span end, int64 ns, ``>= t_start``.
    """

    imu_t: I64
    imu: F64
    i: int
    t_start: int
    u_start: F64
    t_end: int


class Stepping(NamedTuple):
    """How a span is integrated.

    Attributes:
        substeps: RK4 steps per IMU interval.
        max_step_s: longest RK4 step, s (a longer interval takes more steps).
        gap_s: sample intervals longer than this are IMU gaps (their time is accumulated).
    """

    substeps: int
    max_step_s: float
    gap_s: float


class SpanWork(NamedTuple):
    """What propagating a span writes besides the states (``span_work`` allocates it).

    Attributes:
        u_end: the input at the span's end, (6,).
        work: scratch, (9, 10) (rows 5-8: the interval end inputs).
        acc: the span accumulator (``ACC_*``, ``ACC_DIM``,): integrals of the nav-frame
            specific force and of ``C_b^n``, span and gap durations, for ``transition``.
    """

    u_end: F64
    work: F64
    acc: F64


@njit(cache=True, error_model="numpy")
def span_work() -> SpanWork:
    """A zeroed ``SpanWork``."""
    return SpanWork(np.zeros(6), np.zeros((9, 10)), np.zeros(ACC_DIM))


@njit(cache=True, inline="always", error_model="numpy")
def _exp_mul(a0: float, a1: float, a2: float, q: F64) -> tuple[float, float, float, float]:
    """``Exp(a) * q`` (rotation vector ``a`` applied on the left), unit, scalar part >= 0."""
    angle = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
    if angle < 1e-8:  # Taylor of cos(x/2) and sin(x/2)/x, as rotations.rotvec_to_quat
        pw, k = 1.0 - angle * angle / 8.0, 0.5 - angle * angle / 48.0
    else:
        pw, k = math.cos(0.5 * angle), math.sin(0.5 * angle) / angle
    px, py, pz = a0 * k, a1 * k, a2 * k
    w = pw * q[0] - px * q[1] - py * q[2] - pz * q[3]
    x = pw * q[1] + px * q[0] + py * q[3] - pz * q[2]
    y = pw * q[2] - px * q[3] + py * q[0] + pz * q[1]
    z = pw * q[3] + px * q[2] - py * q[1] + pz * q[0]
    n = math.sqrt(w * w + x * x + y * y + z * z)
    s = 1.0 / n if w >= 0.0 else -1.0 / n
    return w * s, x * s, y * s, z * s


@njit(cache=True, inline="always", error_model="numpy")
def _log_div(q: F64, r: F64) -> tuple[float, float, float]:
    """Rotation vector of ``q * r^-1`` (angle in [0, pi])."""
    w = q[0] * r[0] + q[1] * r[1] + q[2] * r[2] + q[3] * r[3]
    x = -q[0] * r[1] + q[1] * r[0] - q[2] * r[3] + q[3] * r[2]
    y = -q[0] * r[2] + q[1] * r[3] + q[2] * r[0] - q[3] * r[1]
    z = -q[0] * r[3] - q[1] * r[2] + q[2] * r[1] + q[3] * r[0]
    if w < 0.0:
        w, x, y, z = -w, -x, -y, -z
    sv = math.sqrt(x * x + y * y + z * z)
    if sv < 1e-12:
        return 2.0 * x, 2.0 * y, 2.0 * z
    k = 2.0 * math.atan2(sv, w) / sv
    return x * k, y * k, z * k


@njit(cache=True, error_model="numpy")
def dcm_into(q: F64, C: F64) -> None:
    """C_b^n of the unit quaternion ``q`` (as ``rotations.quat_to_dcm``) into ``C`` (3, 3)."""
    c = quat_dcm(q[0], q[1], q[2], q[3])
    C[0, 0], C[0, 1], C[0, 2] = c[0], c[1], c[2]
    C[1, 0], C[1, 1], C[1, 2] = c[3], c[4], c[5]
    C[2, 0], C[2, 1], C[2, 2] = c[6], c[7], c[8]


@njit(cache=True, error_model="numpy")
def inject(X: F64, dx: F64, n: int) -> None:
    """Apply an error-state correction in place: ``X <- X [+] dx`` (see the module docstring).

    Args:
        X: full state, shape (18,), modified in place.
        dx: error state, shape (>= n,).
        n: error-state dimension, 15 or 17.
    """
    lat, h = X[X_LAT], X[X_H]
    rm, rn = radii(lat)
    X[X_LAT] = lat + dx[E_POS] / (rm + h)
    X[X_LON] += dx[E_POS + 1] / ((rn + h) * math.cos(lat))
    X[X_H] = h - dx[E_POS + 2]
    for j in range(3):
        X[X_VEL + j] += dx[E_VEL + j]
        X[X_BA + j] += dx[E_BA + j]
        X[X_BG + j] += dx[E_BG + j]
    w, x, y, z = _exp_mul(dx[E_ATT], dx[E_ATT + 1], dx[E_ATT + 2], X[X_Q : X_Q + 4])
    X[X_Q], X[X_Q + 1], X[X_Q + 2], X[X_Q + 3] = w, x, y, z
    if n > N_LOOSE:
        X[X_CB] += dx[E_CB]
        X[X_CD] += dx[E_CD]


@njit(cache=True, error_model="numpy")
def difference(Xa: F64, Xb: F64, n: int) -> F64:
    """The error state ``dx`` with ``inject(Xb, dx) == Xa`` (exact inverse of ``inject``).

    Returns:
        shape (n,): NED position offset (radii at ``Xb``), velocity, the nav-frame rotation
        vector of ``q_a * q_b^-1``, bias and clock differences.
    """
    dx = np.zeros(n)
    lat, h = Xb[X_LAT], Xb[X_H]
    rm, rn = radii(lat)
    dx[E_POS] = (Xa[X_LAT] - lat) * (rm + h)
    dlon = Xa[X_LON] - Xb[X_LON]
    dlon -= 2.0 * math.pi * round(dlon / (2.0 * math.pi))
    dx[E_POS + 1] = dlon * (rn + h) * math.cos(lat)
    dx[E_POS + 2] = -(Xa[X_H] - h)
    for j in range(3):
        dx[E_VEL + j] = Xa[X_VEL + j] - Xb[X_VEL + j]
        dx[E_BA + j] = Xa[X_BA + j] - Xb[X_BA + j]
        dx[E_BG + j] = Xa[X_BG + j] - Xb[X_BG + j]
    a0, a1, a2 = _log_div(Xa[X_Q : X_Q + 4], Xb[X_Q : X_Q + 4])
    dx[E_ATT], dx[E_ATT + 1], dx[E_ATT + 2] = a0, a1, a2
    if n > N_LOOSE:
        dx[E_CB] = Xa[X_CB] - Xb[X_CB]
        dx[E_CD] = Xa[X_CD] - Xb[X_CD]
    return dx


@njit(cache=True, error_model="numpy")
def to_full(s: F64, q_ref: F64, n: int, X: F64) -> None:
    """UKF coordinates ``s`` (n,) and reference quaternion -> full state ``X`` (18,), in place.

    ``q = Exp(a) * q_ref``; allocation-free (called for every sigma point at every stop).
    """
    for j in range(3):
        X[j] = s[j]
        X[X_VEL + j] = s[E_VEL + j]
        X[X_BA + j] = s[E_BA + j]
        X[X_BG + j] = s[E_BG + j]
    w, x, y, z = _exp_mul(s[E_ATT], s[E_ATT + 1], s[E_ATT + 2], q_ref)
    X[X_Q], X[X_Q + 1], X[X_Q + 2], X[X_Q + 3] = w, x, y, z
    if n > N_LOOSE:
        X[X_CB] = s[E_CB]
        X[X_CD] = s[E_CD]
    else:
        X[X_CB] = 0.0
        X[X_CD] = 0.0


@njit(cache=True, error_model="numpy")
def from_full(X: F64, q_ref: F64, n: int, s: F64) -> None:
    """Full state ``X`` -> UKF coordinates ``s`` relative to ``q_ref``, in place."""
    for j in range(3):
        s[j] = X[j]
        s[E_VEL + j] = X[X_VEL + j]
        s[E_BA + j] = X[X_BA + j]
        s[E_BG + j] = X[X_BG + j]
    a0, a1, a2 = _log_div(X[X_Q : X_Q + 4], q_ref)
    s[E_ATT], s[E_ATT + 1], s[E_ATT + 2] = a0, a1, a2
    if n > N_LOOSE:
        s[E_CB] = X[X_CB]
        s[E_CD] = X[X_CD]


@njit(cache=True, error_model="numpy")
def coords_scale(X: F64, n: int, out: F64) -> None:
    """Diagonal of the map from error coordinates to UKF coordinates at ``X``, shape (n,).

    Only the position block differs: d(lat) = dr_n / (R_M + h), d(lon) = dr_e / ((R_N + h)
    cos lat), d(h) = -dr_d; the attitude block is the identity (both are left rotation
    vectors in NED).
    """
    rm, rn = radii(X[X_LAT])
    h = X[X_H]
    for j in range(n):
        out[j] = 1.0
    out[0] = 1.0 / (rm + h)
    out[1] = 1.0 / ((rn + h) * math.cos(X[X_LAT]))
    out[2] = -1.0


@njit(cache=True, inline="always", error_model="numpy")
def _span_start(span: ImuSpan, out: SpanWork, accumulate: bool) -> tuple[int, int, int]:
    """Start a span: the input ``out.u_end`` at its start, the accumulator zeroed if
    ``accumulate``; returns (next sample, start time, end time)."""
    if accumulate:
        for j in range(ACC_DIM):
            out.acc[j] = 0.0
    for j in range(6):
        out.u_end[j] = span.u_start[j]
    return span.i, span.t_start, span.t_end


@njit(cache=True, inline="always", error_model="numpy")
def _next_interval(
    span: ImuSpan, i: int, t_cur: int, step: Stepping, u_cur: F64, f1: F64, w1: F64
) -> tuple[bool, int, float, int, bool]:
    """The interval of ``span`` from ``t_cur`` (``i``: the next sample, ``u_cur``: the input
    at ``t_cur``): (ends at sample ``i``, its end time, its length in s, RK4 steps:
    ``substeps``, more if a step would exceed ``max_step_s``, it lies in an IMU gap: samples
    ``i - 1`` and ``i`` further apart than ``gap_s``, however the stops cut that gap); the
    raw input at its end into ``f1``, ``w1`` (``_target_input``)."""
    imu_t, substeps, max_step_s = span.imu_t, step.substeps, step.max_step_s
    advance = i < imu_t.shape[0] and imu_t[i] <= span.t_end
    t_next = imu_t[i] if advance else span.t_end
    dt = (t_next - t_cur) * 1e-9
    ns = substeps
    if dt > max_step_s * substeps:
        ns = math.ceil(dt / max_step_s)
    in_gap = 0 < i < imu_t.shape[0] and (imu_t[i] - imu_t[i - 1]) * 1e-9 > step.gap_s
    _target_input(span, i, t_cur, advance, u_cur, f1, w1)
    return advance, t_next, dt, ns, in_gap


@njit(cache=True, inline="always", error_model="numpy")
def _target_input(
    span: ImuSpan, i: int, t_cur: int, advance: bool, u_cur: F64, f1: F64, w1: F64
) -> None:
    """The raw input at the end of the next interval of ``span`` (from ``t_cur``, input
    ``u_cur``): sample ``i``, or the input interpolated at ``t_end`` (``u_cur`` lies on the
    segment to sample ``i``), or ``u_cur`` held after the last sample."""
    imu_t, imu, t_end = span.imu_t, span.imu, span.t_end
    if advance:
        for j in range(3):
            f1[j] = imu[i, j]
            w1[j] = imu[i, 3 + j]
    elif i < imu_t.shape[0]:
        a = (t_end - t_cur) / (imu_t[i] - t_cur)
        for j in range(3):
            f1[j] = u_cur[j] + a * (imu[i, j] - u_cur[j])
            w1[j] = u_cur[3 + j] + a * (imu[i, 3 + j] - u_cur[3 + j])
    else:
        for j in range(3):
            f1[j] = u_cur[j]
            w1[j] = u_cur[3 + j]


@njit(cache=True, inline="always", error_model="numpy")
def _accumulate(nav: F64, f0: F64, f1: F64, dt: float, acc: F64) -> None:
    """acc += (C_b^n mean(f0, f1) dt, C_b^n dt) with C_b^n at the interval start."""
    c00, c01, c02, c10, c11, c12, c20, c21, c22 = quat_dcm(nav[6], nav[7], nav[8], nav[9])
    fx, fy, fz = 0.5 * (f0[0] + f1[0]), 0.5 * (f0[1] + f1[1]), 0.5 * (f0[2] + f1[2])
    acc[ACC_FN] += dt * (c00 * fx + c01 * fy + c02 * fz)
    acc[ACC_FN + 1] += dt * (c10 * fx + c11 * fy + c12 * fz)
    acc[ACC_FN + 2] += dt * (c20 * fx + c21 * fy + c22 * fz)
    acc[ACC_C] += dt * c00
    acc[ACC_C + 1] += dt * c01
    acc[ACC_C + 2] += dt * c02
    acc[ACC_C + 3] += dt * c10
    acc[ACC_C + 4] += dt * c11
    acc[ACC_C + 5] += dt * c12
    acc[ACC_C + 6] += dt * c20
    acc[ACC_C + 7] += dt * c21
    acc[ACC_C + 8] += dt * c22


@njit(cache=True, inline="always", error_model="numpy")
def _accumulate_interval(nav: F64, f0: F64, f1: F64, dt: float, in_gap: bool, acc: F64) -> None:
    """One interval into the span accumulator: ``_accumulate``, its duration, and, if it lies
    in an IMU gap (``_next_interval``), the part of the gap it covers."""
    _accumulate(nav, f0, f1, dt, acc)
    acc[ACC_T] += dt
    if in_gap:
        acc[ACC_GAP] += dt


@njit(cache=True, error_model="numpy")
def propagate_span(X: F64, span: ImuSpan, step: Stepping, out: SpanWork, accumulate: bool) -> int:
    """Integrate the full state ``X`` in place over ``span`` (paper 001 eq. 1-3).

    The clock bias integrates the drift (``cb += cd T``). The IMU input is ``span.u_start``
    (6: specific force, angular rate; interpolated at ``t_start``), then every sample
    ``i, i+1, ...`` with ``t_start < imu_t <= t_end``, then the input interpolated at
    ``t_end`` (held if no later sample exists); between inputs it is
    linear. Each interval is integrated by ``propagate_into`` with ``step.substeps`` RK4
    steps, more if an interval exceeds ``step.max_step_s``; the state's own biases correct
    the input.

    Args:
        X: full state (18,), propagated in place.
        span: the IMU samples and the span's limits (``ImuSpan``).
        step: the RK4 stepping and the IMU gap length (``Stepping``).
        out: ``u_end`` receives the input at ``t_end``; ``work`` is scratch; ``acc`` is
            filled when ``accumulate`` (``SpanWork``).
        accumulate: fill ``out.acc`` (done for the EKF nominal and the UKF central sigma
            point).

    Returns:
        The index of the first sample later than ``t_end``.
    """
    nav = X[:NAV_DIM]
    u_end, work, acc = out.u_end, out.work, out.acc
    f0, w0, f1, w1 = work[5, :3], work[6, :3], work[7, :3], work[8, :3]
    i, t_cur, t_end = _span_start(span, out, accumulate)
    while t_cur < t_end:
        advance, t_next, dt, ns, in_gap = _next_interval(span, i, t_cur, step, u_end, f1, w1)
        for j in range(3):
            f0[j] = u_end[j] - X[X_BA + j]
            w0[j] = u_end[3 + j] - X[X_BG + j]
            u_end[j] = f1[j]
            u_end[3 + j] = w1[j]
            f1[j] -= X[X_BA + j]
            w1[j] -= X[X_BG + j]
        if accumulate:
            _accumulate_interval(nav, f0, f1, dt, in_gap, acc)
        propagate_into(nav, f0, w0, f1, w1, dt, ns, nav)
        t_cur = t_next
        if advance:
            i += 1
    X[X_CB] += X[X_CD] * ((t_end - span.t_start) * 1e-9)
    return i


@njit(cache=True, inline="always", error_model="numpy")
def _lane_inputs(X: F64, lanes: I64, m: int, u0: F64, f1: F64, w1: F64, Y: F64) -> None:
    """Each lane's interval inputs, corrected with its own biases, as ``propagate_span``
    forms them (raw input ``u0`` at the start, ``f1``/``w1`` at the end), and its reference
    latitude (the interval start's) with sine and cosine."""
    L = LANES
    for b in range(m):
        xb = X[lanes[b]]
        for j in range(3):
            f0 = u0[j] - xb[X_BA + j]
            w0 = u0[3 + j] - xb[X_BG + j]
            Y[(LN_F0 + j) * L + b] = f0
            Y[(LN_W0 + j) * L + b] = w0
            Y[(LN_DF + j) * L + b] = (f1[j] - xb[X_BA + j]) - f0
            Y[(LN_DW + j) * L + b] = (w1[j] - xb[X_BG + j]) - w0
        Y[LN_SIN * L + b] = math.sin(Y[b])
        Y[LN_COS * L + b] = math.cos(Y[b])
        Y[LN_LAT * L + b] = Y[b]


@njit(cache=True, inline="always", error_model="numpy")
def _accumulate_lane0(
    X0: F64, Y: F64, u0: F64, f1: F64, dt: float, in_gap: bool, out: SpanWork
) -> None:
    """``propagate_span``'s accumulation over one interval for lane 0 (state ``X0`` at the
    span start for its biases, its current navigation state in ``Y``) into ``out.acc``."""
    work = out.work
    f0c, f1c, nav0 = work[5, :3], work[6, :3], work[4]
    for j in range(3):
        f0c[j] = u0[j] - X0[X_BA + j]
        f1c[j] = f1[j] - X0[X_BA + j]
    for d in range(NAV_DIM):
        nav0[d] = Y[d * LANES]
    _accumulate_interval(nav0, f0c, f1c, dt, in_gap, out.acc)


@njit(cache=True, error_model="numpy")
def propagate_sigmas(
    X: F64, lanes: I64, m: int, span: ImuSpan, step: Stepping, out: SpanWork, Y: F64
) -> int:
    """``propagate_span`` for the rows ``X[lanes[:m]]`` of a stack of full states at once.

    Each row ends bitwise where ``propagate_span`` would take it (the same inputs, bias
    corrections and RK4 operations; ``mechanization.propagate_lanes_into`` integrates all rows
    of an interval together, which is what makes this faster). ``acc`` is filled along row
    ``lanes[0]`` (the UKF's central sigma point) into ``out.acc``, as
    ``propagate_span(..., accumulate=True)`` does. ``Y`` is workspace,
    (``mechanization.LN_DIM * mechanization.LANES``,); ``m`` is 1 to ``LANES``.

    Returns:
        The index of the first sample later than ``t_end``.
    """
    L = LANES
    u_end = out.u_end
    f1, w1 = out.work[7, :3], out.work[8, :3]
    if not 0 < m <= L:
        raise ValueError("propagate_sigmas: needs 1 to mechanization.LANES states")
    for b in range(m):
        for d in range(NAV_DIM):
            Y[d * L + b] = X[lanes[b], d]
            Y[(LN_K + d) * L + b] = 0.0
    i, t_cur, t_end = _span_start(span, out, True)
    while t_cur < t_end:
        advance, t_next, dt, ns, in_gap = _next_interval(span, i, t_cur, step, u_end, f1, w1)
        _lane_inputs(X, lanes, m, u_end, f1, w1, Y)
        _accumulate_lane0(X[lanes[0]], Y, u_end, f1, dt, in_gap, out)
        for j in range(3):
            u_end[j] = f1[j]
            u_end[3 + j] = w1[j]
        propagate_lanes_into(Y, m, dt, ns)
        t_cur = t_next
        if advance:
            i += 1
    T = (t_end - span.t_start) * 1e-9
    for b in range(m):
        xb = X[lanes[b]]
        for d in range(NAV_DIM):
            xb[d] = Y[d * L + b]
        xb[X_CB] += xb[X_CD] * T
    return i
