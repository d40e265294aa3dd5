"""Predict and update of the cascade's three estimators, compiled (numba, ``cache=True``).

Each function works on one six-state filter given by its model id (``model.MODEL_NAV`` or
``MODEL_CTL``) and calls only the model's pure functions, so the same code serves both
filters, and the filterpy backend (``reference``) reproduces it step for step.

- **EKF** (paper 000 eq. 21-23): ``x <- f(x, u)`` (Euler for the navigation filter, the
  exact ZOH transition for the linear control filter), ``P <- F P F^T + Q``; the update is
  the Kalman update with the constant ``H`` in Joseph form (``kernels.ekf.joseph_update``),
  the heading residual wrapped.
- **UKF** (eq. 24-27, filterpy's formulation): sigma points of ``(x, P)``
  (``kernels.unscented.draw_sigmas``, the same points as ``MerweScaledSigmaPoints``) through
  ``f``, mean and covariance by the unscented transform plus additive ``Q``; the update draws
  the sigma points of the prior again, predicts the rows through ``h`` and applies
  ``K = P_xz P_y^-1``, ``P <- P - K P_y K^T``.
- **Hybrid** (paper 000 section 9.3, after Andrade-Cetto et al.): the time update is the UKF's
  (sigma points, unscented covariance, unscented means) except that the mean of the states
  flagged in ``ekf_mean`` (default East and North) is the EKF's ``f(x_hat)`` (the propagated
  central sigma point); the update is the EKF's; the control filter is the EKF's.

**Why this hybrid.** The paper proposes UKF propagation with an EKF update, hoping to keep
the UKF's fast bias convergence and the EKF's precise East/North. In this cascade:

- both measurement models are linear (``Y1 = C1 X1``, ``Y2 = C2 X2``), so the EKF update is
  exact and equal to the UKF's (the sigma points add only cost): the update is the EKF's;
- the control model is linear, so its UKF *is* its EKF: the control filter is the EKF;
- in the navigation model the biases and the heading propagate linearly (the unscented
  propagation of these "bias-sensitive" states equals the EKF's), and the only curvature is
  ``(E, N)_dot = (V - r_b)(sin, cos) psi``. With paper 000's ``alpha = 1e-3`` the unscented
  transform is its second-order limit: it adds ``1/2 tr(f'' P)`` to the predicted East/North
  (``(V - r_b) cos(psi) P_psipsi / 2`` per unit time on North) and ``(beta - alpha^2)
  delta delta^T`` to their covariance. Table 1's heading-bias random walk and position
  process noise keep ``P_psipsi`` about 0.15 rad^2 with GPS (``psi`` and ``psi_b`` are
  separable only through the track), and its heading variance grows it by 0.5 rad^2/s
  without, so that term biases the UKF: with GPS it ends up in the radar-bias estimate
  (which settles at ``V_radar - V / (1 - P_psipsi / 2)``, 0.15 instead of 0.4 m/s), in an
  outage in the position. Everything else of the UKF is the EKF's: with the central point
  as its mean it reproduces the EKF (``tests/.../test_ukf_radar_bias.py``).

So the hybrid propagates the covariance and the bias-sensitive states by the unscented
transform and takes the position mean from the EKF (the state GPS measures directly, where
the unscented second-order term does harm), and updates like the EKF. What this buys is
measured in the experiment (``experiments``); it behaves like the EKF, because here the
unscented covariance equals the EKF's to second order, so no faster bias convergence exists
to inherit.

An update is ``prepare_update`` (rows, innovations, gating per block with
``kernels.common.gate_blocks``, the timeout reset of a stream rejected for too long, logs with
the shared recorders; also the filterpy backend's front end) then ``apply_update``.
"""

from __future__ import annotations

import math

import numpy as np

from navreplay.pipeline._jit import njit
from navreplay.pipeline.estimation.cascaded.model import (
    NX,
    NZ,
    is_angle_row,
    model_f,
    model_h,
    model_jacobian,
    model_meas_jacobian,
    wrap_pi,
)
from navreplay.pipeline.estimation.cascaded.numerics import (
    advance_stream_clocks,
    centered_mean_cov,
    reset_observed,
    stream_resets,
)
from navreplay.pipeline.estimation.kernels.common import (
    EV_RESET,
    accepted_rows,
    cho_solve,
    cholesky,
    gate_blocks,
    innovation_cov,
    propagate_cov,
    record_event,
    record_innovations,
)
from navreplay.pipeline.estimation.kernels.ekf import joseph_update
from navreplay.pipeline.estimation.kernels.records import GatedBlocks
from navreplay.pipeline.estimation.kernels.unscented import cross_cov, draw_sigmas
from navreplay.pipeline.nav.earth import F64, I64

EST_EKF, EST_UKF, EST_HYBRID = 0, 1, 2
NSIG = 2 * NX + 1


