"""The vehicle models of paper 003: Jacobians against finite differences, limits, wrapping."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from navreplay.pipeline.estimation.vehicle import model as vm
from navreplay.pipeline.estimation.vehicle.replay import virtual_steering
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


def central_difference(fn: Callable[[np.ndarray], Any], x: np.ndarray, eps: np.ndarray
                       ) -> np.ndarray:  # fmt: skip
    """``d fn / d x`` by central differences with steps ``eps``, one column per element of
    ``x`` (a row for a scalar ``fn``)."""
    cols = []
    for j in range(x.size):
        xp, xm = x.copy(), x.copy()
        xp[j] += eps[j]
        xm[j] -= eps[j]
        cols.append((np.asarray(fn(xp)) - np.asarray(fn(xm))) / (2 * eps[j]))
    return np.stack(cols, axis=-1)


def stepped(model: int, x: np.ndarray, v_whl: float, delta: float) -> np.ndarray:
    """``vehicle.model.step`` over 0.02 s as a function."""
    out = np.empty(5)
    vm.step(model, x, v_whl, delta, 0.02, VP, out)
    return out


@pytest.mark.parametrize("wrt", ["state", "input"])
@pytest.mark.parametrize("model", [vm.KINEMATIC, vm.DYNAMIC])
@pytest.mark.parametrize(("x", "v_whl", "delta"), STATES)
def test_step_jacobians_match_finite_differences(
    wrt: str, model: int, x: np.ndarray, v_whl: float, delta: float
) -> None:
    """``step_jac`` (d step / dx) and ``input_jac`` (d step / d(v_whl, delta))."""
    if wrt == "state":
        J = np.empty((5, 5))
        vm.step_jac(model, x, v_whl, delta, 0.02, VP, J)
        num = central_difference(lambda xx: stepped(model, xx, v_whl, delta), x, EPS)
        rtol, atol = 1e-6, 1e-8
    else:
        J = np.empty((5, 2))
        vm.input_jac(model, x, v_whl, delta, 0.02, VP, J)
        u, h = np.array([v_whl, delta]), np.array([1e-5, 1e-7])
        num = central_difference(lambda uu: stepped(model, x, uu[0], uu[1]), u, h)
        rtol, atol = 1e-5, 2e-8
    np.testing.assert_allclose(J, num, rtol=rtol, atol=atol)


@pytest.mark.parametrize("model", [vm.KINEMATIC, vm.DYNAMIC])
@pytest.mark.parametrize("kind", [vm.Z_SPEED, vm.Z_YAW_RATE, vm.Z_COURSE, vm.Z_N, vm.Z_E])
def test_measurement_jacobians_match_finite_differences(model: int, kind: int) -> None:
    x, _, delta = STATES[1]
    row = np.empty(5)
    vm.measure_jac(model, x, delta, kind, VP, row)
    num = central_difference(lambda xx: vm.measure(model, xx, delta, kind, VP), x, EPS)
    np.testing.assert_allclose(row, num, rtol=1e-6, atol=1e-9)


def settled(v: float, delta: float, n: int) -> np.ndarray:
    """The dynamic model's state after ``n`` steps of 0.01 s at wheel speed ``v`` and
    steering ``delta``, from straight ahead at that speed."""
    x = np.array([v, 0.0, 0.0, 0.0, 0.0])
    out = np.empty(5)
    for _ in range(n):
        vm.step(vm.DYNAMIC, x, v, delta, 0.01, VP, out)
        x = out.copy()
    return x


def test_dynamic_model_tends_to_the_kinematic_one_at_walking_pace() -> None:
    """Small steering at 0.5 m/s: same steady sideslip and yaw rate (l_r delta / L, v delta / L)."""
    delta, v = 0.02, 0.5
    x = settled(v, delta, 500)
    wheelbase = VP[0] + VP[1]
    assert x[vm.X_BETA] == pytest.approx(VP[1] * delta / wheelbase, rel=2e-3)
    assert vm.yaw_rate(vm.DYNAMIC, x, delta, VP) == pytest.approx(v * delta / wheelbase, rel=2e-3)


def test_dynamic_model_understeers_and_reverses_the_sideslip_at_speed() -> None:
    """At 30 m/s the steady yaw rate is u delta / (L + K u^2) and the sideslip is negative."""
    delta, v = 0.01, 30.0
    x = settled(v, delta, 1000)
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
        x = settled(v[k], d_dyn[k], 2000)
        assert vm.yaw_rate(vm.DYNAMIC, x, d_dyn[k], VP) == pytest.approx(r[k], rel=1e-6)


@pytest.mark.parametrize(
    ("a", "wrapped"),
    [(0.0, 0.0), (math.pi, math.pi), (-math.pi, math.pi), (7.0, 7.0 - 2 * math.pi)],
)
def test_course_residual_wraps_to_half_open_interval(a: float, wrapped: float) -> None:
    assert vm.wrap_angle(a) == pytest.approx(wrapped)
    assert vm.residual(vm.Z_COURSE, 3.1, -3.1) == pytest.approx(6.2 - 2 * math.pi)
    assert vm.residual(vm.Z_N, 3.1, -3.1) == pytest.approx(6.2)
