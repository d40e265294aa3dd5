"""The filterpy reference of the backward pass (``kernels.smoother.smooth``).

Each backward step is one call of filterpy's ``rts_smoother`` on the pair (stop k, stop k+1),
the linear step the filters' error-state form reduces to: the state of stop k is its zero
correction, that of stop k+1 the smoothed error relative to its prior (``e``), ``F`` the
transition (``ins_errors.transition``; for the UKF the statistical one, ``D^T P_k^-1`` of the
sigma points' cross covariance ``D``) and ``Q`` what makes ``F P_k F^T + Q`` the prior the
filter updated from (of a stream reset or a fading: its positive semi-definite part, as the
compiled pass). filterpy then gives the gain, the
smoothed correction and covariance; the frames (``e = dx + d``) and the output are the same
code as the compiled pass. ``tests/pipeline/estimation/test_smoother.py`` checks that both
agree.
"""

from __future__ import annotations

import numpy as np
from filterpy.kalman import rts_smoother

from navreplay.pipeline.estimation.ins.kernels import smoother as sk
from navreplay.pipeline.estimation.ins.kernels.records import Settings, SmoothLog
from navreplay.pipeline.estimation.ins.models import ins
from navreplay.pipeline.estimation.ins.models.ins_errors import transition
from navreplay.pipeline.nav.earth import F64


def smooth_filterpy(sm: SmoothLog, out_x: F64, out_P: F64, cfg: Settings, xs: F64, Ps: F64) -> int:
    """``kernels.smoother.smooth`` with filterpy's ``rts_smoother`` doing each step."""
    n = cfg.n
    last = int(sm.counts[sk.SM_C_STOPS]) - 1
    if last < 0:
        return sk.SMOOTH_OK
    Psm = _posterior(sm, last, out_P)
    e = sm.dx[last].copy()
    _write(sm, last, out_x, np.zeros(n), Psm, xs, Ps)
    Phi, Qd = np.empty((n, n)), np.empty((n, n))
    for k in range(last - 1, -1, -1):
        Pk = _posterior(sm, k, out_P)
        jp, jc = sm.rows[k + 1, sk.SM_PRIOR], sm.rows[k + 1, sk.SM_CROSS]
        if jc >= 0:
            F = np.linalg.solve(Pk, sm.pool[jc]).T  # (P_k^-1 D)^T = D^T P_k^-1
            Qd[:] = 0.0
        else:
            X = sm.x[k + 1].copy()
            transition(X, sm.acc[k + 1], cfg.noise, n, Phi, Qd)
            F = Phi
        if jc < 0 and jp >= 0:  # the positive semi-definite part, as the compiled pass
            w, V = np.linalg.eigh(0.5 * (sm.pool[jp] + sm.pool[jp].T) - F @ Pk @ F.T)
            Qd = (V * np.maximum(w, 0.0)) @ V.T
        Pp = (
            sm.pool[jp] if jp >= 0 and jc >= 0
            else _posterior(sm, k + 1, out_P) if jp == sk.SM_AS_POSTERIOR
            else F @ Pk @ F.T + Qd
        )  # fmt: skip
        if not np.all(np.linalg.eigvalsh(Pp) > 0.0):
            return sk.SMOOTH_PRIOR_INDEFINITE
        Q = Pp - F @ Pk @ F.T
        x, P, _, _ = rts_smoother(
            np.array([np.zeros(n), e]), np.array([Pk, Psm]),
            np.array([F, np.eye(n)]), np.array([Q, np.zeros((n, n))]),
        )  # fmt: skip
        d, Psm = x[0], P[0]
        if not np.all(np.linalg.eigvalsh(Psm) > 0.0):
            return sk.SMOOTH_INDEFINITE
        e = sm.dx[k] + d
        _write(sm, k, out_x, d, Psm, xs, Ps)
    return sk.SMOOTH_OK


def _posterior(sm: SmoothLog, k: int, out_P: F64) -> F64:
    j = sm.rows[k, sk.SM_POST]
    return np.array(sm.pool[j] if j >= 0 else out_P[sm.rows[k, sk.SM_OUT]])


def _write(sm: SmoothLog, k: int, out_x: F64, d: F64, Psm: F64, xs: F64, Ps: F64) -> None:
    o = sm.rows[k, sk.SM_OUT]
    if o < 0:
        return
    xs[o] = out_x[o]
    ins.inject(xs[o], d, d.shape[0])
    Ps[o] = Psm