@njit(cache=True, error_model="numpy")
def ekf_predict(model: int, x: F64, P: F64, u: F64, dt: float, par: F64, disc: F64, Q: F64) -> None:
    """EKF time update (eq. 22-23): ``F`` at the prior, ``x <- f(x)``, ``P <- F P F^T + Q``."""
    F = np.empty((NX, NX))
    xn = np.empty(NX)
    model_jacobian(model, x, u, dt, par, disc, F)
    model_f(model, x, u, dt, par, disc, xn)
    for j in range(NX):
        x[j] = xn[j]
    propagate_cov(P, F, Q, NX, np.empty((NX, NX)))


@njit(cache=True, error_model="numpy")
def ukf_predict(
    model: int,
    x: F64,
    P: F64,
    u: F64,
    dt: float,
    par: F64,
    disc: F64,
    Q: F64,
    wm: F64,
    wc: F64,
    gamma: float,
    ekf_mean: I64,
) -> bool:
    """Unscented time update (eq. 24-26) with additive ``Q``; states with ``ekf_mean[j]``
    take the EKF mean ``f(x_hat)[j]`` instead of the unscented one (the hybrid).

    Returns:
        False (nothing changed) if ``P`` is not positive definite.
    """
    L = np.empty((NX, NX))
    sig = np.empty((NSIG, NX))
    if not draw_sigmas(x, P, NX, gamma, L, sig):
        return False
    Y = np.empty((NSIG, NX))
    for i in range(NSIG):
        model_f(model, sig[i], u, dt, par, disc, Y[i])
    mean = np.empty(NX)
    cov = np.empty((NX, NX))
    centered_mean_cov(Y, wm, wc, NX, mean, cov)
    for j in range(NX):
        x[j] = Y[0, j] if ekf_mean[j] else mean[j]
        for k in range(NX):
            P[j, k] = cov[j, k] + Q[j, k]
    return True


@njit(cache=True, error_model="numpy")
def measurement_layout(z: F64, block_of_row: I64, stream_of_block: I64, rows: I64, blocks: I64
                       ) -> tuple[int, int]:  # fmt: skip
    """The available rows of ``z`` (finite entries) and their gating blocks.

    Args:
        z: the three measurement values, NaN where unavailable.
        block_of_row: block id of each of the three rows (rows of one block are adjacent).
        stream_of_block: stream code of each block id.
        rows: out, indices of the available rows (m,).
        blocks: out (nb, 4): first row (into ``rows``), dimension, stream, -1.

    Returns:
        (m, nb).
    """
    m = 0
    nb_ = 0
    prev = -1
    for j in range(NZ):
        if not math.isfinite(z[j]):
            continue
        rows[m] = j
        b = block_of_row[j]
        if b == prev:
            blocks[nb_ - 1, 1] += 1
        else:
            blocks[nb_, 0], blocks[nb_, 1] = m, 1
            blocks[nb_, 2], blocks[nb_, 3] = stream_of_block[b], -1
            nb_ += 1
            prev = b
        m += 1
    return m, nb_


@njit(cache=True, error_model="numpy")
def _prior_rows(
    model: int, est: int, x: F64, P: F64, z: F64, rows: I64, m: int, Hm: F64, rm: F64, wm: F64,
    wc: F64, gamma: float, nu: F64, S: F64, Pxz: F64,
) -> bool:  # fmt: skip
    """Innovations ``nu``, their covariance ``S`` (and for the UKF the cross covariance
    ``Pxz``) of the available rows (``Hm``, variances ``rm``), from the prior; False if a
    UKF prior is not PD."""
    hx = np.empty(NZ)
    zp = np.empty(m)
    if est == EST_UKF:
        L = np.empty((NX, NX))
        sig = np.empty((NSIG, NX))
        if not draw_sigmas(x, P, NX, gamma, L, sig):
            return False
        Z = np.empty((NSIG, m))
        for i in range(NSIG):
            model_h(model, sig[i], hx)
            for k in range(m):
                Z[i, k] = hx[rows[k]]
        centered_mean_cov(Z, wm, wc, m, zp, S)
        cross_cov(sig, x, Z, zp, wc, NX, m, Pxz)
        for k in range(m):
            S[k, k] += rm[k]
    else:
        model_h(model, x, hx)
        for k in range(m):
            zp[k] = hx[rows[k]]
        innovation_cov(Hm, P, rm, m, NX, Pxz, S)
    for k in range(m):
        d = z[rows[k]] - zp[k]
        nu[k] = wrap_pi(d) if is_angle_row(model, rows[k]) else d
    return True


