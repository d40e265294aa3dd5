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
``core.gating.gate_blocks``, the timeout reset of a stream rejected for too long, logs with
the shared recorders; also the filterpy backend's front end) then ``apply_update``.

The functions take records (``typing.NamedTuple``, compiled by numba as tuples with named
fields): the ``Filter`` at work, a time ``Step``, the ``Unscented`` set-up, an update's
``Measurement`` and ``Gating``, the ``UpdateRows`` it found, and the run's ``RunLog``.
"""

from __future__ import annotations

import math
from typing import NamedTuple

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
from navreplay.pipeline.estimation.core.gating import (
    EV_RESET,
    accepted_rows,
    gate_blocks,
    record_event,
    record_innovations,
)
from navreplay.pipeline.estimation.core.linalg import (
    cho_solve,
    cholesky,
    innovation_cov,
    joseph_update,
    propagate_cov,
)
from navreplay.pipeline.estimation.core.runlog import GatedBlocks, RunLog
from navreplay.pipeline.estimation.core.unscented import cross_cov, draw_sigmas
from navreplay.pipeline.nav.earth import F64, I64

EST_EKF, EST_UKF, EST_HYBRID = 0, 1, 2
NSIG = 2 * NX + 1


class Filter(NamedTuple):
    """One of the cascade's two filters at work.

    Attributes:
        model: ``MODEL_NAV`` or ``MODEL_CTL``.
        est: its estimator, ``EST_*``: the time update is the EKF's for ``EST_EKF``, the
            unscented one otherwise; the measurement update the unscented one for
            ``EST_UKF``, the EKF's otherwise (the hybrid's).
        x, P: its state (NX,) and covariance (NX, NX), updated in place.
    """

    model: int
    est: int
    x: F64
    P: F64


class Step(NamedTuple):
    """One time update: the input ``u`` held over ``dt`` seconds, the model parameters
    ``par``, the control discretization ``disc`` of this step (``model.ctl_discretize``) and
    the process noise ``Q`` (NX, NX)."""

    u: F64
    dt: float
    par: F64
    disc: F64
    Q: F64


class Unscented(NamedTuple):
    """The sigma points: mean and covariance weights ``wm``, ``wc`` (2 NX + 1,) and the
    spread ``gamma`` (``kernels.unscented.ukf_weights``; unused by the EKF)."""

    wm: F64
    wc: F64
    gamma: float


class Measurement(NamedTuple):
    """One update's measurement: the three rows ``z`` (NaN = not available), their
    variances ``r`` (Table 2), the gating block of each row ``block_of_row`` (rows of one
    block adjacent) and the stream code of each block ``stream_of_block``."""

    z: F64
    r: F64
    block_of_row: I64
    stream_of_block: I64


class Gating(NamedTuple):
    """The chi-square ``gate`` by block dimension, the gate ``timeout_s`` and the
    per-stream rejection clocks ``reject_since`` (ns, -1 = none; updated)."""

    gate: F64
    timeout_s: float
    reject_since: I64


class UpdateRows(NamedTuple):
    """The available rows of an update and their prior innovations (``prepare_update``).

    Attributes:
        rows: ``rows[:m]``, the available rows (indices into the three).
        m: how many.
        H: their ``H`` rows (m, NX); r: their variances (m,).
        nu: innovations (m,), heading wrapped; S: prior innovation covariance (m, m).
        Pxz: cross covariance (NX, m), UKF only.
    """

    rows: I64
    m: int
    H: F64
    r: F64
    nu: F64
    S: F64
    Pxz: F64


@njit(cache=True, error_model="numpy", inline="always")
def sigma_points(f: Filter, ut: Unscented) -> tuple[bool, F64]:
    """The sigma points (NSIG, NX) of ``(f.x, f.P)`` (``kernels.unscented.draw_sigmas``);
    False if ``P`` is not positive definite."""
    L = np.empty((NX, NX))
    sig = np.empty((NSIG, NX))
    return draw_sigmas(f.x, f.P, NX, ut.gamma, L, sig), sig


@njit(cache=True, error_model="numpy", inline="always")
def ekf_predict(f: Filter, step: Step) -> None:
    """EKF time update (eq. 22-23): ``F`` at the prior, ``x <- f(x)``, ``P <- F P F^T + Q``."""
    model, _, x, P = f
    u, dt, par, disc, Q = step
    F = np.empty((NX, NX))
    xn = np.empty(NX)
    model_jacobian(model, x, u, dt, par, disc, F)
    model_f(model, x, u, dt, par, disc, xn)
    for j in range(NX):
        x[j] = xn[j]
    propagate_cov(P, F, Q, NX, np.empty((NX, NX)))


@njit(cache=True, error_model="numpy", inline="always")
def ukf_predict(f: Filter, step: Step, ut: Unscented, ekf_mean: I64) -> bool:
    """Unscented time update (eq. 24-26) with additive ``Q``; states with ``ekf_mean[j]``
    take the EKF mean ``f(x_hat)[j]`` instead of the unscented one (the hybrid).

    Returns:
        False (nothing changed) if ``P`` is not positive definite.
    """
    model, _, x, P = f
    u, dt, par, disc, Q = step
    ok, sig = sigma_points(f, ut)
    if not ok:
        return False
    Y = np.empty((NSIG, NX))
    for i in range(NSIG):
        model_f(model, sig[i], u, dt, par, disc, Y[i])
    mean = np.empty(NX)
    cov = np.empty((NX, NX))
    centered_mean_cov(Y, ut.wm, ut.wc, NX, mean, cov)
    for j in range(NX):
        x[j] = Y[0, j] if ekf_mean[j] else mean[j]
        for k in range(NX):
            P[j, k] = cov[j, k] + Q[j, k]
    return True


@njit(cache=True, error_model="numpy", inline="always")
def predict(f: Filter, step: Step, ut: Unscented, ekf_mean: I64) -> bool:
    """The time update of ``f``'s estimator (``ekf_predict`` or ``ukf_predict``); False if
    an unscented prior was not positive definite."""
    if f.est == EST_EKF:
        ekf_predict(f, step)
        return True
    return ukf_predict(f, step, ut, ekf_mean)


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


@njit(cache=True, error_model="numpy", inline="always")
def _prior_rows(f: Filter, z: F64, ut: Unscented, ur: UpdateRows) -> bool:
    """Innovations ``ur.nu``, their covariance ``ur.S`` (and for the UKF the cross covariance
    ``ur.Pxz``) of the available rows, from the prior; False if a UKF prior is not PD."""
    model, est, x, P = f
    rows, m, Hm, rm, nu, S, Pxz = ur
    hx = np.empty(NZ)
    zp = np.empty(m)
    if est == EST_UKF:
        ok, sig = sigma_points(f, ut)
        if not ok:
            return False
        Z = np.empty((NSIG, m))
        for i in range(NSIG):
            model_h(model, sig[i], hx)
            for k in range(m):
                Z[i, k] = hx[rows[k]]
        centered_mean_cov(Z, ut.wm, ut.wc, m, zp, S)
        cross_cov(sig, x, Z, zp, ut.wc, NX, m, Pxz)
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


@njit(cache=True, error_model="numpy", inline="always")
def prepare_update(
    t_ns: int, f: Filter, meas: Measurement, gating: Gating, ut: Unscented, log: RunLog
) -> tuple[UpdateRows, I64, int]:
    """Measurement front end: available rows, innovations, gating, timeout resets, logs.

    Shared by both backends (the filterpy backend lets filterpy do the update itself with
    the accepted rows). A stream rejected for the timeout has the states it observes
    inflated in ``f.P`` (``numerics.reset_observed``) and is gated again.

    Args:
        t_ns: the update's time.
        f: the filter at its prior (``P`` may be inflated by a reset); ``f.est == EST_UKF``
            computes ``nu``, ``S`` and ``P_xz`` from sigma points, otherwise from ``h(x)``
            and ``H``.
        meas: the rows and their gating blocks (``measurement_layout``).
        gating: gates, timeout and the stream clocks; ut: sigma points (UKF only).
        log: where innovations and events are recorded (``core.gating``).

    Returns:
        ``(rows, acc, ma)``: the available rows with their prior innovations
        (``UpdateRows``), and ``acc[:ma]`` the accepted ones (indices into ``rows.rows``).
        ``ma == -1``: a UKF prior was not positive definite (nothing was logged).
    """
    inn_i, inn_f, ev_i, ev_f, counts = log.inn_i, log.inn_f, log.ev_i, log.ev_f, log.counts
    gate, timeout_s, reject_since = gating
    rows = np.empty(NZ, np.int64)
    blocks = np.empty((NZ, 4), np.int64)
    m, nb_ = measurement_layout(meas.z, meas.block_of_row, meas.stream_of_block, rows, blocks)
    H = np.empty((NZ, NX))
    model_meas_jacobian(f.model, H)
    ur = UpdateRows(rows, m, np.empty((m, NX)), np.empty(m), np.empty(m), np.empty((m, m)),
                    np.zeros((NX, m)))  # fmt: skip
    acc = np.empty(m, np.int64)
    for k in range(m):
        for j in range(NX):
            ur.H[k, j] = H[rows[k], j]
        ur.r[k] = meas.r[rows[k]]
    if m == 0:
        return ur, acc, 0
    nis = np.empty(nb_)
    accepted = np.empty(nb_, np.int64)
    gwork = np.empty((3, 6))
    for attempt in range(2):
        if not _prior_rows(f, meas.z, ut, ur):
            return ur, acc, -1
        gate_blocks(ur.nu, ur.S, blocks, nb_, gate, nis, accepted, gwork)
        if attempt == 1:
            break
        reset = stream_resets(t_ns, blocks, nb_, accepted, reject_since, timeout_s)
        if reset.sum() == 0:
            break
        for s in range(reset.shape[0]):
            if reset[s]:
                big = reset_observed(f.P, NX, ur.H, blocks, nb_, s, ur.nu)
                record_event(ev_i, ev_f, counts, t_ns, EV_RESET, s, -1, big)
    record_innovations(t_ns, GatedBlocks(ur.nu, ur.S, blocks, nb_, nis, accepted), gate, inn_i,
                       inn_f, counts, ev_i, ev_f)  # fmt: skip
    advance_stream_clocks(t_ns, blocks, nb_, accepted, reject_since)
    ma = accepted_rows(blocks, nb_, accepted, acc)
    return ur, acc, ma


@njit(cache=True, error_model="numpy", inline="always")
def apply_update(f: Filter, ur: UpdateRows, acc: I64, ma: int) -> None:
    """The update of the accepted rows ``acc[:ma]`` from ``prepare_update``'s outputs:
    Kalman in Joseph form with ``H`` (eq. 21; EKF and hybrid) or unscented (eq. 27)."""
    if ma <= 0:
        return
    x, P = f.x, f.P
    if f.est != EST_UKF:
        dx, ok = joseph_update(P, NX, ur.H, ur.S, ur.r, ur.nu, acc, ma)
        if ok:
            for j in range(NX):
                x[j] += dx[j]
        return
    _ukf_apply(x, P, ur.Pxz, ur.S, ur.nu, acc, ma)


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
