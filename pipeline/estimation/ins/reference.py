"""The filterpy reference backend: the same model driven by filterpy's EKF and UKF.

``run_ekf_filterpy`` and ``run_ukf_filterpy`` take exactly the records of the compiled
``kernels.ekf.run_ekf`` / ``kernels.ukf.run_ukf`` and fill the same outputs. Everything that
is model or bookkeeping is the *same* code: the span propagation and transition
(``models.ins``, ``models.ins_errors``), the measurement rows (``models.measurement``), the
gating, timeout resets, positive-definiteness repair, NaN barrier and recording
(``core.gating``), and the EKF's measurement front end (``kernels.ekf.ekf_prepare``).
filterpy does the estimator arithmetic: ``ExtendedKalmanFilter.predict`` / ``update``
(Joseph form) on the error state, and ``UnscentedKalmanFilter`` with
``MerweScaledSigmaPoints`` on the UKF coordinates, its ``fx`` integrating one sigma point
through the span and its ``hx`` predicting the rows.

The loop runs in Python, one stop at a time, so this backend is slow; it is the community
reference the compiled backend is checked against (tests require agreement within 1e-6
sigma).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter, MerweScaledSigmaPoints, UnscentedKalmanFilter

from navreplay.pipeline.estimation.core import gating as gt
from navreplay.pipeline.estimation.core import linalg as la
from navreplay.pipeline.estimation.core import runlog as rl
from navreplay.pipeline.estimation.core.runlog import GatedBlocks, RunLog
from navreplay.pipeline.estimation.ins.kernels import common as cm
from navreplay.pipeline.estimation.ins.kernels import smoother as sk
from navreplay.pipeline.estimation.ins.kernels.ekf import ekf_prepare
from navreplay.pipeline.estimation.ins.kernels.records import (
    Epoch,
    RowPrediction,
    Schedule,
    Settings,
    SmoothLog,
)
from navreplay.pipeline.estimation.ins.kernels.unscented import sigma_h
from navreplay.pipeline.estimation.ins.models import ins, ins_errors
from navreplay.pipeline.estimation.ins.models import measurement as me
from navreplay.pipeline.nav.earth import F64, I64


@dataclass
class _Run:
    """A replay's records (the kernel's arguments) and the loop state of the driver."""

    sched: Schedule
    fix: F64 | None
    obs: F64 | None
    cfg: Settings
    log: RunLog
    sm: SmoothLog

    def __post_init__(self) -> None:
        n, m_max = self.cfg.n, self.sched.m_max
        self.t_cur = int(self.sched.t0)
        self.i = int(self.sched.i0)
        self.still = np.zeros(me.STILL_COLS)
        self.r_scale = np.ones(me.K_PR)  # the fix rows' variance multipliers (iae_ekf)
        self.u = self.sched.u0.copy()
        self.step = ins.Stepping(self.cfg.substeps, self.cfg.max_step_s, self.cfg.gap_s)
        self.out = ins.span_work()
        self.L = np.empty((n, n))
        self.Phi, self.Qd = np.empty((n, n)), np.empty((n, n))
        self.buf = cm.epoch_buffers(m_max, n, int(self.sched.t0))
        self.prior = np.empty((n, n))  # the UKF's prior of the current stop, for smoothing

    def stops(self) -> Iterator[tuple[int, I64, int]]:
        """(index, row, time in ns) of every stop of the schedule, in order."""
        for k, stop in enumerate(self.sched.stops):
            yield k, stop, int(stop[me.ST_T])

    def error_filter(self, kind: Any, P0: F64) -> Any:
        """A filterpy filter of class ``kind`` on the error state: zero, covariance ``P0``."""
        kf = kind(dim_x=self.cfg.n, dim_z=1)
        kf.x = np.zeros(self.cfg.n)
        kf.P = np.array(P0, dtype=float)
        return kf

    def span(self, X: F64, t: int, accumulate: bool) -> int:
        """Propagate ``X`` to ``t`` from the cursor (the cursor does not move)."""
        span = ins.ImuSpan(self.sched.imu_t, self.sched.imu, self.i, self.t_cur, self.u, t)
        return int(ins.propagate_span(X, span, self.step, self.out, accumulate))

    @property
    def acc(self) -> F64:
        """The span accumulator of the last ``span(..., accumulate=True)``."""
        return self.out.acc

    def advance(self, i_next: int, t: int) -> None:
        span_s = (t - self.t_cur) * 1e-9  # the standstill rows' values, used at rest only
        cm.fill_still(self.still, self.sched.imu, self.i, i_next, self.out.u_end[3:6], span_s,
                      self.cfg)  # fmt: skip
        self.i = i_next
        self.u[:] = self.out.u_end
        self.t_cur = t

    def epoch(self, t: int, m: int, nb_: int) -> Epoch:
        """The epoch at ``t`` of ``m`` rows in ``nb_`` blocks (after ``advance`` to ``t``)."""
        return Epoch(t, m, nb_, self.u[3:6].copy(), self.still.copy(), self.r_scale.copy())

    def predict_nominal(self, X: F64, P: F64, t: int, k: int) -> None:
        """Propagate the nominal state ``X`` to ``t`` (the cursor moves with it), and the
        span's transition and process noise (for covariance ``P`` at its start) into ``Phi``,
        ``Qd`` (error-state filters); for smoothing, stop ``k``'s nominal state and span."""
        self.advance(self.span(X, t, True), t)
        ins_errors.second_order_noise(P, self.acc, self.cfg.noise)
        if sk.sm_on(self.sm):
            sk.record_prior(self.sm, k + 1, X, self.acc)
        ins_errors.transition(X, self.acc, self.cfg.noise, self.cfg.n, self.Phi, self.Qd)

    def record_start(self, X: F64, P: F64, scale: F64) -> None:
        """The smoothing log's start row (before the start's output is recorded)."""
        if sk.sm_on(self.sm):
            sk.record_start(self.sm, X, self.acc, P, scale, self.log.counts[rl.CNT_OUT])

    def record_cross(
        self, k: int, sig: F64, x: F64, sc: F64, sig_f: F64, x_f: F64, sc_f: F64
    ) -> None:
        """The UKF's stop ``k`` opened for smoothing with the cross covariance of the sigma
        points ``sig`` about ``x`` (scale ``sc``) and where they went, ``sig_f`` about the
        prior ``x_f`` (scale ``sc_f``)."""
        sk.record_prior(self.sm, k + 1, x, self.acc)
        D = (sig - x).T @ (self.cfg.wc[:, None] * (sig_f - x_f))
        self.sm.rows[k + 1, sk.SM_CROSS] = sk.pool_put_cross(self.sm, D, sc, sc_f)

    def record_ukf_update(self, k: int, updated: bool, ds: F64, sc: F64) -> None:
        """The UKF's prior of stop ``k`` (``self.prior``; its posterior where it made no
        update) and the correction ``ds`` of its coordinates (scale ``sc``)."""
        if updated:
            self.record_prior_cov(k, self.prior, sc)
        else:
            self.sm.rows[k + 1, sk.SM_PRIOR] = sk.SM_AS_POSTERIOR
        self.sm.dx[k + 1, :] = ds / sc

    def record_prior_cov(self, k: int, P: F64, scale: F64) -> None:
        """Pool the prior covariance of stop ``k`` (one the transition does not give)."""
        if sk.sm_on(self.sm):
            self.sm.rows[k + 1, sk.SM_PRIOR] = sk.pool_put(self.sm, P, scale)

    def prepare(self, kf: Any, t: int, stop: I64, X: F64) -> tuple[int, int]:
        """``ekf_prepare`` of the epoch at ``stop`` on the covariance of the error-state
        filter ``kf``; returns (rows, accepted rows) (``buf.acc_rows``)."""
        m, nb_ = self.layout(stop, X[ins.X_VEL : ins.X_VEL + 3], np.asarray(kf.P, dtype=float))
        if m == 0:
            return 0, 0
        P = np.ascontiguousarray(kf.P)
        ep = self.epoch(t, m, nb_)
        ma = int(ekf_prepare(ep, X, P, self.fix, self.obs, self.cfg, self.buf, self.log))
        kf.P = P
        return m, ma

    def inject(self, kf: Any, X: F64, k: int) -> None:
        """Move the error estimate of ``kf`` into the nominal state ``X`` (error reset), and
        keep it as stop ``k``'s correction for smoothing."""
        n = self.cfg.n
        dx = np.asarray(kf.x, dtype=float).reshape(n)
        ins.inject(X, dx, n)
        if sk.sm_on(self.sm):
            self.sm.dx[k + 1, :] = dx
        kf.x = np.zeros(n)

    def finish_kf(self, kf: Any, k: int, stop: I64, X: F64) -> int:
        """``finish`` of stop ``k`` for the error-state filter ``kf``, counted as done if
        it passed."""
        P = np.ascontiguousarray(kf.P)
        status = self.finish(k, stop, X, P, P, np.ones(self.cfg.n))
        kf.P = P
        if status == gt.STATUS_OK:
            self.log.counts[rl.CNT_STOP] = k + 1
        return status

    def layout(self, stop: I64, v: F64, P: F64) -> tuple[int, int]:
        """The rows and blocks of the epoch at ``stop`` (``v``, ``P``: the filter's velocity
        and covariance, whether a standstill update applies)."""
        at_rest = bool(cm.rest_plausible(stop, v, P, self.cfg))
        m, nb_ = me.epoch_layout(
            stop, self.fix, self.obs, self.sched.obs_start, self.cfg.nhc_on, at_rest,
            self.buf.rows, self.buf.blocks,
        )  # fmt: skip
        return int(m), int(nb_)

    def finish(self, k: int, stop: I64, X: F64, P: F64, P_err: F64, scale: F64) -> int:
        """Positive definiteness, the NaN barrier and the output of stop ``k``."""
        log, t = self.log, int(stop[me.ST_T])
        ok = gt.keep_pd(P, self.cfg.n, self.L, t, log.ev_i, log.ev_f, log.counts)
        status = int(cm.check_state(X, P, scale, self.cfg)) if ok else 3
        if status != gt.STATUS_OK:
            return int(gt.fail(t, status, log.ev_i, log.ev_f, log.counts))
        if sk.sm_on(self.sm):
            out_row = log.counts[rl.CNT_OUT] if stop[me.ST_OUT] > 0 else -1
            sk.record_post(self.sm, k + 1, P, scale, out_row)
        if stop[me.ST_OUT] > 0:
            gt.record_output(t, X, P_err, log)
        return gt.STATUS_OK


