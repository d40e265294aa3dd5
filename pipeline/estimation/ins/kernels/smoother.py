"""Rauch-Tung-Striebel smoothing of an INS run: what the forward kernels record per stop, and
the backward pass over it (numba).

The forward filters (``kernels.ekf``, ``kernels.fwekf``, ``kernels.ukf``) record a
``records.SmoothLog`` when given one with rows. The backward pass runs from the last stop to
the first, in error coordinates, and is the same for every estimator:

- the gain ``C_k = D_(k+1) (P-_(k+1))^-1``, with ``D`` the cross covariance of the posterior
  at stop k and the prior at stop k+1: ``P_k Phi^T`` for the EKFs (the transition of
  ``ins_errors.transition``), the sigma points' for the UKF (the unscented RTS smoother);
- the smoothed correction of stop k relative to its posterior ``d_k = C_k e_(k+1)``, where
  ``e_(k+1) = dx_(k+1) + d_(k+1)`` is the smoothed error relative to the *prior* at k+1 (the
  filters inject every update into their nominal state, so the forward error at a prior is
  the correction its update applied, ``dx``);
- the smoothed covariance ``P_k|N = P_k + C_k (P_(k+1)|N - P-_(k+1)) C_k^T``, for the EKFs
  in the equal Joseph form ``(I - C Phi) P_k (I - C Phi)^T + C (Q + P_(k+1)|N) C^T`` (a sum
  of positive semi-definite terms: the plain form loses definiteness to rounding where the
  gain is large, as through a long outage); a smoothed covariance that is not positive
  definite ends the pass (``SMOOTH_INDEFINITE``: the run keeps its forward estimate, and
  says so);
- at output stops the smoothed state ``x_k [+] d_k`` (``ins.inject``) and ``P_k|N``.

Memory: per stop a nominal state, a span accumulator and a correction (~0.4 kB for 15
states); covariances only where ``records.SmoothLog`` says. At the default 0.1 s step that is
~14 MB per hour beside the forward run's own output covariances, plus one covariance per
update epoch between output times (``benchmarks/bench_smoother.py`` measures it).
"""

from __future__ import annotations

import numpy as np

from navreplay.pipeline._jit import njit
from navreplay.pipeline.estimation.core.linalg import cho_solve, cholesky, propagate_cov
from navreplay.pipeline.estimation.ins.kernels.records import Settings, SmoothLog
from navreplay.pipeline.estimation.ins.models.ins import ACC_DIM, FULL_DIM, inject
from navreplay.pipeline.estimation.ins.models.ins_errors import transition
from navreplay.pipeline.nav.earth import F64

SM_POST, SM_PRIOR, SM_CROSS, SM_OUT = 0, 1, 2, 3
SM_C_STOPS, SM_C_POOL = 0, 1
#: ``rows[k, SM_PRIOR]`` of a stop without an update: its prior is its posterior
SM_AS_POSTERIOR = -2

#: how the backward pass ended
SMOOTH_OK, SMOOTH_PRIOR_INDEFINITE, SMOOTH_INDEFINITE = 0, 1, 2
SMOOTH_FAILURES = {
    SMOOTH_PRIOR_INDEFINITE: "a prior covariance is not positive definite",
    SMOOTH_INDEFINITE: "a smoothed covariance is not positive definite",
}


def allocate(n_stops: int, n_pool: int, n: int, nominal: bool = True) -> SmoothLog:
    """A smoothing log for ``n_stops`` stops (the start included) and ``n_pool`` pooled
    covariances; ``n_stops`` 0: a run without smoothing (the kernels record nothing).
    ``nominal`` False: no nominal state and span per stop (the UKF pools its priors and cross
    covariances instead)."""
    rows = -np.ones((n_stops, 4), np.int64)
    return SmoothLog(
        np.zeros((n_stops, FULL_DIM if nominal else 0)),
        np.zeros((n_stops, ACC_DIM if nominal else 0)),
        np.zeros((n_stops, n)),
        rows,
        np.zeros((n_pool, n, n)),
        np.zeros(2, np.int64),
    )


