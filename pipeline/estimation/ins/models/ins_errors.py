"""Error dynamics of the strapdown INS: the EKF's predict model and the UKF's process noise.

Paper 001 eq. 4-6 in the error convention of ``models.ins`` (``dx`` = truth minus estimate,
NED position offsets, nav-frame attitude rotation vector), extended by random-walk sensor
biases and the two-state receiver clock. ``transition`` turns the continuous dynamics ``F``
into the discrete ``Phi`` and ``Qd`` of one span, using the span means that
``ins.propagate_span`` accumulates; the EKF propagates its covariance with them, the UKF adds
``Qd`` (mapped into its coordinates) once per span.
"""

from __future__ import annotations

import math

import numpy as np

from navreplay.pipeline._jit import njit
from navreplay.pipeline.estimation.ins.models.ins import (
    ACC_C,
    ACC_FN,
    ACC_GAP,
    ACC_SO,
    ACC_T,
    E_ATT,
    E_BA,
    E_BG,
    E_CB,
    E_CD,
    E_POS,
    E_VEL,
    N_LOOSE,
    X_CB,
    X_CD,
    X_H,
    X_LAT,
    X_Q,
    X_VEL,
    dcm_into,
)
from navreplay.pipeline.nav.earth import E2, F64, OMEGA_IE, A, gravity

# Indices of the noise vector handed to ``transition`` (see ``noise_vector``).
NZ_ACC, NZ_GYR, NZ_BA, NZ_BG, NZ_CB, NZ_CD, NZ_GAP_ACC, NZ_GAP_GYR, NZ_GM_RATE = range(9)
NZ_SO_CORR = 9
NOISE_DIM = 10


def noise_vector(
    accel_noise_mps2_rthz: float,
    gyro_noise_radps_rthz: float,
    accel_bias_rw_mps3_rthz: float,
    gyro_bias_rw_radps2_rthz: float,
    clock_bias_psd_m2ps: float,
    clock_drift_psd_m2ps3: float,
    gap_accel_psd_m2ps3: float,
    gap_gyro_psd_rad2ps: float,
    fix_error: tuple[float, float] = (0.0, 0.0),
    second_order_corr_s: float = 0.0,
) -> F64:
    """Pack the continuous noise model into the vector ``transition`` reads.

    White-noise densities (per root hertz) are squared into power spectral densities; the
    clock and gap entries are already densities. ``fix_error`` (tau s, sigma m; tau 0: none)
    turns a loosely coupled filter's states 15 and 16 (the tightly coupled clock's) into
    first-order Gauss-Markov fix errors, north and east (``inputs.fix_error_states``): rate
    ``1 / tau`` and driving density ``2 sigma^2 / tau`` in place of the clock's.
    ``second_order_corr_s``: the correlation time ``second_order_noise`` gives the term the
    linearised velocity error leaves out (0: none).
    """
    tau, sigma = fix_error
    if tau > 0.0:
        clock_bias_psd_m2ps = clock_drift_psd_m2ps3 = 2.0 * sigma * sigma / tau
    return np.array(
        [
            accel_noise_mps2_rthz**2,
            gyro_noise_radps_rthz**2,
            accel_bias_rw_mps3_rthz**2,
            gyro_bias_rw_radps2_rthz**2,
            clock_bias_psd_m2ps,
            clock_drift_psd_m2ps3,
            gap_accel_psd_m2ps3,
            gap_gyro_psd_rad2ps,
            1.0 / tau if tau > 0.0 else 0.0,
            second_order_corr_s,
        ]
    )


@njit(cache=True, error_model="numpy")
def _span_mean_dcm(acc: F64, C: F64) -> None:
    """The span's mean ``C_b^n`` into ``C`` (3, 3) from the accumulator (its ``ACC_T`` > 0)."""
    T = acc[ACC_T]
    for r in range(3):
        for c in range(3):
            C[r, c] = acc[ACC_C + 3 * r + c] / T


