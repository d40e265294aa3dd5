"""The fuzzy-adaptive weighted EKF of paper 004 (``fwekf``), compiled whole with numba.

The loosely coupled error-state EKF of ``kernels.ekf`` (same propagation, same measurement
front end ``ekf_prepare``, same Joseph update) with the exponential data weighting of paper
004 section 3.2, quoted from the paper (``../shared/papers/004_d39d0dffc633ab38.txt``)::

    R_k = R alpha^(-2(k+1))                                                   (21)
    Q_k = Q alpha^(-2(k+1))                                                   (22)
    P_k^(alpha-) = P_k^- alpha^(2k)                                           (23)
    K_k = P_k^(alpha-) H_k^T (H_k P_k^(alpha-) H_k^T + R / alpha^2)^-1         (24)
    x_k = x_k^- + K_k (z_k - z^_k)                                            (25)
    P_(k+1)^(alpha-) = alpha^2 Phi_k P_k^(alpha-) Phi_k^T + Q                 (26)
    P_k^alpha = (I - K_k H_k) P_k^(alpha-)                                    (27)

Eq. 21-23 make the weighted filter a plain Kalman filter whose noise covariances grow as
``alpha^-2(k+1)`` (old data weigh ``alpha^-2`` per cycle relative to newer data); in the
scaled covariance ``P^alpha`` that filter has the faded prior of eq. 26 *and* the measurement
covariance ``R / alpha^2`` in its gain (eq. 24). Both are applied here, once per measurement
cycle (a stop that carries a GNSS fix; ``alpha = 1`` is the plain EKF, and the stops without
a fix use ``alpha = 1``):

- ``fade_prior``: ``P- = alpha^2 Phi P Phi^T + Qd`` (eq. 26);
- ``weighted_update``: the gain with ``R / alpha^2`` (eq. 24) and the covariance update in
  Joseph form with the same ``R / alpha^2``, ``P = (I - K H) P- (I - K H)^T + K (R / alpha^2)
  K^T``, which equals eq. 27 for that gain and stays symmetric positive definite.

A constant alpha thus inflates the prior relative to R by ``alpha^4`` per cycle, not
``alpha^2`` (``tests/.../test_fwekf.py`` proves the equivalence with eq. 21-23 by hand).

Gating and the fuzzy inputs use the unweighted innovation covariance ``S = H P- H^T + R``
(eq. 28: the residual covariance the fuzzy system compares against has ``R`` unscaled), so
the chi-square gate keeps its meaning and the residual statistics judge the receiver's
declared accuracy, not the weighting. Our reading: after each fix's update, the normalized
innovations ``nu / sqrt(S_ii)`` of its position and velocity rows, accepted by the gate or
not (the paper's fuzzy system is what judges the residuals; a gate that hid the rejected
ones would blind it to exactly the faults it is meant to detect), enter a ring of the last
``window`` epochs; the fuzzy system (``estimation.fuzzy``: eq. 29-32, Table 1) turns the
ring's mean and covariance into the alpha of the next cycle.

The same kernel runs ``iae_ekf`` (``fz[FZ_MODE] == MODE_IAE``, ``ins.iae``): no fading
(alpha = 1 throughout), and the fix rows' variances multiplied by the innovation-based
estimate of R (``Epoch.r_scale``, in the gate as in the update), re-estimated after each fix;
the multiplier of the horizontal position variance is recorded where fwekf records alpha.
"""

from __future__ import annotations

import math

import numpy as np

