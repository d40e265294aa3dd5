"""Small dense linear algebra of every family's compiled filters (numba): Cholesky, positive-
definiteness repair, covariance propagation, innovation covariance and the Joseph-form update.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from navreplay.pipeline._jit import njit
from navreplay.pipeline.nav.earth import F64, I64

# Explicit signatures for the helpers called from many places: a call from jitted code
# otherwise compiles a new specialization for every array layout it sees. numba compiles them
# when this module is imported (or loads them from its cache).
_F2 = nb.float64[:, :]
_F2C = nb.float64[:, ::1]
_F1C = nb.float64[::1]
_I2C = nb.int64[:, ::1]
_I1C = nb.int64[::1]


@njit(nb.boolean(_F2, nb.int64, _F2), cache=True, error_model="numpy")
def cholesky(A: F64, n: int, L: F64) -> bool:
    """Lower Cholesky factor of ``A[:n, :n]`` into ``L``; False if not positive definite."""
    for j in range(n):
        s = A[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not s > 0.0 or not math.isfinite(s):
            return False
        d = math.sqrt(s)
        L[j, j] = d
        for i in range(j + 1, n):
            s = A[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s / d
        for i in range(j):
            L[i, j] = 0.0
    return True


@njit(nb.void(_F2, nb.int64, _F2, nb.int64), cache=True, error_model="numpy")
def cho_solve(L: F64, n: int, B: F64, k: int) -> None:
    """Solve ``(L L^T) X = B[:n, :k]`` in place (``L`` from ``cholesky``)."""
    for c in range(k):
        for i in range(n):
            s = B[i, c]
            for j in range(i):
                s -= L[i, j] * B[j, c]
            B[i, c] = s / L[i, i]
        for i in range(n - 1, -1, -1):
            s = B[i, c]
            for j in range(i + 1, n):
                s -= L[j, i] * B[j, c]
            B[i, c] = s / L[i, i]


@njit(cache=True, error_model="numpy")
def symmetrize(P: F64, n: int) -> None:
    """P <- (P + P^T) / 2 on ``P[:n, :n]``."""
    for i in range(n):
        for j in range(i + 1, n):
            a = 0.5 * (P[i, j] + P[j, i])
            P[i, j] = a
            P[j, i] = a


@njit(cache=True, error_model="numpy")
def ensure_pd(P: F64, n: int, L: F64) -> tuple[bool, bool, float]:
    """Keep ``P[:n, :n]`` symmetric positive definite; ``L`` receives its Cholesky factor.

    A ``P`` that fails the Cholesky test is repaired by adding a diagonal jitter, starting at
    1e-12 of its largest variance (at least 1e-30) and growing tenfold until the factorization
    succeeds (the minimal-change repair; no eigendecomposition is needed).

    Returns:
        (ok, repaired, total jitter added to each variance): ``ok`` is False when no repair is
        possible (non-finite entries); the caller logs a repair event.
    """
    symmetrize(P, n)
    if cholesky(P, n, L):
        return True, False, 0.0
    big = 0.0
    for i in range(n):
        for j in range(n):
            if not math.isfinite(P[i, j]):
                return False, False, math.nan
        big = max(big, abs(P[i, i]))
    step = max(1e-12 * big, 1e-30)
    total = 0.0
    for _ in range(60):
        for i in range(n):
            P[i, i] += step
        total += step
        if cholesky(P, n, L):
            return True, True, total
        step *= 10.0
    return False, True, total


@njit(cache=True, error_model="numpy", inline="always")
def mat_mul_into(A: F64, B: F64, rows: int, inner: int, cols: int, out: F64) -> None:
    """``out[:rows, :cols] = A[:rows, :inner] B[:inner, :cols]``, each entry summed in the
    order of ``inner``."""
    for i in range(rows):
        for j in range(cols):
            a = 0.0
            for k in range(inner):
                a += A[i, k] * B[k, j]
            out[i, j] = a


@njit(cache=True, error_model="numpy")
def propagate_cov(P: F64, Phi: F64, Qd: F64, n: int, tmp: F64) -> None:
    """``P <- Phi P Phi^T + Qd`` in place (``tmp``: scratch (n, n))."""
    mat_mul_into(Phi, P, n, n, n, tmp)
    for r in range(n):
        for c in range(r, n):
            a = Qd[r, c]
            for k in range(n):
                a += tmp[r, k] * Phi[c, k]
            P[r, c] = a
            P[c, r] = a


@njit(cache=True, error_model="numpy")
def innovation_cov(H: F64, P: F64, r: F64, m: int, n: int, PHt: F64, S: F64) -> None:
    """``PHt = P H^T`` (n, m) and ``S = H P H^T + diag(r)`` (m, m) for the first ``m`` rows."""
    mat_mul_into(P, H.T, n, n, m, PHt)
    for k in range(m):
        for q in range(k, m):
            a = 0.0
            for j in range(n):
                a += H[k, j] * PHt[j, q]
            S[k, q] = a
            S[q, k] = a
        S[k, k] += r[k]


@njit(cache=True, error_model="numpy", inline="always")
def joseph_update(
    P: F64, n: int, H: F64, S: F64, r: F64, nu: F64, acc_rows: I64, ma: int
) -> tuple[F64, bool]:
    """Kalman update of the accepted rows in Joseph form; returns (dx, ok).

    ``K = P H^T S^-1`` (by Cholesky), ``P <- (I - K H) P (I - K H)^T + K R K^T``, symmetrized.
    ``ok`` is False (and nothing changes) if the accepted ``S`` is not positive definite.
    """
    Ha = np.empty((ma, n))
    Sa = np.empty((ma, ma))
    for i in range(ma):
        for j in range(n):
            Ha[i, j] = H[acc_rows[i], j]
        for j in range(ma):
            Sa[i, j] = S[acc_rows[i], acc_rows[j]]
    L = np.empty((ma, ma))
    dx = np.zeros(n)
    if not cholesky(Sa, ma, L):
        return dx, False
    Kt = np.empty((ma, n))  # (P H^T)^T, then S^-1 (P H^T)^T = K^T
    mat_mul_into(Ha, P, ma, n, n, Kt)
    cho_solve(L, ma, Kt, n)
    for j in range(n):
        a = 0.0
        for i in range(ma):
            a += Kt[i, j] * nu[acc_rows[i]]
        dx[j] = a
    A = np.empty((n, n))  # I - K H
    for i in range(n):
        for j in range(n):
            a = 1.0 if i == j else 0.0
            for k in range(ma):
                a -= Kt[k, i] * Ha[k, j]
            A[i, j] = a
    AP = np.empty((n, n))
    mat_mul_into(A, P, n, n, n, AP)
    for i in range(n):
        for j in range(i, n):
            a = 0.0
            for k in range(n):
                a += AP[i, k] * A[j, k]
            for k in range(ma):
                a += Kt[k, i] * r[acc_rows[k]] * Kt[k, j]
            P[i, j] = a
            P[j, i] = a
    return dx, True