def run_ekf_filterpy(
    x0: F64,
    P0: F64,
    sched: Schedule,
    fix: F64 | None,
    obs: F64 | None,
    cfg: Settings,
    log: RunLog,
    sm: SmoothLog,
) -> int:
    """``kernels.ekf.run_ekf`` with filterpy's ``ExtendedKalmanFilter`` doing predict/update."""
    run = _Run(sched, fix, obs, cfg, log, sm)
    n, buf = cfg.n, run.buf
    ekf = run.error_filter(ExtendedKalmanFilter, P0)
    X = x0.copy()
    run.record_start(X, ekf.P, np.ones(n))
    gt.record_output(sched.t0, X, ekf.P, log)
    for k, stop, t in run.stops():
        run.predict_nominal(X, np.asarray(ekf.P, dtype=float), t, k)
        ekf.F, ekf.Q = run.Phi, run.Qd
        ekf.x = np.zeros(n)
        ekf.predict()
        P_prop = np.array(ekf.P, dtype=float)
        _, ma = run.prepare(ekf, t, stop, X)
        if not np.array_equal(P_prop, ekf.P):  # a stream reset: not the transition's
            run.record_prior_cov(k, np.ascontiguousarray(ekf.P), np.ones(n))
        if ma > 0:
            a = buf.acc_rows[:ma]
            Ha, hx = buf.H[a, :n].copy(), buf.z[a] - buf.nu[a]
            ekf.update(
                buf.z[a], HJacobian=lambda _x, h=Ha: h, Hx=lambda _x, v=hx: v, R=np.diag(buf.r[a])
            )
            run.inject(ekf, X, k)
        status = run.finish_kf(ekf, k, stop, X)
        if status != gt.STATUS_OK:
            return status
    return gt.STATUS_OK


