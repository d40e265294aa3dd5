"""Paper 000's straight-line LQR (eq. 8-14): discretization, gain, closed loop."""

from __future__ import annotations

import math

import numpy as np
import pytest

from navreplay.pipeline.control.lqr import (
    PAPER_Q_C,
    PAPER_R_C,
    StraightLine,
    YawSteerModel,
    discretize,
    dlqr,
    lateral_model,
    lqr_command,
    tractor_lqr_gain,
)

TS = 0.02


def closed_loop(speed: float = 3.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    a, b = lateral_model(speed, YawSteerModel())
    a_d, b_d = discretize(a, b, TS)
    k = tractor_lqr_gain(speed, TS)
    return a_d, b_d, k


def test_block_exponential_discretization_matches_the_closed_form_for_a_first_order_lag() -> None:
    a, b, dt = -1.0 / 0.1053, 2.5, 0.02
    a_d, b_d = discretize(np.array([[a]]), np.array([[b]]), dt)
    assert a_d[0, 0] == pytest.approx(math.exp(a * dt), rel=1e-14)
    assert b_d[0, 0] == pytest.approx((math.exp(a * dt) - 1.0) / a * b, rel=1e-13)


def test_discretization_of_a_double_integrator_is_exact() -> None:
    a = np.array([[0.0, 1.0], [0.0, 0.0]])
    b = np.array([[0.0], [1.0]])
    a_d, b_d = discretize(a, b, 0.5)
    np.testing.assert_allclose(a_d, [[1.0, 0.5], [0.0, 1.0]], atol=1e-15)
    np.testing.assert_allclose(b_d, [[0.125], [0.5]], atol=1e-15)


@pytest.mark.parametrize("speed", [1.0, 3.0, 6.0])
def test_gain_from_the_discretized_model_puts_every_closed_loop_eigenvalue_inside_the_unit_circle(
    speed: float,
) -> None:
    a_d, b_d, k = closed_loop(speed)
    radius = np.abs(np.linalg.eigvals(a_d - b_d @ k[None, :])).max()
    assert radius < 0.99  # 0.977 at 3 m/s: the slowest mode decays with ~0.9 s time constant
    # the open loop has integrators (lateral error, heading, steer angle) on the unit circle
    assert np.abs(np.linalg.eigvals(a_d)).max() == pytest.approx(1.0, abs=1e-12)


def quadratic_cost(a_d: np.ndarray, b_d: np.ndarray, k: np.ndarray, x0: np.ndarray) -> float:
    q = np.diag(PAPER_Q_C)
    x, cost = x0.copy(), 0.0
    for _ in range(6000):
        u = -(k @ x)
        cost += x @ q @ x + PAPER_R_C * u * u
        x = a_d @ x + b_d[:, 0] * u
    return float(cost)


def test_gain_minimizes_the_cost_of_eq_13_against_perturbed_gains() -> None:
    a_d, b_d, k = closed_loop()
    x0 = np.array([-3.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    best = quadratic_cost(a_d, b_d, k, x0)
    rng = np.random.default_rng(0)
    for _ in range(5):
        other = k * (1.0 + 0.05 * rng.standard_normal(6))
        if np.abs(np.linalg.eigvals(a_d - b_d @ other[None, :])).max() < 1.0:
            assert quadratic_cost(a_d, b_d, other, x0) > best


def test_dlqr_refuses_an_unstabilizable_pair() -> None:
    a_d = np.diag([1.1, 0.5])
    b_d = np.array([[0.0], [1.0]])  # the unstable mode is not reachable
    with pytest.raises(ValueError, match="stabilizing"):
        dlqr(a_d, b_d, np.eye(2), np.array([[1.0]]))


def test_the_linear_closed_loop_brings_a_3_m_step_back_to_the_line() -> None:
    a_d, b_d, k = closed_loop()
    x = np.array([-3.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    for _ in range(round(10.0 / TS)):
        x = a_d @ x + b_d[:, 0] * lqr_command(k, x)
    assert abs(x[0]) < 1e-4


def test_lateral_error_and_heading_error_signs() -> None:
    north_line = StraightLine(3.0, 0.0, 0.0)
    assert north_line.lateral_error(0.0, 50.0) == pytest.approx(-3.0)  # left of the line
    east_line = StraightLine(0.0, 0.0, math.pi / 2)
    assert east_line.lateral_error(10.0, -2.0) == pytest.approx(2.0)  # right of an eastward line
    xc = north_line.control_state(0.0, 0.0, 2 * math.pi - 0.1, 0.1, 0.2, 0.3, 0.4)
    np.testing.assert_allclose(xc, [-3.0, -0.1, 0.1, 0.2, 0.3, 0.4], atol=1e-12)
