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

import numba as nb
import numpy as np

from pipeline.estimation.models.ins import (
    ACC_C,
    ACC_FN,
    ACC_GAP,
    ACC_T,
    E_ATT,
    E_BA,
    E_BG,
    E_CB,
    E_CD,
    E_POS,
    E_VEL,
    N_LOOSE,
    X_H,
    X_LAT,
    X_Q,
    X_VEL,
)
from pipeline.nav.earth import E2, F64, OMEGA_IE, A, gravity
from pipeline.nav.rotations import quat_to_dcm

# Indices of the noise vector handed to ``transition`` (see ``noise_vector``).
NZ_ACC, NZ_GYR, NZ_BA, NZ_BG, NZ_CB, NZ_CD, NZ_GAP_ACC, NZ_GAP_GYR = range(8)
NOISE_DIM = 8


def noise_vector(
    accel_noise_mps2_rthz: float,
    gyro_noise_radps_rthz: float,
    accel_bias_rw_mps3_rthz: float,
    gyro_bias_rw_radps2_rthz: float,
    clock_bias_psd_m2ps: float,
    clock_drift_psd_m2ps3: float,
    gap_accel_sigma_mps2: float,
    gap_gyro_sigma_radps: float,
) -> F64:
    """Pack the continuous noise model into the vector ``transition`` reads.

    White-noise densities are squared into power spectral densities; the gap sigmas are kept
    as 1-sigma values (they scale with the gap duration, see ``transition``).
    """
    return np.array(
        [
            accel_noise_mps2_rthz**2,
            gyro_noise_radps_rthz**2,
            accel_bias_rw_mps3_rthz**2,
            gyro_bias_rw_radps2_rthz**2,
            clock_bias_psd_m2ps,
            clock_drift_psd_m2ps3,
            gap_accel_sigma_mps2,
            gap_gyro_sigma_radps,
        ]
    )


@nb.njit(cache=True)
def _dgravity_dh(lat: float, h: float) -> float:
    """d g / d h of ``earth.gravity`` (normal gravity decreases with height), 1/s^2."""
    eps = 1.0
    return (gravity(lat, h + eps) - gravity(lat, h - eps)) / (2.0 * eps)


