"""The unscented transform of every family's UKFs (numba): weights, sigma points, mean and
covariance, cross covariance.
"""

from __future__ import annotations

import math

import numpy as np

from navreplay.pipeline._jit import njit
from navreplay.pipeline.estimation.core.linalg import cholesky
from navreplay.pipeline.nav.earth import F64


def ukf_weights(n: int, alpha: float, beta: float, kappa: float) -> tuple[F64, F64, float]:
    """Scaled-UT weights (mean, covariance) and the sigma spread ``gamma = sqrt(n + lambda)``,
    ``lambda = alpha^2 (n + kappa) - n`` (paper 001; the same as filterpy's
    ``MerweScaledSigmaPoints``)."""
    lam = alpha**2 * (n + kappa) - n
    wm = np.full(2 * n + 1, 0.5 / (n + lam))
    wc = wm.copy()
    wm[0] = lam / (n + lam)
    wc[0] = lam / (n + lam) + (1.0 - alpha**2 + beta)
    return wm, wc, math.sqrt(n + lam)


@njit(cache=True, error_model="numpy", inline="always")
def draw_sigmas(s: F64, P: F64, n: int, gamma: float, L: F64, sig: F64) -> bool:
    """Sigma points ``s``, ``s +/- gamma * L[:, j]`` (``L L^T = P``) into ``sig`` (2n+1, n)."""
    if not cholesky(P, n, L):
        return False
    for c in range(n):
        sig[0, c] = s[c]
    for j in range(n):
        for c in range(n):
            d = gamma * L[c, j]
            sig[1 + j, c] = s[c] + d
            sig[1 + n + j, c] = s[c] - d
    return True


@njit(cache=True, error_model="numpy", inline="always")
def unscented_mean_cov(sig: F64, wm: F64, wc: F64, n_out: int, mean: F64, cov: F64) -> None:
    """Weighted mean and covariance of the rows of ``sig[:, :n_out]``."""
    ns = sig.shape[0]
    for c in range(n_out):
        a = 0.0
        for j in range(ns):
            a += wm[j] * sig[j, c]
        mean[c] = a
    for r in range(n_out):
        for c in range(r, n_out):
            a = 0.0
            for j in range(ns):
                a += wc[j] * (sig[j, r] - mean[r]) * (sig[j, c] - mean[c])
            cov[r, c] = a
            cov[c, r] = a


@njit(cache=True, error_model="numpy", inline="always")
def cross_cov(sig: F64, s: F64, Z: F64, zp: F64, wc: F64, n: int, m: int, Pxz: F64) -> None:
    """``Pxz = sum_j wc_j (sig_j - s)(Z_j - zp)^T`` into ``Pxz[:n, :m]``."""
    for r in range(n):
        for c in range(m):
            a = 0.0
            for j in range(sig.shape[0]):
                a += wc[j] * (sig[j, r] - s[r]) * (Z[j, c] - zp[c])
            Pxz[r, c] = a