from navreplay.pipeline._jit import njit
from navreplay.pipeline.estimation.core.gating import (
    STATUS_INDEFINITE,
    STATUS_OK,
    fail,
    keep_pd,
    record_output,
)
from navreplay.pipeline.estimation.core.linalg import joseph_update
from navreplay.pipeline.estimation.core.runlog import CNT_OUT, CNT_STOP, RunLog
from navreplay.pipeline.estimation.ins.fuzzy import (
    FZ_MODE,
    FZ_WINDOW,
    MODE_IAE,
    infer_alpha,
    residual_inputs,
)
from navreplay.pipeline.estimation.ins.iae import N_KINDS, iae_scales, push_innovations
from navreplay.pipeline.estimation.ins.kernels.common import (
    check_state,
    epoch_buffers,
    fill_still,
    rest_plausible,
)
from navreplay.pipeline.estimation.ins.kernels.ekf import ekf_prepare
from navreplay.pipeline.estimation.ins.kernels.records import (
    Epoch,
    EpochBuffers,
    Fading,
    Schedule,
    Settings,
    SmoothLog,
)
from navreplay.pipeline.estimation.ins.kernels.smoother import (
    SM_PRIOR,
    copy_vec,
    pool_put,
    record_post,
    record_prior,
    record_start,
    sm_on,
)
from navreplay.pipeline.estimation.ins.models.ins import (
    X_VEL,
    ImuSpan,
    Stepping,
    inject,
    propagate_span,
    span_work,
)
from navreplay.pipeline.estimation.ins.models.ins_errors import second_order_noise, transition
from navreplay.pipeline.estimation.ins.models.measurement import (
    K_POS,
    K_PR,
    ST_FIX,
    ST_OUT,
    ST_STILL,
    ST_T,
    STILL_COLS,
    epoch_layout,
)
from navreplay.pipeline.nav.earth import F64, I64

RING_COLS = 6  # north, east, down position; north, east, down velocity


@njit(cache=True)
def fade_prior(P: F64, Phi: F64, Qd: F64, alpha: float) -> None:
    """Paper 004 eq. 26 in place: ``P <- alpha^2 Phi P Phi^T + Qd``."""
    P[:, :] = (alpha * alpha) * (Phi @ P @ Phi.T) + Qd


@njit(cache=True, error_model="numpy")
def weighted_update(P: F64, n: int, buf: EpochBuffers, ma: int, alpha: float) -> tuple[F64, bool]:
    """The weighted-EKF update (paper 004 eq. 24, 25, 27) of the accepted rows.

    Args:
        P: (n, n) weighted prior ``P^(alpha-)``, updated in place.
        buf: the epoch as ``ekf_prepare`` left it: ``H`` (m_max, n) Jacobian, ``nu``
            (m_max,) innovations, ``S`` (m_max, m_max) unweighted innovation covariance
            ``H P H^T + diag(r)``, ``r`` (m_max,) measurement variances ``R`` as declared,
            ``acc_rows``: the accepted rows.
        ma: the number of accepted rows.
        alpha: the fading factor of this cycle (> 0).

    Returns:
        (dx, ok) as ``kernels.ekf.joseph_update``, whose Joseph form is used with ``R / alpha^2``
        both in the gain ``K = P H^T (H P H^T + R / alpha^2)^-1`` and in ``K R K^T / alpha^2``.
    """
    r, acc_rows = buf.r, buf.acc_rows
    inv2 = 1.0 / (alpha * alpha)
    m = r.shape[0]
    r_w = np.empty(m)
    S_w = buf.S.copy()
    for k in range(m):
        r_w[k] = r[k] * inv2
    for i in range(ma):
        k = acc_rows[i]
        S_w[k, k] += r_w[k] - r[k]
    return joseph_update(P, n, buf.H, S_w, r_w, buf.nu, acc_rows, ma)


@njit(cache=True)
def push_residuals(ring: F64, count: int, rows: I64, nu: F64, S: F64, m: int) -> int:
    """Append one epoch's normalized GNSS residuals (all rows, gated or not) to the ring;
    returns the new count."""
    slot = count % ring.shape[0]
    ring[slot, :] = math.nan
    for k in range(m):
        kind = rows[k, 0]
        if kind < K_PR:
            ring[slot, kind] = nu[k] / math.sqrt(S[k, k])
    return count + 1


