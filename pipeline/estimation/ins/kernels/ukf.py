"""The total-state UKF replay loop (paper 001), compiled whole with numba (``cache=True``).

State: the UKF coordinates ``s`` of ``models.ins`` (lat, lon, h, v_NED, attitude rotation
vector relative to ``q_ref``, biases, clock) with covariance ``P``; sigma points are never
quaternions, so their weighted means and differences are plain vector arithmetic.

Per stop (every ``step_s`` and every update epoch):

1. draw the 2n+1 scaled sigma points (Van der Merwe; ``alpha``, ``beta``, ``kappa``) from
   ``(s, P)`` and materialize each as a full state (``q = Exp(a) q_ref``);
2. integrate every sigma point through the IMU samples of the span with RK4 (its own biases
   correct the input), all of them together (``ins.propagate_sigmas``: each RK4 stage
   vectorized over the sigma points, bitwise what one-at-a-time integration gives);
3. re-reference the attitude to the propagated central sigma point (``q_ref``), convert back
   to coordinates, and take the unscented mean and covariance, adding the process noise
   accumulated over the span, ``Qd`` of ``ins.transition`` along the central trajectory
   mapped into UKF coordinates;
4. if the stop has measurements: redraw the sigma points from the predicted ``(s, P)``,
   predict every row through ``models.measurement.epoch_h`` (relative to the prediction of
   the mean, which keeps ~2e7 m pseudoranges well conditioned), gate each block on its NIS
   against the unscented ``S``, reset timed-out streams, and update the accepted rows jointly
   (``K = Pxz S^-1``, ``P <- P - K S K^T``, symmetrized).

Between stops the sigma points are not redrawn: the process noise enters once per span
(``step_s``, default 0.1 s) instead of at every IMU sample. This is what filterpy's
``UnscentedKalmanFilter`` does when its ``fx`` integrates a whole span, which the reference
backend uses; the accuracy cost is measured in ``benchmarks/bench_estimation.py``.

**Compile time.** numba finalizes every jitted function as its own module holding a copy of
everything it calls, so each level of calls re-optimizes and re-emits the levels below it. The
stages of the loop (here and in ``ekf``: predict, update, gain; in ``unscented``
and ``models.measurement``: the sigma-point and epoch helpers) are therefore
``inline="always"``: inlined into the loop while numba builds it, they add no level. A cold
first run compiles about 3 s sooner for it (``benchmarks/bench_estimation.py``); the code is
the same. Inlining the small common helpers as well measured slower, and is not done.
``ukf_update`` is compiled on its own (not inlined).
"""

from __future__ import annotations

import numpy as np

from navreplay.pipeline._jit import njit
from navreplay.pipeline.estimation.core.gating import (
    STATUS_INDEFINITE,
    STATUS_OK,
    fail,
    gate_blocks,
    gating_cov,
    keep_pd,
    record_output,
)
from navreplay.pipeline.estimation.core.linalg import cho_solve, cholesky
from navreplay.pipeline.estimation.core.runlog import CNT_OUT, CNT_STOP, GatedBlocks, RunLog
from navreplay.pipeline.estimation.core.unscented import cross_cov, draw_sigmas, unscented_mean_cov
from navreplay.pipeline.estimation.ins.kernels.common import (
    check_state,
    close_gating,
    epoch_buffers,
    fill_still,
    reset_timed_out,
    rest_plausible,
)
from navreplay.pipeline.estimation.ins.kernels.records import (
    Epoch,
    EpochBuffers,
    RowPrediction,
    Schedule,
    Settings,
    SigmaWork,
    SmoothLog,
    UkfState,
)
from navreplay.pipeline.estimation.ins.kernels.smoother import (
    SM_AS_POSTERIOR,
    SM_CROSS,
    SM_PRIOR,
    copy_mat,
    copy_vec,
    pool_put,
    pool_put_cross,
    record_post,
    record_prior,
    record_start,
    sm_on,
)
from navreplay.pipeline.estimation.ins.kernels.unscented import sigma_h
from navreplay.pipeline.estimation.ins.models.ins import (
    E_CB,
    E_VEL,
    FULL_DIM,
    X_CB,
    X_CD,
    X_Q,
    ImuSpan,
    Stepping,
    coords_scale,
    from_full,
    propagate_sigmas,
    span_work,
    to_full,
)
from navreplay.pipeline.estimation.ins.models.ins_errors import second_order_noise, transition
from navreplay.pipeline.estimation.ins.models.measurement import (
    K_PR,
    ST_OUT,
    ST_STILL,
    ST_T,
    STILL_COLS,
    epoch_h,
    epoch_layout,
    epoch_z,
    gate_shift,
    scale_fix_rows,
)
from navreplay.pipeline.nav.earth import F64, I64
from navreplay.pipeline.nav.mechanization import LANES, LN_DIM


