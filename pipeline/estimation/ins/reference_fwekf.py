"""The filterpy reference backend of the FWEKF (paper 004).

``run_fwekf_filterpy`` takes the records of ``kernels.fwekf.run_fwekf``. The span
propagation, transition, measurement front end (gating, resets, recording), residual ring and
fuzzy system are the shared code; filterpy's ``KalmanFilter`` on the error state does the
estimator arithmetic of paper 004 eq. 24-27 (see ``kernels.fwekf``): its predict is given
``F = alpha Phi``, so that ``F P F^T + Q`` is eq. 26 (``alpha^2 Phi P Phi^T + Q``; the error
state is zero before the predict, so ``F x`` is unaffected; filterpy's own fading ``alpha``
refuses the values below 1 that Table 1's NS rule produces), and its update (Joseph form) is
given ``R / alpha^2``, the measurement covariance of the weighted gain of eq. 24. Both use
the fuzzy alpha at the stops that carry a fix and 1 elsewhere. With ``iae.IaeParams`` the
same driver runs ``iae_ekf``: alpha 1, the fix rows' variances multiplied in the front end
by the innovation-based estimate (``kernels.fwekf``).
"""

from __future__ import annotations

import numpy as np
from filterpy.kalman import KalmanFilter

from navreplay.pipeline.estimation.core import gating as gt
from navreplay.pipeline.estimation.core import runlog as rl
from navreplay.pipeline.estimation.core.runlog import RunLog
from navreplay.pipeline.estimation.ins.fuzzy import (
    FZ_MODE,
    FZ_WINDOW,
    MODE_IAE,
    infer_alpha,
    residual_inputs,
)
from navreplay.pipeline.estimation.ins.iae import N_KINDS, iae_scales, push_innovations
from navreplay.pipeline.estimation.ins.kernels.fwekf import RING_COLS, push_residuals
from navreplay.pipeline.estimation.ins.kernels.records import (
    Fading,
    Schedule,
    Settings,
    SmoothLog,
)
from navreplay.pipeline.estimation.ins.models import measurement as me
from navreplay.pipeline.estimation.ins.reference import _Run
from navreplay.pipeline.nav.earth import F64, I64


def run_fwekf_filterpy(
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
    """``kernels.fwekf.run_fwekf`` with filterpy's fading-memory ``KalmanFilter``."""
    run = _Run(sched, fix, obs, cfg, log, sm)
    n, buf, counts = cfg.n, run.buf, log.counts
    fz, out_alpha = fading.fz, fading.out_alpha
    kf = run.error_filter(KalmanFilter, P0)
    X = x0.copy()
    iae = fz[FZ_MODE] == MODE_IAE
    ring = np.full((int(fz[FZ_WINDOW]), 3 * N_KINDS if iae else RING_COLS), np.nan)
    n_ring, alpha = 0, 1.0
    out_alpha[0] = alpha
    run.record_start(X, kf.P, np.ones(n))
    gt.record_output(sched.t0, X, kf.P, log)
    for k, stop, t in run.stops():
        run.predict_nominal(X, np.asarray(kf.P, dtype=float), t, k)
        a_k = alpha if stop[me.ST_FIX] >= 0 and not iae else 1.0  # once per GNSS cycle
        kf.F, kf.Q = a_k * run.Phi, run.Qd.copy()  # eq. 26: (a Phi) P (a Phi)^T + Q
        kf.x = np.zeros(n)
        kf.predict()
        m, ma = run.prepare(kf, t, stop, X)
        if m > 0:
            run.record_prior_cov(k, np.ascontiguousarray(kf.P), np.ones(n))
        if ma > 0:
            a = buf.acc_rows[:ma]
            kf.dim_z = ma
            R_w = np.diag(buf.r[a]) / (a_k * a_k)  # eq. 24: R / alpha^2 in gain and Joseph
            kf.update(buf.nu[a].copy(), R=R_w, H=buf.H[a, :n].copy())
            run.inject(kf, X, k)
        if m > 0 and stop[me.ST_FIX] >= 0 and iae:
            n_ring = int(
                push_innovations(ring, n_ring, buf.rows, buf.nu, buf.S, buf.r, run.r_scale, m)
            )
            iae_scales(ring, n_ring, fz, run.r_scale)
            alpha = float(run.r_scale[me.K_POS])
        elif m > 0 and stop[me.ST_FIX] >= 0:
            n_ring = int(push_residuals(ring, n_ring, buf.rows, buf.nu, buf.S, m))
            rules = fuzzy_rules(fading.rules)
            alpha = float(infer_alpha(*residual_inputs(ring, n_ring), fz, rules))
        if stop[me.ST_OUT] > 0 and counts[rl.CNT_OUT] < out_alpha.shape[0]:
            out_alpha[counts[rl.CNT_OUT]] = alpha
        status = run.finish_kf(kf, k, stop, X)
        if status != gt.STATUS_OK:
            return status
    return gt.STATUS_OK


def fuzzy_rules(rules: I64) -> I64:
    """The rule table as the contiguous int64 array the compiled inference expects."""
    return np.ascontiguousarray(rules, dtype=np.int64)