def run_ukf_filterpy(
    x0: F64,
    P0: F64,
    sched: Schedule,
    fix: F64 | None,
    obs: F64 | None,
    cfg: Settings,
    log: RunLog,
    sm: SmoothLog,
) -> int:
    """``kernels.ukf.run_ukf`` with filterpy's ``UnscentedKalmanFilter`` doing the UT."""
    run = _Run(sched, fix, obs, cfg, log, sm)
    smoothing = bool(sk.sm_on(sm))
    n = cfg.n
    points = MerweScaledSigmaPoints(n, alpha=cfg.ukf_alpha, beta=cfg.ukf_beta, kappa=cfg.ukf_kappa)
    if not (
        np.allclose(points.Wm, cfg.wm, rtol=1e-12) and np.allclose(points.Wc, cfg.wc, rtol=1e-12)
    ):
        raise ValueError("filterpy's sigma-point weights differ from the kernel's")
    ukf = UnscentedKalmanFilter(dim_x=n, dim_z=1, dt=1.0, hx=None, fx=None, points=points)
    q_ref = x0[ins.X_Q : ins.X_Q + 4].copy()
    ukf.x = np.empty(n)
    ins.from_full(x0, q_ref, n, ukf.x)
    sc = np.empty(n)
    ins.coords_scale(x0, n, sc)
    ukf.P = P0 * np.outer(sc, sc)
    X = np.empty(ins.FULL_DIM)
    run.record_start(x0, P0, np.ones(n))
    gt.record_output(sched.t0, x0, P0, log)

    propagated: list[F64] = []  # the sigma points of a predict, where fx took them

    def fx(s: F64, dt: float, t_end: int, q_old: F64, q_new: F64) -> F64:
        Xs = np.empty(ins.FULL_DIM)
        ins.to_full(np.asarray(s, dtype=float), q_old, n, Xs)
        run.span(Xs, t_end, False)
        out = np.empty(n)
        ins.from_full(Xs, q_new, n, out)
        propagated.append(out)
        return out

    for k, stop, t in run.stops():
        x_prev, sc_prev = np.array(ukf.x, dtype=float), sc.copy()
        sig_prev = points.sigma_points(x_prev, ukf.P) if smoothing else None
        propagated.clear()
        q_ref = _ukf_predict(ukf, run, fx, q_ref, X, sc, t)
        sc_prior, s_prior = sc.copy(), np.array(ukf.x, dtype=float)
        if sig_prev is not None:  # (not ukf.sigmas_f: filterpy redraws those after predict)
            prior_pts = (sig_prev, x_prev, sc_prev, np.array(propagated), s_prior, sc_prior)
            run.record_cross(k, *prior_pts)
        P = np.ascontiguousarray(ukf.P)
        ok = gt.keep_pd(P, n, run.L, t, log.ev_i, log.ev_f, log.counts)
        ukf.P = P
        run.prior = np.array(P)
        x = np.asarray(ukf.x, dtype=float)
        m, nb_ = run.layout(stop, x[ins.E_VEL : ins.E_VEL + 3], np.asarray(ukf.P, dtype=float))
        if ok and m > 0:
            _ukf_update(ukf, points, run, t, q_ref, m, nb_)
        ins.to_full(np.asarray(ukf.x, dtype=float), q_ref, n, X)
        ins.coords_scale(X, n, sc)
        P = np.ascontiguousarray(ukf.P)
        if smoothing and ok:
            run.record_ukf_update(k, m > 0, np.asarray(ukf.x, dtype=float) - s_prior, sc_prior)
        status = run.finish(k, stop, X, P, P / np.outer(sc, sc), sc) if ok else 3
        ukf.P = P
        if status != gt.STATUS_OK:
            return status if ok else int(gt.fail(t, status, log.ev_i, log.ev_f, log.counts))
        log.counts[rl.CNT_STOP] = k + 1
    return gt.STATUS_OK