@njit(cache=True, error_model="numpy")
def _clock_only(L: F64, c: int) -> bool:
    """Column ``c`` of the Cholesky factor moves no navigation or bias state."""
    for r in range(E_CB):  # noqa: SIM110 (numba: no all() over a generator)
        if L[r, c] != 0.0:
            return False
    return True


@njit(cache=True, error_model="numpy", inline="always")
def ukf_predict(st: UkfState, span: ImuSpan, cfg: Settings, ws: SigmaWork) -> int:
    """Steps 1-3 of the module docstring over one ``span``; ``st`` updated in place (``ws``:
    the workspace; its ``lanes``, ``Y`` and ``prop`` those of ``ins.propagate_sigmas``, which
    integrates the span's sigma points together). Returns the next IMU index, or -1 if ``P``
    is not positive definite."""
    n, wm, wc, gamma, noise = cfg.n, cfg.wm, cfg.wc, cfg.ukf_gamma, cfg.noise
    s, P, q_ref = st
    sig, sigX, L, acc = ws.sig, ws.sigX, ws.L, ws.prop.acc
    Phi, Qd, sc, lanes, Y = ws.Phi, ws.Qd, ws.sc, ws.lanes, ws.Y
    if not draw_sigmas(s, P, n, gamma, L, sig):
        return -1
    ns = 2 * n + 1
    T = (span.t_end - span.t_start) * 1e-9
    m = np.int64(0)  # not the literal 0: one compile of propagate_sigmas, not two
    for j in range(ns):
        to_full(sig[j], q_ref, n, sigX[j])
        c = (j - 1) % n  # the Cholesky column that made sigma point j
        if j == 0 or c < E_CB or not _clock_only(L, c):
            lanes[m] = j
            m += 1
    step = Stepping(cfg.substeps, cfg.max_step_s, cfg.gap_s)
    i_next = propagate_sigmas(sigX, lanes, int(m), span, step, ws.prop, Y)
    q = 0
    for j in range(ns):  # the points left out of lanes (ascending): clock-only columns
        if q < m and lanes[q] == j:
            q += 1
            continue
        # lower-triangular factor: this point equals the mean except for the clock, so its
        # navigation solution is the central point's (bitwise); integrate its clock
        for r in range(X_CB):
            sigX[j, r] = sigX[0, r]
        sigX[j, X_CB] += sigX[j, X_CD] * T
    second_order_noise(P, acc, noise)  # the attitude and bias blocks are not scaled
    transition(sigX[0], acc, noise, n, Phi, Qd)
    coords_scale(sigX[0], n, sc)
    for j in range(4):
        q_ref[j] = sigX[0, X_Q + j]
    for j in range(ns):
        from_full(sigX[j], q_ref, n, sig[j])
    unscented_mean_cov(sig, wm, wc, n, s, P)
    for r in range(n):
        for c in range(n):
            P[r, c] += sc[r] * sc[c] * Qd[r, c]
    return i_next


