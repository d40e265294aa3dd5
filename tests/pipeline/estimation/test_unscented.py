"""The unscented transform of the UKF kernel: filterpy's weights, and the Kalman filter on a
linear model."""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pytest
from filterpy.kalman import KalmanFilter, MerweScaledSigmaPoints

from navreplay.ingest.meta import SensorMeta
from navreplay.pipeline.estimation.config import FiltersParams
from navreplay.pipeline.estimation.core.linalg import joseph_update
from navreplay.pipeline.estimation.core.unscented import (
    cross_cov,
    draw_sigmas,
    ukf_weights,
    unscented_mean_cov,
)
from navreplay.pipeline.estimation.ins.kernels.ukf import _apply_gain
from navreplay.pipeline.estimation.ins.models import ins
from navreplay.pipeline.estimation.ins.replay import run_filter


@pytest.mark.parametrize(("alpha", "beta", "kappa"), [(0.99, 2.0, 0.0), (1e-3, 2.0, 0.0)])
def test_weights_and_sigma_points_equal_filterpys(alpha: float, beta: float, kappa: float) -> None:
    n = 17
    wm, wc, gamma = ukf_weights(n, alpha, beta, kappa)
    ref = MerweScaledSigmaPoints(n, alpha, beta, kappa)
    np.testing.assert_allclose(wm, ref.Wm, rtol=1e-13)
    np.testing.assert_allclose(wc, ref.Wc, rtol=1e-13)
    rng = np.random.default_rng(3)
    A = rng.normal(size=(n, n))
    P = A @ A.T + n * np.eye(n)
    x = rng.normal(size=n)
    sig = np.empty((2 * n + 1, n))
    assert draw_sigmas(x, P, n, gamma, np.empty((n, n)), sig)
    np.testing.assert_allclose(sig, ref.sigma_points(x, P), rtol=1e-12, atol=1e-12)
    mean, cov = np.empty(n), np.empty((n, n))
    unscented_mean_cov(sig, wm, wc, n, mean, cov)
    np.testing.assert_allclose(mean, x, atol=1e-12)
    np.testing.assert_allclose(cov, P, rtol=1e-10, atol=1e-10)


def test_ukf_equals_the_kalman_filter_on_a_linear_model() -> None:
    """Predict and update through the kernel's unscented primitives equal filterpy's
    KalmanFilter and the EKF kernel's Joseph update when f and h are linear."""
    n, m = 6, 3
    rng = np.random.default_rng(11)
    A = np.eye(n) + 0.1 * rng.normal(size=(n, n))
    H = rng.normal(size=(m, n))
    Q = np.diag(rng.uniform(0.01, 0.1, n))
    R = np.diag(rng.uniform(0.5, 2.0, m))
    x, P = rng.normal(size=n), np.diag(rng.uniform(1.0, 4.0, n))
    wm, wc, gamma = ukf_weights(n, 0.99, 2.0, 0.0)
    kf = KalmanFilter(dim_x=n, dim_z=m)
    kf.x, kf.P, kf.F, kf.Q, kf.H, kf.R = x.copy(), P.copy(), A, Q, H, R
    sig, L = np.empty((2 * n + 1, n)), np.empty((n, n))
    for _ in range(5):
        z = rng.normal(size=m)
        # unscented predict
        assert draw_sigmas(x, P, n, gamma, L, sig)
        sig = sig @ A.T
        unscented_mean_cov(sig, wm, wc, n, x, P)
        P += Q
        # unscented update
        assert draw_sigmas(x, P, n, gamma, L, sig)
        Z = sig @ H.T
        zp, S, Pxz = np.empty(m), np.empty((m, m)), np.empty((n, m))
        unscented_mean_cov(Z, wm, wc, m, zp, S)
        S += R
        cross_cov(sig, x, Z, zp, wc, n, m, Pxz)
        # the EKF kernel's Joseph update on the same prior
        P_ekf = P.copy()
        dx, ok = joseph_update(P_ekf, n, H, S, np.diag(R).copy(), z - zp, np.arange(m), m)
        assert ok
        x_prior = x.copy()
        _apply_gain(x, P, n, Pxz, S, z - zp, np.arange(m), m)
        np.testing.assert_allclose(x - x_prior, dx, rtol=1e-9, atol=1e-10)
        kf.predict()
        kf.update(z)
        np.testing.assert_allclose(x, kf.x, rtol=1e-9, atol=1e-10)
        np.testing.assert_allclose(P, kf.P, rtol=1e-9, atol=1e-10)
        np.testing.assert_allclose(P_ekf, kf.P, rtol=1e-9, atol=1e-10)


def test_ukf_and_ekf_agree_on_the_nearly_linear_land_vehicle_problem(
    filters: FiltersParams, drive60: tuple[dict[str, pa.Table], SensorMeta]
) -> None:
    """Paper 001: 'a small difference between EKF and UKF ... for land navigation'."""
    tables, sensors = drive60
    ekf = run_filter(tables, sensors, "tc_ekf", filters.tc_ekf)
    ukf = run_filter(tables, sensors, "tc_ukf", filters.tc_ukf)
    assert np.array_equal(ekf.t_ns, ukf.t_ns)
    worst = 0.0
    for k in range(ekf.t_ns.size):
        d = ins.difference(ukf.x[k], ekf.x[k], ins.N_TIGHT)
        worst = max(worst, float(np.max(np.abs(d) / np.sqrt(np.diag(ekf.P[k])))))
    assert worst < 0.25
    ratio = np.sqrt(np.diagonal(ukf.P, axis1=1, axis2=2) / np.diagonal(ekf.P, axis1=1, axis2=2))
    assert np.all(np.abs(ratio - 1.0) < 0.05)
