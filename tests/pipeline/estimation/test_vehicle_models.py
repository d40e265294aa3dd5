"""The vehicle models of paper 003: Jacobians against finite differences, limits, wrapping."""

from __future__ import annotations

import math

import numpy as np
import pytest

from navreplay.pipeline.estimation.models import vehicle as vm
from navreplay.pipeline.estimation.vehicle_replay import virtual_steering
from navreplay.pipeline.synth.bicycle import VehicleParams

_V = VehicleParams()
VP = np.array([_V.cg_to_front_m, _V.cg_to_rear_m, _V.mass_kg,
               _V.cornering_stiffness_front_npr, _V.cornering_stiffness_rear_npr])  # fmt: skip
STATES = [
    (np.array([1.5, 0.2, 0.3, 10.0, -4.0]), 1.5, 0.4),
    (np.array([12.0, -0.02, -2.9, 100.0, 50.0]), 12.1, 0.05),
    (np.array([33.0, 0.01, 4.0, -300.0, 800.0]), 32.9, -0.03),
]
EPS = np.array([1e-5, 1e-7, 1e-7, 1e-4, 1e-4])


@pytest.mark.parametrize("model", [vm.KINEMATIC, vm.DYNAMIC])
@pytest.mark.parametrize(("x", "v_whl", "delta"), STATES)
def test_step_jacobian_matches_finite_differences(
    model: int, x: np.ndarray, v_whl: float, delta: float
) -> None:
    F = np.empty((5, 5))
    vm.step_jac(model, x, v_whl, delta, 0.02, VP, F)
    num = np.empty((5, 5))
    for j in range(5):
        xp, xm = x.copy(), x.copy()
        xp[j] += EPS[j]
        xm[j] -= EPS[j]
        fp, fm = np.empty(5), np.empty(5)
        vm.step(model, xp, v_whl, delta, 0.02, VP, fp)
        vm.step(model, xm, v_whl, delta, 0.02, VP, fm)
        num[:, j] = (fp - fm) / (2 * EPS[j])
    np.testing.assert_allclose(F, num, rtol=1e-6, atol=1e-8)


@pytest.mark.parametrize("model", [vm.KINEMATIC, vm.DYNAMIC])
@pytest.mark.parametrize(("x", "v_whl", "delta"), STATES)
def test_input_jacobian_matches_finite_differences(
    model: int, x: np.ndarray, v_whl: float, delta: float
) -> None:
    G = np.empty((5, 2))
    vm.input_jac(model, x, v_whl, delta, 0.02, VP, G)
    num = np.empty((5, 2))
    for j, h in enumerate((1e-5, 1e-7)):
        u = np.array([v_whl, delta])
        outs = []
        for sgn in (1.0, -1.0):
            uu = u.copy()
            uu[j] += sgn * h
            f = np.empty(5)
            vm.step(model, x, uu[0], uu[1], 0.02, VP, f)
            outs.append(f)
        num[:, j] = (outs[0] - outs[1]) / (2 * h)
    np.testing.assert_allclose(G, num, rtol=1e-5, atol=2e-8)


@pytest.mark.parametrize("model", [vm.KINEMATIC, vm.DYNAMIC])
@pytest.mark.parametrize("kind", [vm.Z_SPEED, vm.Z_YAW_RATE, vm.Z_COURSE, vm.Z_N, vm.Z_E])
def test_measurement_jacobians_match_finite_differences(model: int, kind: int) -> None:
    x, _, delta = STATES[1]
    row = np.empty(5)
    vm.measure_jac(model, x, delta, kind, VP, row)
    num = np.empty(5)
    for j in range(5):
        xp, xm = x.copy(), x.copy()
        xp[j] += EPS[j]
        xm[j] -= EPS[j]
        num[j] = (
            vm.measure(model, xp, delta, kind, VP) - vm.measure(model, xm, delta, kind, VP)
        ) / (2 * EPS[j])
    np.testing.assert_allclose(row, num, rtol=1e-6, atol=1e-9)


def test_dynamic_model_tends_to_the_kinematic_one_at_walking_pace() -> None:
    """Small steering at 0.5 m/s: same steady sideslip and yaw rate (l_r delta / L, v delta / L)."""
    delta, v = 0.02, 0.5
    x = np.array([v, 0.0, 0.0, 0.0, 0.0])
    out = np.empty(5)
    for _ in range(500):
        vm.step(vm.DYNAMIC, x, v, delta, 0.01, VP, out)
        x = out.copy()
    wheelbase = VP[0] + VP[1]
    assert x[vm.X_BETA] == pytest.approx(VP[1] * delta / wheelbase, rel=2e-3)
    assert vm.yaw_rate(vm.DYNAMIC, x, delta, VP) == pytest.approx(v * delta / wheelbase, rel=2e-3)


def test_dynamic_model_understeers_and_reverses_the_sideslip_at_speed() -> None:
    """At 30 m/s the steady yaw rate is u delta / (L + K u^2) and the sideslip is negative."""
    delta, v = 0.01, 30.0
    x = np.array([v, 0.0, 0.0, 0.0, 0.0])
    out = np.empty(5)
    for _ in range(1000):
        vm.step(vm.DYNAMIC, x, v, delta, 0.01, VP, out)
        x = out.copy()
    expected = _V.steady_state_yaw_rate(v, delta)
    assert vm.yaw_rate(vm.DYNAMIC, x, delta, VP) == pytest.approx(expected, rel=1e-3)
    assert x[vm.X_BETA] < 0.0


def test_virtual_steering_reproduces_the_measured_yaw_rate_in_each_model() -> None:
    v, r = np.array([3.0, 15.0]), np.array([0.2, 0.1])
    d_kin, d_dyn = virtual_steering(v, r, VP)
    for k in range(2):
        xk = np.zeros(5)
        vm.step(vm.KINEMATIC, np.array([v[k], 0, 0, 0, 0.0]), v[k], d_kin[k], 0.01, VP, xk)
        assert vm.yaw_rate(vm.KINEMATIC, xk, d_kin[k], VP) == pytest.approx(r[k], rel=1e-9)
        x = np.array([v[k], 0.0, 0.0, 0.0, 0.0])
        out = np.empty(5)
        for _ in range(2000):
            vm.step(vm.DYNAMIC, x, v[k], d_dyn[k], 0.01, VP, out)
            x = out.copy()
        assert vm.yaw_rate(vm.DYNAMIC, x, d_dyn[k], VP) == pytest.approx(r[k], rel=1e-6)


@pytest.mark.parametrize(
    ("a", "wrapped"),
    [(0.0, 0.0), (math.pi, math.pi), (-math.pi, math.pi), (7.0, 7.0 - 2 * math.pi)],
)
def test_course_residual_wraps_to_half_open_interval(a: float, wrapped: float) -> None:
    assert vm.wrap_angle(a) == pytest.approx(wrapped)
    assert vm.residual(vm.Z_COURSE, 3.1, -3.1) == pytest.approx(6.2 - 2 * math.pi)
    assert vm.residual(vm.Z_N, 3.1, -3.1) == pytest.approx(6.2)
