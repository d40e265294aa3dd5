"""The three estimators on the cascade's models: UKF = EKF where linear, the unscented
second-order term where not, the hybrid's split, gating and the timeout reset."""

from __future__ import annotations

import math

import numpy as np
import pytest

from navreplay.pipeline.estimation.cascaded.cascade import NAV_BLOCK_OF_ROW, NAV_STREAMS, S_GPS_POS
from navreplay.pipeline.estimation.cascaded.filters import (
    EST_EKF,
    EST_UKF,
    Filter,
    Gating,
    Measurement,
    Step,
    Unscented,
    apply_update,
    ekf_predict,
    prepare_update,
    ukf_predict,
)
from navreplay.pipeline.estimation.cascaded.model import (
    MODEL_CTL,
    MODEL_NAV,
    NAV_E,
    NAV_N,
    NAV_PSI,
    NAV_RB,
    NX,
    ctl_discretize,
    model_f,
    model_params,
)
from navreplay.pipeline.estimation.core import gating as gt
from navreplay.pipeline.estimation.core import runlog as rl
from navreplay.pipeline.estimation.core.runlog import RunLog
from navreplay.pipeline.estimation.core.unscented import ukf_weights

UT = Unscented(*ukf_weights(NX, 1e-3, 2.0, 0.0))
GATE = np.array([math.inf, 15.13, 18.42, 21.11])  # chi2(0.9999) by dimension
PAR = model_params(6.4, 0.35, 1.0, 1.0, 0.1053)
DISC = ctl_discretize(PAR, 0.02)
NONE = np.zeros(NX, np.int64)


def random_cov(rng: np.random.Generator, scale: np.ndarray) -> np.ndarray:
    A = rng.normal(size=(NX, NX)) * scale[:, None]
    P: np.ndarray = A @ A.T / NX + np.diag(scale**2) * 0.1
    return P


class Logs:
    def __init__(self, n: int = 64) -> None:
        self.inn_i = np.zeros((n, rl.INN_I_COLS), np.int64)
        self.inn_f = np.zeros((n, rl.INN_F_COLS))
        self.ev_i = np.zeros((n, 4), np.int64)
        self.ev_f = np.zeros(n)
        self.counts = np.zeros(rl.CNT_DIM, np.int64)
        self.reject_since = -np.ones(5, np.int64)
        none = np.zeros(0, np.int64)
        self.log = RunLog(none, np.zeros((0, 2 * NX)), np.zeros((0, 2, NX, NX)), self.inn_i,
                          self.inn_f, self.ev_i, self.ev_f, self.counts)  # fmt: skip

    def kinds(self) -> list[int]:
        return [int(k) for k in self.ev_i[: self.counts[rl.CNT_EV], 1]]


def update(model: int, est: int, t_ns: int, x: np.ndarray, P: np.ndarray, z: np.ndarray,
           r: np.ndarray, logs: Logs, timeout_s: float = 1.0) -> None:  # fmt: skip
    """``prepare_update`` then ``apply_update``, as ``cascade_sample`` does."""
    rows, streams = (NAV_BLOCK_OF_ROW, NAV_STREAMS) if model == MODEL_NAV else (
        np.array([0, 1, 2]), np.array([2, 3, 4]))  # fmt: skip
    f = Filter(model, est, x, P)
    meas, gating = Measurement(z, r, rows, streams), Gating(GATE, timeout_s, logs.reject_since)
    ur, acc, ma = prepare_update(t_ns, f, meas, gating, UT, logs.log)
    assert ma >= 0
    apply_update(f, ur, acc, ma)


def nav_update(est: int, t_ns: int, x: np.ndarray, P: np.ndarray, z: np.ndarray,
               logs: Logs) -> None:  # fmt: skip
    update(MODEL_NAV, est, t_ns, x, P, z, np.array([9e-4, 9e-4, 1.745e-3]), logs)


def test_ukf_equals_ekf_on_the_linear_control_filter() -> None:
    rng = np.random.default_rng(2)
    P0 = random_cov(rng, np.array([0.3, 1.0, 0.5, 0.2, 0.5, 0.1]))
    x0 = rng.normal(size=NX)
    disc = DISC
    Q = np.diag([0.1, 0.1, 0.01, 0.01, 0.01, 1e-3])
    xs, Ps = [x0.copy(), x0.copy()], [P0.copy(), P0.copy()]
    step = Step(np.array([0.4]), 0.02, PAR, disc, Q)
    ekf_predict(Filter(MODEL_CTL, EST_EKF, xs[0], Ps[0]), step)
    assert ukf_predict(Filter(MODEL_CTL, EST_UKF, xs[1], Ps[1]), step, UT, NONE)
    np.testing.assert_allclose(xs[1], xs[0], rtol=0, atol=1e-9)
    np.testing.assert_allclose(Ps[1], Ps[0], rtol=1e-6, atol=1e-9)
    z = xs[0][[0, 2, 3]] + np.array([0.01, -0.05, 0.02])
    z[2] += xs[0][5]
    r = np.array([6e-5, 1.4e-2, 1.5e-3])
    for i, est in enumerate((EST_EKF, EST_UKF)):
        update(MODEL_CTL, est, 0, xs[i], Ps[i], z, r, Logs())
    np.testing.assert_allclose(xs[1], xs[0], rtol=0, atol=1e-8)
    np.testing.assert_allclose(Ps[1], Ps[0], rtol=1e-6, atol=1e-10)