def grown(sm: SmoothLog) -> SmoothLog | None:
    """A fresh log whose pool holds what the run wanted, or None if it all fitted."""
    want = int(sm.counts[SM_C_POOL])
    if want <= sm.pool.shape[0]:
        return None
    size = max(want, 2 * sm.pool.shape[0])
    return allocate(sm.x.shape[0], size, sm.dx.shape[1], sm.x.shape[1] > 0)


def empty_like(sm: SmoothLog) -> SmoothLog:
    """A fresh log of the same size (a run repeated for the run log's sake)."""
    return allocate(sm.x.shape[0], sm.pool.shape[0], sm.dx.shape[1], sm.x.shape[1] > 0)


@njit(cache=True, error_model="numpy", inline="always")
def copy_vec(dst: F64, src: F64, n: int) -> None:
    """``dst[:n] = src[:n]`` as a loop: numba's slice assignment compiles a shape check whose
    error message (string formatting) took ~5 s of a cold filter compile."""
    for j in range(n):
        dst[j] = src[j]


@njit(cache=True, error_model="numpy", inline="always")
def copy_mat(dst: F64, src: F64) -> None:
    """``dst[:, :] = src`` as a loop (see ``copy_vec``)."""
    for r in range(src.shape[0]):
        for c in range(src.shape[1]):
            dst[r, c] = src[r, c]


@njit(cache=True, error_model="numpy", inline="always")
def sm_on(sm: SmoothLog) -> bool:
    """The run records for smoothing."""
    return bool(sm.x.shape[0] > 0)


@njit(cache=True, error_model="numpy")
def pool_put_cross(sm: SmoothLog, M: F64, sc_from: F64, sc_to: F64) -> int:
    """Store ``M / (sc_from sc_to^T)`` (error coordinates) in the pool; its row (a row past
    the pool is only counted: the run is repeated with a larger pool)."""
    j = sm.counts[SM_C_POOL]
    sm.counts[SM_C_POOL] = j + 1
    if j < sm.pool.shape[0]:
        n = sm.pool.shape[1]
        for r in range(n):
            for c in range(n):
                sm.pool[j, r, c] = M[r, c] / (sc_from[r] * sc_to[c])
    return int(j)


@njit(cache=True, error_model="numpy")
def pool_put(sm: SmoothLog, M: F64, scale: F64) -> int:
    """``pool_put_cross`` of a covariance (one coordinate scale)."""
    return pool_put_cross(sm, M, scale, scale)


@njit(cache=True, error_model="numpy")
def record_prior(sm: SmoothLog, k: int, X: F64, acc: F64) -> None:
    """Open row ``k`` (stop ``k - 1`` of the schedule): its nominal state before any update
    and the span accumulator that ended there (if the log keeps them); no correction yet."""
    for j in range(sm.x.shape[1]):
        sm.x[k, j] = X[j]
    for j in range(sm.acc.shape[1]):
        sm.acc[k, j] = acc[j]
    for j in range(sm.dx.shape[1]):
        sm.dx[k, j] = 0.0
    for c in range(4):
        sm.rows[k, c] = -1


@njit(cache=True, error_model="numpy")
def record_post(sm: SmoothLog, k: int, P: F64, scale: F64, out_row: int) -> None:
    """Close row ``k``: its output row, or (not an output) its posterior ``P`` pooled."""
    if out_row >= 0:
        sm.rows[k, SM_OUT] = out_row
    else:
        sm.rows[k, SM_POST] = pool_put(sm, P, scale)
    sm.counts[SM_C_STOPS] = k + 1


@njit(cache=True, error_model="numpy")
def record_start(sm: SmoothLog, X: F64, acc: F64, P: F64, scale: F64, out_row: int) -> None:
    """Row 0, the start: ``record_prior`` and ``record_post`` (its index typed int64, as
    every other row's: called with a literal 0 they would each compile a second time)."""
    first = int(np.int64(0))
    record_prior(sm, first, X, acc)
    record_post(sm, first, P, scale, out_row)


@njit(cache=True, error_model="numpy")
def changed(A: F64, B: F64, n: int) -> bool:
    """``A`` and ``B`` differ in any of their first ``n`` x ``n`` entries."""
    for r in range(n):
        for c in range(n):
            if A[r, c] != B[r, c]:
                return True
    return False