def _ukf_predict(ukf: Any, run: _Run, fx: Any, q_ref: F64, X: F64, sc: F64, t: int) -> F64:
    """filterpy's predict to ``t`` (the cursor moves with it); ``X`` and ``sc`` become the
    central sigma point's full state and coordinate scale, which carries the process-noise
    accumulation and the new attitude reference (returned)."""
    n, cfg = run.cfg.n, run.cfg
    ins.to_full(np.asarray(ukf.x, dtype=float), q_ref, n, X)
    i_next = run.span(X, t, True)
    ins_errors.second_order_noise(np.asarray(ukf.P, dtype=float), run.acc, cfg.noise)
    ins_errors.transition(X, run.acc, cfg.noise, n, run.Phi, run.Qd)
    ins.coords_scale(X, n, sc)
    q_new = X[ins.X_Q : ins.X_Q + 4].copy()
    ukf.Q = run.Qd * np.outer(sc, sc)
    ukf.predict(dt=(t - run.t_cur) * 1e-9, fx=fx, t_end=t, q_old=q_ref.copy(), q_new=q_new)
    run.advance(i_next, t)
    return q_new


def _ukf_update(ukf: Any, points: Any, run: _Run, t: int, q_ref: F64, m: int, nb_: int) -> None:
    """Gate with the shared code, then let filterpy update with the accepted rows."""
    cfg, buf = run.cfg, run.buf
    n, rows, blocks, wm, wc = cfg.n, buf.rows, buf.blocks, cfg.wm, cfg.wc
    Xm = np.empty(ins.FULL_DIM)
    ins.to_full(np.asarray(ukf.x, dtype=float), q_ref, n, Xm)
    ref = Xm[:3].copy()
    sc = np.empty(n)
    ins.coords_scale(Xm, n, sc)
    z, r = np.empty(m), np.empty(m)
    ep = run.epoch(t, m, nb_)
    me.epoch_z(rows, m, run.fix, run.obs, ref, cfg.nhc_sigma, ep.still, z, r)
    dr = np.empty(m)
    me.gate_shift(rows, m, run.fix, r, dr)
    pred = RowPrediction(rows, m, ref, ep.w_ib_b, cfg.lever_b)
    h_ref = np.empty(m)  # as the kernel: rows relative to the mean's prediction
    me.epoch_h(Xm, rows, m, run.obs, ref, ep.w_ib_b, cfg.lever_b, h_ref)
    z -= h_ref
    nis, accepted = np.empty(nb_), np.empty(nb_, np.int64)
    Z = np.empty((2 * n + 1, m))
    for attempt in range(2):
        sig = points.sigma_points(ukf.x, ukf.P)
        sigma_h(sig, q_ref, pred, run.obs, h_ref, np.empty(ins.FULL_DIM), Z)
        zp = wm @ Z
        dz = Z - zp
        S = np.ascontiguousarray(dz.T @ (wc[:, None] * dz) + np.diag(r))
        nu = z - zp
        g = GatedBlocks(nu, gt.gating_cov(S, dr, m), blocks, nb_, nis, accepted)
        gt.gate_blocks(nu, g.S, blocks, nb_, cfg.gate, nis, accepted, np.empty((3, 6)))
        if attempt == 1:
            break
        P = np.ascontiguousarray(ukf.P)
        reset = cm.reset_timed_out(t, P, g, buf, sc, cfg, run.log)
        ukf.P = P
        if not reset:
            break
    run.prior = np.array(ukf.P)  # after any reset: the prior a smoother takes
    a = buf.acc_rows[: cm.close_gating(t, g, cfg, buf, run.log)].copy()
    if a.size == 0:
        return
    ukf.sigmas_f = sig

    def hx(s: F64) -> F64:
        Xs = np.empty(ins.FULL_DIM)
        ins.to_full(np.asarray(s, dtype=float), q_ref, n, Xs)
        out = np.empty(m)
        me.epoch_h(Xs, rows, m, run.obs, ref, ep.w_ib_b, cfg.lever_b, out)
        return (out - h_ref)[a]

    ukf.update(z[a], R=np.diag(r[a]), hx=hx)
    P = np.ascontiguousarray(ukf.P)
    la.symmetrize(P, n)
    ukf.P = P