def test_unscented_mean_adds_the_second_order_term_to_the_navigation_step() -> None:
    """With alpha = 1e-3 the unscented mean is ``f(x) + 1/2 tr(f'' P)``: the North step
    shrinks by ``dt/2 (V - r_b) cos(psi) P_psipsi`` (the mechanism behind the UKF's radar-bias
    offset and outage drift in the experiment)."""
    x = np.array([10.0, 100.0, 0.3, 0.1, 0.2, 0.05])
    u = np.array([3.4, 0.25])
    P = np.diag([0.1, 0.1, 0.01, 0.16, 0.001, 0.15])
    P[NAV_PSI, NAV_RB] = P[NAV_RB, NAV_PSI] = 0.004
    dt = 0.02
    f = np.empty(NX)
    model_f(MODEL_NAV, x, u, dt, PAR, DISC, f)
    xu, Pu = x.copy(), P.copy()
    step = Step(u, dt, PAR, DISC, np.zeros((NX, NX)))
    assert ukf_predict(Filter(MODEL_NAV, EST_UKF, xu, Pu), step, UT, NONE)
    v, psi = u[0] - x[NAV_RB], x[NAV_PSI]
    second_n = -0.5 * dt * v * math.cos(psi) * P[3, 3] + dt * math.sin(psi) * P[3, 2]
    second_e = -0.5 * dt * v * math.sin(psi) * P[3, 3] - dt * math.cos(psi) * P[3, 2]
    assert xu[NAV_N] - f[NAV_N] == pytest.approx(second_n, rel=1e-4)
    assert xu[NAV_E] - f[NAV_E] == pytest.approx(second_e, rel=1e-4)
    np.testing.assert_allclose(xu[2:], f[2:], atol=1e-12)


def test_hybrid_takes_the_ekf_mean_for_east_north_and_the_unscented_covariance() -> None:
    x = np.array([10.0, 100.0, 0.3, 0.1, 0.2, 0.05])
    u = np.array([3.4, 0.25])
    P = random_cov(np.random.default_rng(4), np.array([0.3, 0.3, 0.1, 0.4, 0.03, 0.4]))
    Q = np.diag([0.1, 0.1, 1e-3, 0.01, 1e-3, 1e-3])
    f = np.empty(NX)
    model_f(MODEL_NAV, x, u, 0.02, PAR, DISC, f)
    xu, Pu, xh, Ph = x.copy(), P.copy(), x.copy(), P.copy()
    mask = np.array([1, 1, 0, 0, 0, 0], np.int64)
    step = Step(u, 0.02, PAR, DISC, Q)
    ukf_predict(Filter(MODEL_NAV, EST_UKF, xu, Pu), step, UT, NONE)
    ukf_predict(Filter(MODEL_NAV, EST_UKF, xh, Ph), step, UT, mask)
    np.testing.assert_array_equal(xh[:2], f[:2])
    assert abs(xu[NAV_N] - f[NAV_N]) > 1e-5  # the unscented mean differs there
    np.testing.assert_allclose(xh[2:], xu[2:], atol=1e-12)
    np.testing.assert_array_equal(Ph, Pu)


@pytest.mark.parametrize("est", [EST_EKF, EST_UKF])
def test_an_outlier_is_rejected_and_a_persistent_step_is_followed_after_the_timeout(
    est: int,
) -> None:
    x = np.zeros(NX)
    P = np.diag([9e-4, 9e-4, 1e-3, 1e-3, 1e-3, 1e-3])
    logs = Logs()
    jump = np.array([5.0, 0.0, math.nan])  # 5 m jump, heading not available
    nav_update(est, 0, x, P, jump, logs)
    assert x[NAV_E] == 0.0  # rejected, nothing applied
    assert logs.kinds() == [gt.EV_REJECT]
    for k in range(1, 6):  # the same 5 m offset for 1.0 s at 5 Hz: rejected until the timeout
        nav_update(est, k * 200_000_000, x, P, jump, logs)
    assert gt.EV_RESET in logs.kinds()
    assert x[NAV_E] == pytest.approx(5.0, abs=0.05)  # followed once reset
    i = logs.inn_i[: logs.counts[rl.CNT_INN]]
    assert (i[:, 1] == S_GPS_POS).all()
    assert i[-1, 4] == 1
    assert (i[:-1, 4] == 0).all()