@njit(cache=True, error_model="numpy")
def _posterior(sm: SmoothLog, k: int, out_P: F64, P: F64) -> None:
    j = sm.rows[k, SM_POST]
    P[:, :] = sm.pool[j] if j >= 0 else out_P[sm.rows[k, SM_OUT]]


@njit(cache=True, error_model="numpy")
def smooth(sm: SmoothLog, out_x: F64, out_P: F64, cfg: Settings, xs: F64, Ps: F64) -> int:
    """The backward pass over the rows ``sm`` recorded (module docstring): the smoothed state
    and error covariance of every output row into ``xs`` (K, 18) and ``Ps`` (K, n, n).

    ``out_x``, ``out_P``: the forward run's outputs (the run log's). Returns ``SMOOTH_OK``, or
    ``SMOOTH_INDEFINITE`` if a prior covariance was not positive definite.
    """
    n = cfg.n
    last = sm.counts[SM_C_STOPS] - 1
    if last < 0:
        return SMOOTH_OK
    Pk = np.empty((n, n))
    Pp = np.empty((n, n))
    Psm = np.empty((n, n))
    Phi = np.empty((n, n))
    Qd = np.empty((n, n))
    tmp = np.empty((n, n))
    L = np.empty((n, n))
    Ct = np.empty((n, n))  # C^T = Pp^-1 D^T
    Cm = np.empty((n, n))  # C
    W = np.empty((n, n))
    sc = np.empty(n)
    Xw = np.empty(FULL_DIM)
    e = np.empty(n)
    d = np.zeros(n)
    _posterior(sm, last, out_P, Psm)
    for j in range(n):
        e[j] = sm.dx[last, j]
    _write(sm, last, out_x, d, Psm, n, xs, Ps)
    for k in range(last - 1, -1, -1):
        _posterior(sm, k, out_P, Pk)
        jp, jc = sm.rows[k + 1, SM_PRIOR], sm.rows[k + 1, SM_CROSS]
        if jp == -1 or jc < 0:
            Xw[:] = sm.x[k + 1]  # transition decays the fix-error states of its X: a copy
            transition(Xw, sm.acc[k + 1], cfg.noise, n, Phi, Qd)
        if jc < 0 and jp >= 0:  # an EKF prior beyond the transition (a reset, a fading)
            _prior_noise(sm.pool[jp], Pk, Phi, n, Qd, Pp, W)
        elif jp >= 0:
            Pp[:, :] = sm.pool[jp]
        elif jp == SM_AS_POSTERIOR:
            _posterior(sm, k + 1, out_P, Pp)
        else:
            Pp[:, :] = Pk
            propagate_cov(Pp, Phi, Qd, n, tmp)
        if jc >= 0:
            for r in range(n):
                for c in range(n):
                    Ct[r, c] = sm.pool[jc, c, r]
        else:
            for r in range(n):  # D^T = Phi P_k
                for c in range(n):
                    a = 0.0
                    for q in range(n):
                        a += Phi[r, q] * Pk[q, c]
                    Ct[r, c] = a
        if not _scaled_solve(Pp, n, Ct, L, sc):
            return SMOOTH_PRIOR_INDEFINITE
        Cm[:, :] = Ct.T
        for r in range(n):  # d = C e
            a = 0.0
            for q in range(n):
                a += Ct[q, r] * e[q]
            d[r] = a
        if jc >= 0:  # the UKF: P_k + C (P_(k+1)|N - P-) C^T
            for r in range(n):
                for c in range(n):
                    Psm[r, c] -= Pp[r, c]
            _add_sandwich(Psm, Cm, Pk, n, W)
            Psm[:, :] = Pk
        else:  # the EKFs, in Joseph form: (I - C Phi) P_k (I - C Phi)^T + C (Q + P_(k+1)|N) C^T
            for r in range(n):
                for c in range(n):
                    Psm[r, c] += Qd[r, c]
            for r in range(n):  # tmp = I - C Phi
                for c in range(n):
                    a = 1.0 if r == c else 0.0
                    for q in range(n):
                        a -= Ct[q, r] * Phi[q, c]
                    tmp[r, c] = a
            Pp[:, :] = 0.0  # the sum, built in Pp (the prior is not needed any more)
            _add_sandwich(Psm, Cm, Pp, n, W)
            _add_sandwich(Pk, tmp, Pp, n, W)
            Psm[:, :] = Pp
        if not _scaled_cholesky(Psm, n, L, sc):
            return SMOOTH_INDEFINITE
        for j in range(n):
            e[j] = sm.dx[k, j] + d[j]
        _write(sm, k, out_x, d, Psm, n, xs, Ps)
    return SMOOTH_OK


