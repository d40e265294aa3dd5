"""Paper 000's cascaded models: Jacobians against finite differences, eq. 14, the noise."""

from __future__ import annotations

import math

import numpy as np
import pytest

from navreplay.pipeline.control.lqr import YawSteerModel
from navreplay.pipeline.estimation.cascaded.model import (
    CTL_DEL,
    CTL_PD,
    MODEL_CTL,
    MODEL_NAV,
    NAV_PSI,
    NX,
    ctl_continuous,
    ctl_discretize,
    model_f,
    model_h,
    model_jacobian,
    model_meas_jacobian,
    model_noise,
    model_params,
)

TABLE3 = YawSteerModel()


def par(*, desired: bool = False, psi_d: float = 0.0) -> np.ndarray:
    m = TABLE3
    return model_params(m.omega_n_radps, m.zeta, m.k_r, m.k_v, m.tau_v_s,
                        jacobian_at_desired=desired, desired_heading_rad=psi_d)  # fmt: skip


def fd_jacobian(model: int, x: np.ndarray, u: np.ndarray, dt: float, p: np.ndarray,
                disc: np.ndarray, h: float = 1e-6) -> np.ndarray:  # fmt: skip
    J = np.empty((NX, NX))
    for j in range(NX):
        xp, xm = x.copy(), x.copy()
        xp[j] += h
        xm[j] -= h
        fp, fm = np.empty(NX), np.empty(NX)
        model_f(model, xp, u, dt, p, disc, fp)
        model_f(model, xm, u, dt, p, disc, fm)
        J[:, j] = (fp - fm) / (2 * h)
    return J


@pytest.mark.parametrize("seed", range(5))
def test_navigation_jacobian_matches_finite_differences_at_the_estimate(seed: int) -> None:
    rng = np.random.default_rng(seed)
    x = rng.normal(size=NX) * np.array([50, 50, 0.5, 2.0, 0.3, 0.3])
    u = np.array([3.0 + rng.normal(), rng.normal(scale=0.3)])
    p, disc, dt = par(), ctl_discretize(par(), 0.02), 0.02
    F = np.empty((NX, NX))
    model_jacobian(MODEL_NAV, x, u, dt, p, disc, F)
    np.testing.assert_allclose(F, fd_jacobian(MODEL_NAV, x, u, dt, p, disc), rtol=1e-6, atol=1e-8)


def test_papers_linearization_is_the_jacobian_at_the_desired_heading() -> None:
    """``jacobian_at: desired_heading`` (eq. 17 as printed, row 2's sign corrected) equals the
    true Jacobian where the heading equals psi_d, and differs away from it."""
    psi_d = 0.3
    x = np.array([1.0, 2.0, 0.4, psi_d, 0.3, 0.2])
    u = np.array([3.4, 0.1])
    disc, dt = ctl_discretize(par(), 0.02), 0.02
    F_paper, F_est = np.empty((NX, NX)), np.empty((NX, NX))
    model_jacobian(MODEL_NAV, x, u, dt, par(desired=True, psi_d=psi_d), disc, F_paper)
    np.testing.assert_allclose(F_paper, fd_jacobian(MODEL_NAV, x, u, dt, par(), disc), atol=1e-9)
    x[NAV_PSI] = psi_d + 0.5
    model_jacobian(MODEL_NAV, x, u, dt, par(desired=True, psi_d=psi_d), disc, F_paper)
    model_jacobian(MODEL_NAV, x, u, dt, par(), disc, F_est)
    assert np.abs(F_paper - F_est).max() > 1e-3


def test_control_jacobian_matches_finite_differences_and_is_the_transition() -> None:
    rng = np.random.default_rng(3)
    x, u, p, dt = rng.normal(size=NX), np.array([0.7]), par(), 0.02
    disc = ctl_discretize(p, dt)
    F = np.empty((NX, NX))
    model_jacobian(MODEL_CTL, x, u, dt, p, disc, F)
    np.testing.assert_allclose(F, fd_jacobian(MODEL_CTL, x, u, dt, p, disc), atol=1e-8)


@pytest.mark.parametrize("model", [MODEL_NAV, MODEL_CTL])
def test_measurement_jacobians_match_finite_differences(model: int) -> None:
    x = np.random.default_rng(1).normal(size=NX)
    H = np.empty((3, NX))
    model_meas_jacobian(model, H)
    fd = np.empty((3, NX))
    for j in range(NX):
        xp, xm, hp, hm = x.copy(), x.copy(), np.empty(3), np.empty(3)
        xp[j] += 1e-6
        xm[j] -= 1e-6
        model_h(model, xp, hp)
        model_h(model, xm, hm)
        fd[:, j] = (hp - hm) / 2e-6
    np.testing.assert_allclose(H, fd, atol=1e-9)


@pytest.mark.parametrize("dt", [0.02, 0.013, 0.5])
def test_control_discretization_is_the_exact_zero_order_hold_of_eq_19(dt: float) -> None:
    """eq. 14's (Phi, Gamma) integrate ``x_dot = J2 x + B2 u`` exactly over ``dt`` with ``u``
    held: compare with a fine RK4 integration."""
    p = par()
    disc = ctl_discretize(p, dt)
    A, B = np.empty((NX, NX)), np.empty(NX)
    ctl_continuous(p, A, B)
    x0, u = np.array([0.1, -0.2, 3.0, 0.05, 0.3, 0.1]), 0.7
    x, n = x0.copy(), 20000
    h = dt / n
    for _ in range(n):
        k1 = A @ x + B * u
        k2 = A @ (x + h / 2 * k1) + B * u
        k3 = A @ (x + h / 2 * k2) + B * u
        k4 = A @ (x + h * k3) + B * u
        x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    out = np.empty(NX)
    model_f(MODEL_CTL, x0, np.array([u]), dt, p, disc, out)
    np.testing.assert_allclose(out, x, rtol=0, atol=1e-12)


def test_a_constant_steer_angle_gives_k_r_times_it_as_yaw_rate() -> None:
    """J2 reads eq. 3 with K_R w_n^2 (the paper prints K_R w_n): DC gain K_R (Table 3)."""
    p = par()
    disc = ctl_discretize(p, 0.02)
    x = np.zeros(NX)
    x[CTL_DEL] = 0.1
    out = np.empty(NX)
    for _ in range(2000):
        model_f(MODEL_CTL, x, np.zeros(1), 0.02, p, disc, out)
        x = out.copy()
    assert x[CTL_PD] == pytest.approx(TABLE3.k_r * 0.1, rel=1e-9)


def test_euler_step_moves_along_the_heading_with_the_corrected_speed() -> None:
    x = np.array([0.0, 0.0, 0.4, math.pi / 6, 0.3, 0.2])
    out = np.empty(NX)
    model_f(MODEL_NAV, x, np.array([3.4, 0.35]), 0.02, par(), ctl_discretize(par(), 0.02), out)
    np.testing.assert_allclose(out[:2], 0.02 * 3.0 * np.array([0.5, math.sqrt(3) / 2]))
    assert out[NAV_PSI] == pytest.approx(math.pi / 6 + 0.02 * 0.05)


def test_process_noise_scales_table_1_with_the_step() -> None:
    q = np.arange(1.0, 7.0)
    Q = np.empty((NX, NX))
    model_noise(q, 0.02, 0.02, Q)
    np.testing.assert_array_equal(Q, np.diag(q))
    model_noise(q, 0.01, 0.02, Q)
    np.testing.assert_allclose(Q, np.diag(q / 2))