@njit(cache=True, error_model="numpy")
def ukf_update(
    ep: Epoch,
    st: UkfState,
    fix: F64 | None,
    obs: F64 | None,
    cfg: Settings,
    buf: EpochBuffers,
    ws: SigmaWork,
    log: RunLog,
    prior: F64,
) -> bool:
    """Step 4 of the module docstring at epoch ``ep``, ``st`` updated in place; False if
    ``P`` was not positive definite. ``prior`` (n, n), if it has rows: the covariance the
    update starts from, after any stream reset (what a smoother takes as the prior)."""
    n, wm, wc, gamma, gate = cfg.n, cfg.wm, cfg.wc, cfg.ukf_gamma, cfg.gate
    t_ns, m, nb_, w_ib_b, still, r_scale = ep
    s, P, q_ref = st
    lever_b, rows, blocks, sig, L = cfg.lever_b, buf.rows, buf.blocks, ws.sig, ws.L
    ns = 2 * n + 1
    Xm = np.empty(FULL_DIM)
    to_full(s, q_ref, n, Xm)
    ref = Xm[:3].copy()
    sc = np.empty(n)
    coords_scale(Xm, n, sc)
    z = np.empty(m)
    r = np.empty(m)
    epoch_z(rows, m, fix, obs, ref, cfg.nhc_sigma, still, z, r)
    scale_fix_rows(rows, m, r_scale, r)
    dr = np.empty(m)
    gate_shift(rows, m, fix, r, dr)
    # predictions relative to the mean's: pseudoranges are ~2e7 m and their unscented average
    # would otherwise lose ~1e-9 m to cancellation
    h_ref = np.empty(m)
    epoch_h(Xm, rows, m, obs, ref, w_ib_b, lever_b, h_ref)
    for k in range(m):
        z[k] -= h_ref[k]
    Z = np.empty((ns, m))
    zp = np.empty(m)
    S = np.empty((m, m))
    Pxz = np.empty((n, m))
    nu = np.empty(m)
    nis = np.empty(nb_)
    accepted = np.empty(nb_, np.int64)
    gwork = np.empty((3, 6))
    pred = RowPrediction(rows, m, ref, w_ib_b, lever_b)
    for attempt in range(2):
        if not draw_sigmas(s, P, n, gamma, L, sig):
            return False
        sigma_h(sig, q_ref, pred, obs, h_ref, Xm, Z)
        unscented_mean_cov(Z, wm, wc, m, zp, S)
        for k in range(m):
            S[k, k] += r[k]
            nu[k] = z[k] - zp[k]
        g = GatedBlocks(nu, gating_cov(S, dr, m), blocks, nb_, nis, accepted)
        gate_blocks(nu, g.S, blocks, nb_, gate, nis, accepted, gwork)
        if attempt == 1 or not reset_timed_out(t_ns, P, g, buf, sc, cfg, log):
            break
    cross_cov(sig, s, Z, zp, wc, n, m, Pxz)
    if prior.shape[0] > 0:
        copy_mat(prior, P)
    ma = close_gating(t_ns, g, cfg, buf, log)
    if ma > 0:
        _apply_gain(s, P, n, Pxz, S, nu, buf.acc_rows, ma)
    return True


@njit(cache=True, error_model="numpy", inline="always")
def _apply_gain(s: F64, P: F64, n: int, Pxz: F64, S: F64, nu: F64, a: I64, ma: int) -> None:
    """``s += K nu``, ``P -= K S K^T`` with ``K = Pxz S^-1`` over the accepted rows ``a``."""
    Sa = np.empty((ma, ma))
    Kt = np.empty((ma, n))  # Pxz^T of the accepted rows, then Sa^-1 Pxz^T = K^T
    for i in range(ma):
        for j in range(n):
            Kt[i, j] = Pxz[j, a[i]]
        for j in range(ma):
            Sa[i, j] = S[a[i], a[j]]
    La = np.empty((ma, ma))
    if not cholesky(Sa, ma, La):
        return
    cho_solve(La, ma, Kt, n)
    for j in range(n):
        d = 0.0
        for i in range(ma):
            d += Kt[i, j] * nu[a[i]]
        s[j] += d
    for r in range(n):  # P -= K S K^T = Pxz Sa^-1 Pxz^T
        for c in range(r, n):
            d = 0.0
            for i in range(ma):
                d += Pxz[r, a[i]] * Kt[i, c]
            P[r, c] -= d
            if c != r:
                P[c, r] = P[r, c]


@njit(cache=True, error_model="numpy", inline="always")
def _error_cov(P: F64, sc: F64, n: int, out: F64) -> None:
    for r in range(n):
        for c in range(n):
            out[r, c] = P[r, c] / (sc[r] * sc[c])


@njit(cache=True, error_model="numpy")
def _sigma_cross(ws: SigmaWork, s: F64, cfg: Settings, D: F64) -> None:
    """The cross covariance of the sigma points a ``ukf_predict`` drew (``s +/- gamma L``,
    ``ws.L`` still their factor) and where they went (``ws.sig``, about the prior mean
    ``s``): what the unscented RTS smoother's gain is made of."""
    n, wc, gamma, L, sig = cfg.n, cfg.wc, cfg.ukf_gamma, ws.L, ws.sig
    for r in range(n):
        for c in range(n):
            a = 0.0
            for j in range(n):
                plus = wc[1 + j] * (sig[1 + j, c] - s[c])
                minus = wc[1 + n + j] * (sig[1 + n + j, c] - s[c])
                a += gamma * L[r, j] * (plus - minus)
            D[r, c] = a


@njit(cache=True, error_model="numpy")
def sigma_work(n: int) -> SigmaWork:
    """The UKF workspace for ``n`` error states."""
    ns = 2 * n + 1
    return SigmaWork(
        np.empty((ns, n)),
        np.empty((ns, FULL_DIM)),
        np.empty((n, n)),
        span_work(),
        np.empty((n, n)),
        np.empty((n, n)),
        np.empty(n),
        np.empty(ns, np.int64),
        np.zeros(LN_DIM * LANES),
    )