@njit(cache=True, error_model="numpy")
def _prior_noise(pooled: F64, Pk: F64, Phi: F64, n: int, Q: F64, Pp: F64, W: F64) -> None:
    """The process noise ``Q`` and prior ``Pp = Phi P_k Phi^T + Q`` of a stop whose pooled
    prior is not the transition's: ``Q`` is the positive semi-definite part of ``pooled -
    Phi P_k Phi^T``. A stream reset decorrelates the reset states, which no added noise
    does; its negative part is dropped, so that the smoothed covariance stays positive
    definite (the prior then holds at least what the filter's did in every direction)."""
    Z = np.zeros((n, n))
    Pp[:, :] = Pk
    propagate_cov(Pp, Phi, Z, n, W)  # Phi P_k Phi^T
    for r in range(n):
        for c in range(n):
            W[r, c] = 0.5 * (pooled[r, c] + pooled[c, r]) - Pp[r, c]
    w, V = np.linalg.eigh(W)
    for r in range(n):
        for c in range(n):
            a = 0.0
            for q in range(n):
                if w[q] > 0.0:
                    a += V[r, q] * w[q] * V[c, q]
            Q[r, c] = a
    for r in range(n):
        for c in range(n):
            Pp[r, c] += Q[r, c]


@njit(cache=True, error_model="numpy")
def _scaled_cholesky(A: F64, n: int, L: F64, sc: F64) -> bool:
    """The Cholesky factor of ``A`` scaled to unit diagonal (``sc``: the square roots of its
    diagonal) into ``L``; False if ``A`` is not positive definite. The scaling makes the test
    one of the correlations, not of the states' units (metres squared beside radians)."""
    for i in range(n):
        if not A[i, i] > 0.0:
            return False
        sc[i] = np.sqrt(A[i, i])
    for i in range(n):
        for j in range(n):
            L[i, j] = A[i, j] / (sc[i] * sc[j])
    return bool(cholesky(L, n, L))  # in place: it reads each lower entry before writing it


@njit(cache=True, error_model="numpy")
def _scaled_solve(A: F64, n: int, B: F64, L: F64, sc: F64) -> bool:
    """``B <- A^-1 B`` (n, n) through the Cholesky factor of ``A`` scaled to unit diagonal;
    False if ``A`` is not positive definite."""
    if not _scaled_cholesky(A, n, L, sc):
        return False
    for i in range(n):
        for j in range(n):
            B[i, j] /= sc[i]
    cho_solve(L, n, B, n)
    for i in range(n):
        for j in range(n):
            B[i, j] /= sc[i]
    return True


@njit(cache=True, error_model="numpy")
def _add_sandwich(M: F64, A: F64, out: F64, n: int, W: F64) -> None:
    """``out += A M A^T`` (symmetric; ``W`` scratch)."""
    for r in range(n):  # W = M A^T
        for c in range(n):
            a = 0.0
            for q in range(n):
                a += M[r, q] * A[c, q]
            W[r, c] = a
    for r in range(n):
        for c in range(r, n):
            a = 0.0
            for q in range(n):
                a += A[r, q] * W[q, c]
            out[r, c] += a
            if c != r:
                out[c, r] += a


@njit(cache=True, error_model="numpy")
def _write(sm: SmoothLog, k: int, out_x: F64, d: F64, Psm: F64, n: int, xs: F64, Ps: F64) -> None:
    """The smoothed output of row ``k``, if it is an output."""
    o = sm.rows[k, SM_OUT]
    if o < 0:
        return
    xs[o, :] = out_x[o]
    inject(xs[o], d, n)
    Ps[o, :, :] = Psm