@njit(cache=True, error_model="numpy")
def second_order_noise(P: F64, acc: F64, noise: F64) -> None:
    """The velocity noise of the term the linearised velocity error leaves out, into
    ``acc[ACC_SO : ACC_SO + 3]`` (white densities per NED axis, m^2/s^3; zero with
    ``noise[NZ_SO_CORR]`` 0), from the covariance ``P`` (error coordinates, at least in the
    attitude and accelerometer-bias blocks) at the start of the span ``acc`` describes.

    The velocity error's rate holds ``psi x (C db)``, the product of the attitude error and the
    accelerometer-bias error in the nav frame, which the Jacobian drops. A consumer bias of
    0.5 m/s^2 that levelling put into a 0.05 rad tilt makes it 0.03 m/s^2: left out, the
    filter explains the vertical and horizontal velocity it drives with a lateral bias and a
    roll the first minutes of straight driving cannot tell apart, and is confident of both
    while 4-5 sigma off (issue 22: NEES 3 to 25 x dof). Its variance per axis under the
    filter's own Gaussian (Isserlis: ``Var(ab) = P_aa P_bb + P_ab^2``,
    ``Cov(ab, cd) = P_ac P_bd + P_ad P_bc``) enters as a first-order Gauss-Markov
    acceleration of correlation time ``tau = noise[NZ_SO_CORR]``, white at the low-frequency
    density ``2 tau Var``. It vanishes as either error becomes known (a tactical-grade bias,
    or after the first turns)."""
    for i in range(3):
        acc[ACC_SO + i] = 0.0
    tau, T = noise[NZ_SO_CORR], acc[ACC_T]
    if tau <= 0.0 or T <= 0.0:
        return
    C, A = np.empty((3, 3)), np.empty((3, 3))
    PbC, B, X = np.zeros((3, 3)), np.zeros((3, 3)), np.zeros((3, 3))
    _span_mean_dcm(acc, C)
    for r in range(3):
        for c in range(3):
            A[r, c] = P[E_ATT + r, E_ATT + c]
    for r in range(3):  # P_bb C^T, then B = C P_bb C^T (u = C db), X = P_psi,b C^T
        for c in range(3):
            for q in range(3):
                PbC[r, c] += P[E_BA + r, E_BA + q] * C[c, q]
                X[r, c] += P[E_ATT + r, E_BA + q] * C[c, q]
    for r in range(3):
        for c in range(3):
            for q in range(3):
                B[r, c] += C[r, q] * PbC[q, c]
    for i in range(3):  # e_i = psi_j u_k - psi_k u_j
        j, k = (i + 1) % 3, (i + 2) % 3
        var = (
            A[j, j] * B[k, k] + X[j, k] ** 2
            + A[k, k] * B[j, j] + X[k, j] ** 2
            - 2.0 * (A[j, k] * B[k, j] + X[j, j] * X[k, k])
        )  # fmt: skip
        acc[ACC_SO + i] = 2.0 * tau * max(var, 0.0)


@njit(cache=True, error_model="numpy")
def _dgravity_dh(lat: float, h: float) -> float:
    """d g / d h of ``earth.gravity`` (normal gravity decreases with height), 1/s^2."""
    return (gravity(lat, h + 1.0) - gravity(lat, h - 1.0)) / 2.0