@njit(cache=True, error_model="numpy")
def run_ukf(
    x0: F64,
    P0: F64,
    sched: Schedule,
    fix: F64 | None,
    obs: F64 | None,
    cfg: Settings,
    log: RunLog,
    sm: SmoothLog,
) -> int:
    """Replay the total-state UKF from ``x0`` (full state) and ``P0`` (error coordinates).

    Arguments as ``kernels.ekf.run_ekf``; the unscented weights and sigma spread are
    ``cfg.wm``, ``cfg.wc`` and ``cfg.ukf_gamma``. Outputs carry the full state and the
    covariance converted to error coordinates (NED metres for position), like the EKF's.
    """
    n = cfg.n
    q_ref = x0[X_Q : X_Q + 4].copy()
    s = np.empty(n)
    from_full(x0, q_ref, n, s)
    sc = np.empty(n)
    coords_scale(x0, n, sc)
    P = np.empty((n, n))
    for r in range(n):
        for c in range(n):
            P[r, c] = P0[r, c] * sc[r] * sc[c]
    Pe = np.empty((n, n))
    X = np.empty(FULL_DIM)
    u = sched.u0.copy()
    st = UkfState(s, P, q_ref)
    ws = sigma_work(n)
    buf = epoch_buffers(sched.m_max, n, sched.t0)
    still = np.zeros(STILL_COLS)
    unit = np.ones(K_PR)
    ev_i, ev_f, counts = log.ev_i, log.ev_f, log.counts
    smoothing = sm_on(sm)
    n_sm = n if smoothing else 0
    prior, D, s_prior, sc_prev = np.empty((n_sm, n_sm)), np.empty((n, n)), np.empty(n), sc.copy()
    if smoothing:
        record_start(sm, x0, ws.prop.acc, P0, np.ones(n), counts[CNT_OUT])
    record_output(sched.t0, x0, P0, log)
    t_cur = sched.t0
    i = sched.i0
    stops = sched.stops
    for k in range(stops.shape[0]):
        stop = stops[k]
        t = stop[ST_T]
        i_next = ukf_predict(st, ImuSpan(sched.imu_t, sched.imu, i, t_cur, u, t), cfg, ws)
        ok = i_next >= 0
        if ok:
            for j in range(6):
                u[j] = ws.prop.u_end[j]
            if stop[ST_STILL] > 0:
                fill_still(still, sched.imu, i, i_next, u[3:6], (t - t_cur) * 1e-9, cfg)
            i = i_next
            t_cur = t
            if smoothing:
                record_prior(sm, k + 1, ws.sigX[0], ws.prop.acc)
                _sigma_cross(ws, s, cfg, D)
                sm.rows[k + 1, SM_CROSS] = pool_put_cross(sm, D, sc_prev, ws.sc)
                copy_vec(s_prior, s, s.shape[0])
            ok = keep_pd(P, n, ws.L, t, ev_i, ev_f, counts)
        at_rest = rest_plausible(stop, s[E_VEL : E_VEL + 3], P, cfg)  # UKF velocity: scale 1
        m, nb_ = epoch_layout(
            stop, fix, obs, sched.obs_start, cfg.nhc_on, at_rest, buf.rows, buf.blocks
        )
        if smoothing and ok:
            copy_mat(prior, P)  # the update's, after any reset, if there is one
        if ok and m > 0:
            ep = Epoch(t, m, nb_, u[3:6], still, unit)
            ok = ukf_update(ep, st, fix, obs, cfg, buf, ws, log, prior) and keep_pd(
                P, n, ws.L, t, ev_i, ev_f, counts
            )
        to_full(s, q_ref, n, X)
        coords_scale(X, n, sc)
        status = check_state(X, P, sc, cfg) if ok else STATUS_INDEFINITE
        if status != STATUS_OK:
            return fail(t, status, ev_i, ev_f, counts)
        if smoothing:
            updated = m > 0
            sm.rows[k + 1, SM_PRIOR] = pool_put(sm, prior, ws.sc) if updated else SM_AS_POSTERIOR
            for j in range(n):
                sm.dx[k + 1, j] = (s[j] - s_prior[j]) / ws.sc[j]
            record_post(sm, k + 1, P, sc, counts[CNT_OUT] if stop[ST_OUT] > 0 else -1)
            copy_vec(sc_prev, sc, sc.shape[0])
        if stop[ST_OUT] > 0:
            _error_cov(P, sc, n, Pe)
            record_output(t, X, Pe, log)
        counts[CNT_STOP] = k + 1
    return STATUS_OK