@nb.njit(cache=True)
def error_jacobian(X: F64, f_n: F64, C: F64, n: int, F: F64) -> None:
    """Continuous error dynamics ``d(dx)/dt = F dx`` at the full state ``X`` (eq. 4-6).

    With the conventions of the module docstring (``dx`` = truth minus estimate):

    - position:  d(dr)/dt   = dv + F_rr dr (transport of the NED offsets),
    - velocity:  d(dv)/dt   = -[f^n x] phi - C_b^n dba - (2 w_ie + w_en) x dv
                              - (2 dw_ie + dw_en) x v + dg,
    - attitude:  d(phi)/dt  = -w_in x phi - C_b^n dbg - dw_in,
    - biases random walks, clock: d(dcb)/dt = dcd.

    Args:
        X: full state, (18,).
        f_n: specific force resolved in NED (bias-corrected), m/s^2, (3,).
        C: the body-to-NED rotation coupling the biases, (3, 3) (``transition`` passes the
            span mean of ``C_b^n``; use ``quat_to_dcm`` of the state for the instant).
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
    w_ie = np.array([OMEGA_IE * cl, 0.0, -OMEGA_IE * sl])
    w_en = np.array([ve / rnh, -vn / rmh, -ve * tl / rnh])
    v = np.array([vn, ve, vd])
    # partial derivatives of w_ie and w_en w.r.t. dr (NED m) and dv
    m_ie_r = np.zeros((3, 3))
    m_ie_r[0, 0] = -OMEGA_IE * sl / rmh
    m_ie_r[2, 0] = -OMEGA_IE * cl / rmh
    m_en_r = np.zeros((3, 3))
    m_en_r[0, 2] = ve / (rnh * rnh)
    m_en_r[1, 2] = -vn / (rmh * rmh)
    m_en_r[2, 0] = -ve / (cl * cl * rnh * rmh)
    m_en_r[2, 2] = -ve * tl / (rnh * rnh)
    m_en_v = np.zeros((3, 3))
    m_en_v[0, 1] = 1.0 / rnh
    m_en_v[1, 0] = -1.0 / rmh
    m_en_v[2, 1] = -tl / rnh
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
    # velocity rows
    vx = _skew(v)
    cor = 2.0 * w_ie + w_en
    m_vr = vx @ (2.0 * m_ie_r + m_en_r)
    m_vv = -_skew(cor) + vx @ m_en_v
    fx = _skew(f_n)
    w_in = w_ie + w_en
    m_ax = _skew(w_in)
    for r in range(3):
        for c in range(3):
            F[E_VEL + r, E_POS + c] = m_vr[r, c]
            F[E_VEL + r, E_VEL + c] = m_vv[r, c]
            F[E_VEL + r, E_ATT + c] = -fx[r, c]
            F[E_VEL + r, E_BA + c] = -C[r, c]
            F[E_ATT + r, E_POS + c] = -(m_ie_r[r, c] + m_en_r[r, c])
            F[E_ATT + r, E_VEL + c] = -m_en_v[r, c]
            F[E_ATT + r, E_ATT + c] = -m_ax[r, c]
            F[E_ATT + r, E_BG + c] = -C[r, c]
    # gravity: g grows downwards as the height drops (dh = -dr_d)
    F[E_VEL + 2, E_POS + 2] += -_dgravity_dh(lat, h)
    if n > N_LOOSE:
        F[E_CB, E_CD] = 1.0


@nb.njit(cache=True)
def _skew(v: F64) -> F64:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


@nb.njit(cache=True)
def transition(X: F64, acc: F64, noise: F64, n: int, Phi: F64, Qd: F64) -> None:
    """Error-state transition and process noise over one span (the EKF's predict model).

    ``Phi = I + F T + (F T)^2 / 2`` with ``F = error_jacobian`` at the end-of-span state with
    the span means of the nav-frame specific force and of ``C_b^n`` (so the first-order term
    is the exact integral of the bias couplings while the body turns);
    ``Qd = (Phi D Phi^T + D) T / 2`` (trapezoid) with ``D`` the diagonal continuous noise
    (accel and gyro white noise, bias random walks, clock).
    IMU gaps inside the span add the effect of an unknown acceleration and rotation rate
    (``noise[NZ_GAP_*]``) over the gap duration: velocity ``(s_a T_g)^2``, position
    ``(s_a T_g^2 / 2)^2`` (correlated), attitude ``(s_w T_g)^2``.

    Args:
        X: full state at the end of the span, (18,).
        acc: accumulator of ``propagate_span`` (``ACC_DIM``,).
        noise: ``noise_vector(...)``, (``NOISE_DIM``,).
        n: error-state dimension.
        Phi, Qd: out, (n, n).
    """
    T = acc[ACC_T]
    f_n = np.zeros(3)
    if T > 0.0:
        for j in range(3):
            f_n[j] = acc[ACC_FN + j] / T
        C = acc[ACC_C : ACC_C + 9].copy().reshape((3, 3)) / T
    else:
        f_n[2] = -gravity(X[X_LAT], X[X_H])
        C = quat_to_dcm(X[X_Q : X_Q + 4])
    F = np.empty((n, n))
    error_jacobian(X, f_n, C, n, F)
    At = F * T
    Phi[:, :] = At + 0.5 * (At @ At)
    for j in range(n):
        Phi[j, j] += 1.0
    d = np.zeros(n)
    for j in range(3):
        d[E_VEL + j] = noise[NZ_ACC]
        d[E_ATT + j] = noise[NZ_GYR]
        d[E_BA + j] = noise[NZ_BA]
        d[E_BG + j] = noise[NZ_BG]
    if n > N_LOOSE:
        d[E_CB] = noise[NZ_CB]
        d[E_CD] = noise[NZ_CD]
    Pd = Phi * d  # Phi @ diag(d)
    Qd[:, :] = (Pd @ Phi.T) * (0.5 * T)
    for j in range(n):
        Qd[j, j] += 0.5 * T * d[j]
    tg = acc[ACC_GAP]
    if tg > 0.0:
        sa, sw = noise[NZ_GAP_ACC], noise[NZ_GAP_GYR]
        for j in range(3):
            Qd[E_VEL + j, E_VEL + j] += (sa * tg) ** 2
            Qd[E_POS + j, E_POS + j] += (0.5 * sa * tg * tg) ** 2
            Qd[E_POS + j, E_VEL + j] += 0.5 * sa * sa * tg**3
            Qd[E_VEL + j, E_POS + j] += 0.5 * sa * sa * tg**3
            Qd[E_ATT + j, E_ATT + j] += (sw * tg) ** 2