@njit(cache=True, error_model="numpy")
def error_jacobian(X: F64, f_n: F64, C: F64, n: int, F: F64) -> None:
    """Continuous error dynamics ``d(dx)/dt = F dx`` at the full state ``X`` (eq. 4-6).

    With the conventions of ``models.ins`` (``dx`` = truth minus estimate):

    - position:  d(dr)/dt   = dv + F_rr dr (transport of the NED offsets),
    - velocity:  d(dv)/dt   = -[f^n x] phi - C_b^n dba - (2 w_ie + w_en) x dv
                              - (2 dw_ie + dw_en) x v + dg,
    - attitude:  d(phi)/dt  = -w_in x phi - C_b^n dbg - dw_in,
    - biases random walks, clock: d(dcb)/dt = dcd.

    ``dw_ie`` and ``dw_en`` are the changes of the earth and transport rates with the position
    and velocity errors (``m_ie``, ``m_en``, ``m_ev`` below). Written out element by element:
    small-matrix numpy code costs numba seconds of compilation.

    Args:
        X: full state, (18,).
        f_n: specific force resolved in NED (bias-corrected), m/s^2, (3,).
        C: the body-to-NED rotation coupling the biases, (3, 3) (``transition`` passes the
            span mean of ``C_b^n``; ``ins.dcm_into`` of the state for the instant).
        n: error-state dimension, 15 or 17.
        F: out, (n, n), overwritten.
    """
    lat, h = X[X_LAT], X[X_H]
    vn, ve, vd = X[X_VEL], X[X_VEL + 1], X[X_VEL + 2]
    sl, cl = math.sin(lat), math.cos(lat)
    tl = sl / cl
    w2 = 1.0 - E2 * sl * sl
    rn = A / math.sqrt(w2)
    rm = rn * (1.0 - E2) / w2
    rmh, rnh = rm + h, rn + h
    # earth rate, transport rate and their sum w_in; Coriolis rate 2 w_ie + w_en
    ie = (OMEGA_IE * cl, 0.0, -OMEGA_IE * sl)
    en = (ve / rnh, -vn / rmh, -ve * tl / rnh)
    win = (ie[0] + en[0], ie[1] + en[1], ie[2] + en[2])
    cor = (2.0 * ie[0] + en[0], 2.0 * ie[1] + en[1], 2.0 * ie[2] + en[2])
    # m_ie = d w_ie / d dr, m_en = d w_en / d dr, m_ev = d w_en / d dv: their nonzero entries
    ie00, ie20 = -OMEGA_IE * sl / rmh, -OMEGA_IE * cl / rmh
    en02, en12 = ve / (rnh * rnh), -vn / (rmh * rmh)
    en20, en22 = -ve / (cl * cl * rnh * rmh), -ve * tl / (rnh * rnh)
    ev01, ev10, ev21 = 1.0 / rnh, -1.0 / rmh, -tl / rnh
    for r in range(n):
        for c in range(n):
            F[r, c] = 0.0
    # position rows
    F[0, 0] = -vd / rmh
    F[0, 2] = vn / rmh
    F[1, 0] = ve * tl / rmh
    F[1, 1] = -(vd / rnh + vn * tl / rmh)
    F[1, 2] = ve / rnh
    for j in range(3):
        F[E_POS + j, E_VEL + j] = 1.0
    # velocity rows: -(2 dw_ie + dw_en) x v = [v x] (M dr + m_ev dv), M = 2 m_ie + m_en,
    # [v x] = [[0, -vd, ve], [vd, 0, -vn], [-ve, vn, 0]]; columns 1 of M and 2 of m_ev are 0
    m00, m20 = 2.0 * ie00, 2.0 * ie20 + en20
    F[E_VEL, E_POS] = ve * m20
    F[E_VEL, E_POS + 2] = -vd * en12 + ve * en22
    F[E_VEL + 1, E_POS] = vd * m00 - vn * m20
    F[E_VEL + 1, E_POS + 2] = vd * en02 - vn * en22
    F[E_VEL + 2, E_POS] = -ve * m00
    F[E_VEL + 2, E_POS + 2] = -ve * en02 + vn * en12
    F[E_VEL, E_VEL] = -vd * ev10
    F[E_VEL, E_VEL + 1] = ve * ev21
    F[E_VEL + 1, E_VEL + 1] = vd * ev01 - vn * ev21
    F[E_VEL + 2, E_VEL] = vn * ev10
    F[E_VEL + 2, E_VEL + 1] = -ve * ev01
    # attitude rows: -(dw_ie + dw_en) = -(m_ie + m_en) dr - m_ev dv
    F[E_ATT, E_POS] = -ie00
    F[E_ATT, E_POS + 2] = -en02
    F[E_ATT + 1, E_POS + 2] = -en12
    F[E_ATT + 2, E_POS] = -(ie20 + en20)
    F[E_ATT + 2, E_POS + 2] = -en22
    F[E_ATT, E_VEL + 1] = -ev01
    F[E_ATT + 1, E_VEL] = -ev10
    F[E_ATT + 2, E_VEL + 1] = -ev21
    # the cross-product blocks (Coriolis, specific force, w_in) and the bias couplings
    fx = (f_n[0], f_n[1], f_n[2])
    for r in range(3):
        for c in range(3):
            F[E_VEL + r, E_VEL + c] -= _cross_entry(cor, r, c)
            F[E_VEL + r, E_ATT + c] = -_cross_entry(fx, r, c)
            F[E_VEL + r, E_BA + c] = -C[r, c]
            F[E_ATT + r, E_ATT + c] = -_cross_entry(win, r, c)
            F[E_ATT + r, E_BG + c] = -C[r, c]
    # gravity: g grows downwards as the height drops (dh = -dr_d)
    F[E_VEL + 2, E_POS + 2] += -_dgravity_dh(lat, h)
    if n > N_LOOSE:
        F[E_CB, E_CD] = 1.0


@njit(cache=True, inline="always", error_model="numpy")
def _cross_entry(a: tuple[float, float, float], r: int, c: int) -> float:
    """Entry (r, c) of the cross-product matrix [a x]."""
    if r == c:
        return 0.0
    if r == 0:
        return -a[2] if c == 1 else a[1]
    if r == 1:
        return a[2] if c == 0 else -a[0]
    return -a[1] if c == 0 else a[0]