@njit(cache=True)
def run_fwekf(
    x0: F64,
    P0: F64,
    sched: Schedule,
    fix: F64 | None,
    obs: F64 | None,
    cfg: Settings,
    fading: Fading,
    log: RunLog,
    sm: SmoothLog,
) -> int:
    """Replay the FWEKF: ``kernels.ekf.run_ekf``'s arguments plus the fuzzy system
    (``records.Fading``: its parameters, rules, and the alpha in force at each output row),
    or with ``fading.fz`` of ``iae.IaeParams`` the IAE (module docstring). For smoothing
    (``sm``) the prior of every update epoch is kept: the fading changes it.

    Returns:
        a ``common.STATUS_*`` code.
    """
    n = cfg.n
    fz, rules, out_alpha = fading.fz, fading.rules, fading.out_alpha
    ev_i, ev_f, counts = log.ev_i, log.ev_f, log.counts
    X = x0.copy()
    P = P0.copy()
    ones = np.ones(n)
    L = np.empty((n, n))
    Phi = np.empty((n, n))
    Qd = np.empty((n, n))
    step = Stepping(cfg.substeps, cfg.max_step_s, cfg.gap_s)
    sw = span_work()
    u = sched.u0.copy()
    buf = epoch_buffers(sched.m_max, n, sched.t0)
    still = np.zeros(STILL_COLS)
    iae = fz[FZ_MODE] == MODE_IAE
    ring = np.full((int(fz[FZ_WINDOW]), 3 * N_KINDS if iae else RING_COLS), math.nan)
    n_ring = 0
    alpha = 1.0
    r_scale = np.ones(K_PR)
    out_alpha[0] = alpha
    smoothing = sm_on(sm)
    if smoothing:
        record_start(sm, X, sw.acc, P, ones, counts[CNT_OUT])
    record_output(sched.t0, X, P, log)
    t_cur = sched.t0
    i = sched.i0
    stops = sched.stops
    for k in range(stops.shape[0]):
        stop = stops[k]
        t = stop[ST_T]
        i_prev = i
        i = propagate_span(X, ImuSpan(sched.imu_t, sched.imu, i, t_cur, u, t), step, sw, True)
        u[:] = sw.u_end
        if stop[ST_STILL] > 0:
            fill_still(still, sched.imu, i_prev, i, u[3:6], (t - t_cur) * 1e-9, cfg)
        t_cur = t
        second_order_noise(P, sw.acc, cfg.noise)
        if smoothing:
            record_prior(sm, k + 1, X, sw.acc)
        transition(X, sw.acc, cfg.noise, n, Phi, Qd)
        a_k = alpha if stop[ST_FIX] >= 0 and not iae else 1.0  # once per GNSS cycle
        fade_prior(P, Phi, Qd, a_k)
        at_rest = rest_plausible(stop, X[X_VEL : X_VEL + 3], P, cfg)
        m, nb_ = epoch_layout(
            stop, fix, obs, sched.obs_start, cfg.nhc_on, at_rest, buf.rows, buf.blocks
        )
        if m > 0:
            ep = Epoch(t, m, nb_, u[3:6], still, r_scale)
            ma = ekf_prepare(ep, X, P, fix, obs, cfg, buf, log)
            if smoothing:
                sm.rows[k + 1, SM_PRIOR] = pool_put(sm, P, ones)
            if ma > 0:
                dx, ok = weighted_update(P, n, buf, ma, a_k)
                if ok:
                    inject(X, dx, n)
                    if smoothing:
                        copy_vec(sm.dx[k + 1], dx, n)
            if stop[ST_FIX] >= 0 and iae:
                n_ring = push_innovations(ring, n_ring, buf.rows, buf.nu, buf.S, buf.r, r_scale, m)
                iae_scales(ring, n_ring, fz, r_scale)
                alpha = r_scale[K_POS]
            elif stop[ST_FIX] >= 0:
                n_ring = push_residuals(ring, n_ring, buf.rows, buf.nu, buf.S, m)
                mean_in, cov_in = residual_inputs(ring, n_ring)
                alpha = infer_alpha(mean_in, cov_in, fz, rules)
        ok = keep_pd(P, n, L, t, ev_i, ev_f, counts)
        status = check_state(X, P, ones, cfg) if ok else STATUS_INDEFINITE
        if status != STATUS_OK:
            return fail(t, status, ev_i, ev_f, counts)
        if smoothing:
            record_post(sm, k + 1, P, ones, counts[CNT_OUT] if stop[ST_OUT] > 0 else -1)
        if stop[ST_OUT] > 0:
            j = counts[CNT_OUT]
            if j < out_alpha.shape[0]:
                out_alpha[j] = alpha
            record_output(t, X, P, log)
        counts[CNT_STOP] = k + 1
    return STATUS_OK