@njit(cache=True, error_model="numpy")
def prepare_update(
    model: int,
    est: int,
    t_ns: int,
    x: F64,
    P: F64,
    z: F64,
    r: F64,
    block_of_row: I64,
    stream_of_block: I64,
    gate: F64,
    timeout_s: float,
    reject_since: I64,
    wm: F64,
    wc: F64,
    gamma: float,
    inn_i: I64,
    inn_f: F64,
    ev_i: I64,
    ev_f: F64,
    counts: I64,
) -> tuple[int, I64, F64, F64, F64, F64, F64, I64, int]:
    """Measurement front end: available rows, innovations, gating, timeout resets, logs.

    Shared by both backends (the filterpy backend lets filterpy do the update itself with
    the accepted rows). A stream rejected for the timeout has the states it observes
    inflated in ``P`` (``numerics.reset_observed``) and is gated again.

    Args:
        model: ``MODEL_NAV`` or ``MODEL_CTL``; est: ``EST_UKF`` computes ``nu``, ``S`` and
            ``P_xz`` from sigma points, otherwise from ``h(x)`` and ``H``.
        x, P: prior (``P`` may be inflated by a reset).
        z: the three rows (NaN = not available); r: their variances (Table 2).
        block_of_row, stream_of_block: the gating blocks (``measurement_layout``).
        gate: chi-square thresholds by block dimension; timeout_s: gate timeout;
            reject_since: per-stream rejection clocks (ns, -1 = none).
        wm, wc, gamma: unscented weights and spread (UKF only).
        inn_i, inn_f, ev_i, ev_f, counts: innovation and event logs (``kernels.common``).

    Returns:
        ``(m, rows, Hm, rm, nu, S, Pxz, acc, ma)``: ``m`` available rows (indices into the
        three) with their ``H`` rows (m, 6), variances, innovations (heading wrapped), prior
        innovation covariance (m, m) and cross covariance (6, m, UKF only); ``acc[:ma]`` the
        accepted ones (indices into the m). ``m == -1``: a UKF prior was not positive
        definite (nothing was logged).
    """
    rows = np.empty(NZ, np.int64)
    blocks = np.empty((NZ, 4), np.int64)
    m, nb_ = measurement_layout(z, block_of_row, stream_of_block, rows, blocks)
    nu = np.empty(m)
    S = np.empty((m, m))
    Pxz = np.zeros((NX, m))
    H = np.empty((NZ, NX))
    model_meas_jacobian(model, H)
    Hm = np.empty((m, NX))
    rm = np.empty(m)
    acc = np.empty(m, np.int64)
    for k in range(m):
        for j in range(NX):
            Hm[k, j] = H[rows[k], j]
        rm[k] = r[rows[k]]
    if m == 0:
        return 0, rows, Hm, rm, nu, S, Pxz, acc, 0
    nis = np.empty(nb_)
    accepted = np.empty(nb_, np.int64)
    gwork = np.empty((3, 6))
    for attempt in range(2):
        if not _prior_rows(model, est, x, P, z, rows, m, Hm, rm, wm, wc, gamma, nu, S, Pxz):
            return -1, rows, Hm, rm, nu, S, Pxz, acc, 0
        gate_blocks(nu, S, blocks, nb_, gate, nis, accepted, gwork)
        if attempt == 1:
            break
        reset = stream_resets(t_ns, blocks, nb_, accepted, reject_since, timeout_s)
        if reset.sum() == 0:
            break
        for s in range(reset.shape[0]):
            if reset[s]:
                big = reset_observed(P, NX, Hm, blocks, nb_, s, nu)
                record_event(ev_i, ev_f, counts, t_ns, EV_RESET, s, -1, big)
    record_innovations(t_ns, GatedBlocks(nu, S, blocks, nb_, nis, accepted), gate, inn_i, inn_f,
                       counts, ev_i, ev_f)  # fmt: skip
    advance_stream_clocks(t_ns, blocks, nb_, accepted, reject_since)
    ma = accepted_rows(blocks, nb_, accepted, acc)
    return m, rows, Hm, rm, nu, S, Pxz, acc, ma


@njit(cache=True, error_model="numpy")
def apply_update(
    est: int, x: F64, P: F64, Hm: F64, rm: F64, nu: F64, S: F64, Pxz: F64, acc: I64, ma: int
) -> None:
    """The update of the accepted rows ``acc[:ma]`` from ``prepare_update``'s outputs:
    Kalman in Joseph form with ``H`` (eq. 21; EKF and hybrid) or unscented (eq. 27)."""
    if ma == 0:
        return
    if est != EST_UKF:
        dx, ok = joseph_update(P, NX, Hm, S, rm, nu, acc, ma)
        if ok:
            for j in range(NX):
                x[j] += dx[j]
        return
    _ukf_apply(x, P, Pxz, S, nu, acc, ma)


@njit(cache=True, error_model="numpy")
def _ukf_apply(x: F64, P: F64, Pxz: F64, S: F64, nu: F64, acc: I64, ma: int) -> None:
    """``K = P_xz P_y^-1``, ``x += K nu``, ``P -= K P_y K^T`` on the accepted rows (eq. 27)."""
    Sa = np.empty((ma, ma))
    Kt = np.empty((ma, NX))
    for i in range(ma):
        for j in range(NX):
            Kt[i, j] = Pxz[j, acc[i]]
        for j in range(ma):
            Sa[i, j] = S[acc[i], acc[j]]
    L = np.empty((ma, ma))
    if not cholesky(Sa, ma, L):
        return
    cho_solve(L, ma, Kt, NX)  # Kt = S^-1 Pxz^T = K^T
    for j in range(NX):
        for i in range(ma):
            x[j] += Kt[i, j] * nu[acc[i]]
    # P -= K S K^T = Pxz_a K^T (K S = Pxz_a)
    for r in range(NX):
        for c in range(NX):
            a = 0.0
            for i in range(ma):
                a += Pxz[r, acc[i]] * Kt[i, c]
            P[r, c] -= a