@njit(cache=True, error_model="numpy")
def transition(X: F64, acc: F64, noise: F64, n: int, Phi: F64, Qd: F64) -> None:
    """Error-state transition and process noise over one span (the EKF's predict model); with
    Gauss-Markov fix-error states (``noise_vector``'s ``fix_error``) also their estimate in
    ``X``, which decays over the span (``exp(-T / tau)``).

    ``Phi = I + F T + (F T)^2 / 2`` with ``F = error_jacobian`` at the end-of-span state with
    the span means of the nav-frame specific force and of ``C_b^n`` (so the first-order term
    is the exact integral of the bias couplings while the body turns);
    ``Qd = (Phi D Phi^T + D) T / 2`` (trapezoid) with ``D`` the diagonal continuous noise
    (accel and gyro white noise, bias random walks, clock; the velocity's with the span's
    ``second_order_noise``).
    Time spent inside IMU gaps (``T_g``, bridged by interpolating the samples on both sides)
    adds white acceleration and rotation-rate noise of densities ``noise[NZ_GAP_ACC]``,
    ``noise[NZ_GAP_GYR]`` for the vehicle's unknown manoeuvres: velocity ``q_a T_g``, position
    ``q_a T_g^3 / 3`` (correlated ``q_a T_g^2 / 2``), attitude ``q_w T_g``. Being white, it
    adds up the same however the stops cut the gap.

    Args:
        X: full state at the end of the span, (18,).
        acc: accumulator of ``propagate_span`` (``ACC_DIM``,).
        noise: ``noise_vector(...)``, (``NOISE_DIM``,).
        n: error-state dimension.
        Phi, Qd: out, (n, n).
    """
    T = acc[ACC_T]
    f_n = np.zeros(3)
    C = np.empty((3, 3))
    if T > 0.0:
        for j in range(3):
            f_n[j] = acc[ACC_FN + j] / T
        _span_mean_dcm(acc, C)
    else:
        f_n[2] = -gravity(X[X_LAT], X[X_H])
        dcm_into(X[X_Q : X_Q + 4], C)
    F = np.empty((n, n))
    error_jacobian(X, f_n, C, n, F)
    if n > N_LOOSE and noise[NZ_GM_RATE] > 0.0:  # Gauss-Markov fix errors, not a clock
        F[E_CB, E_CD] = 0.0
        F[E_CB, E_CB] = F[E_CD, E_CD] = -noise[NZ_GM_RATE]
        # their estimate decays to the mean (propagate_span integrated it as a clock's)
        X[X_CB] -= X[X_CD] * T
        decay = math.exp(-T * noise[NZ_GM_RATE])
        X[X_CB] *= decay
        X[X_CD] *= decay
    for r in range(n):  # Phi = I + F T + (F T)^2 / 2
        for c in range(n):
            a = 0.0
            for k in range(n):
                a += F[r, k] * F[k, c]
            Phi[r, c] = F[r, c] * T + 0.5 * a * T * T
        Phi[r, r] += 1.0
    d = np.zeros(n)
    for j in range(3):
        d[E_VEL + j] = noise[NZ_ACC] + acc[ACC_SO + j]
        d[E_ATT + j] = noise[NZ_GYR]
        d[E_BA + j] = noise[NZ_BA]
        d[E_BG + j] = noise[NZ_BG]
    if n > N_LOOSE:
        d[E_CB] = noise[NZ_CB]
        d[E_CD] = noise[NZ_CD]
    for r in range(n):  # Qd = (Phi D Phi^T + D) T / 2
        for c in range(r, n):
            a = 0.0
            for k in range(n):
                a += Phi[r, k] * d[k] * Phi[c, k]
            Qd[r, c] = 0.5 * T * a
            Qd[c, r] = Qd[r, c]
        Qd[r, r] += 0.5 * T * d[r]
    tg = acc[ACC_GAP]
    if tg > 0.0:
        qa, qw = noise[NZ_GAP_ACC], noise[NZ_GAP_GYR]
        for j in range(3):
            Qd[E_VEL + j, E_VEL + j] += qa * tg
            Qd[E_POS + j, E_POS + j] += qa * tg**3 / 3.0
            Qd[E_POS + j, E_VEL + j] += qa * tg**2 / 2.0
            Qd[E_VEL + j, E_POS + j] += qa * tg**2 / 2.0
            Qd[E_ATT + j, E_ATT + j] += qw * tg
