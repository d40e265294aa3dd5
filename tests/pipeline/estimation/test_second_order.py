"""The term the linearised velocity error leaves out (attitude error x accelerometer-bias
error, ``ins_errors.second_order_noise``): its variance is the product's, and with it the
declared consumer IMU of the robustness sweep is no longer confidently wrong (issue 22)."""

from __future__ import annotations

import dataclasses
import functools
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from navreplay.ingest.meta import SensorMeta
from navreplay.pipeline.estimation.ins.metrics import compute_metrics
from navreplay.pipeline.estimation.ins.models import ins
from navreplay.pipeline.estimation.ins.models import ins_errors as ie
from navreplay.pipeline.estimation.ins.replay import run_filter
from navreplay.pipeline.experiments.drives import Tables, filter_params
from navreplay.pipeline.experiments.robustness import grid as gr
from navreplay.pipeline.params import load_params

REPO = Path(__file__).resolve().parents[3]


def _span(C: np.ndarray, T: float = 0.1) -> np.ndarray:
    acc = np.zeros(ins.ACC_DIM)
    acc[ins.ACC_C : ins.ACC_C + 9] = (C * T).ravel()
    acc[ins.ACC_T] = T
    return acc


def _noise(tau: float) -> np.ndarray:
    return ie.noise_vector(1e-3, 1e-4, 1e-4, 1e-5, 0.0, 0.0, 0.0, 0.0, second_order_corr_s=tau)


def test_the_noise_is_the_variance_of_the_product_under_the_filters_gaussian() -> None:
    """Against psi x (C db) sampled from a covariance whose attitude and bias errors are
    strongly correlated (as levelling leaves them): per axis within 3 % of 400 000 draws."""
    rng = np.random.default_rng(7)
    n = ins.N_LOOSE
    M = rng.normal(size=(n, n)) * 0.02
    P = M @ M.T + np.diag(np.r_[np.ones(6), np.full(3, 0.03**2), np.full(3, 0.4**2), np.ones(3)])
    P[ins.E_ATT, ins.E_BA + 1] = P[ins.E_BA + 1, ins.E_ATT] = 0.9 * 0.03 * 0.4  # roll ~ b_y / g
    C = Rotation.from_euler("zyx", [0.7, 0.05, -0.08]).as_matrix()
    acc, tau = _span(C), 3.0
    ie.second_order_noise(P, acc, _noise(tau))
    got = acc[ins.ACC_SO : ins.ACC_SO + 3] / (2.0 * tau)
    idx = np.r_[ins.E_ATT : ins.E_ATT + 3, ins.E_BA : ins.E_BA + 3]
    draws = rng.multivariate_normal(np.zeros(6), P[np.ix_(idx, idx)], size=400_000)
    e = np.cross(draws[:, :3], draws[:, 3:] @ C.T)
    np.testing.assert_allclose(got, e.var(axis=0), rtol=0.03)


def test_no_noise_without_a_correlation_time_or_a_bias_uncertainty() -> None:
    P = np.eye(ins.N_LOOSE) * 0.01
    acc = _span(np.eye(3))
    ie.second_order_noise(P, acc, _noise(0.0))
    assert not acc[ins.ACC_SO : ins.ACC_SO + 3].any()
    P[ins.E_BA : ins.E_BA + 3, :] = P[:, ins.E_BA : ins.E_BA + 3] = 0.0
    ie.second_order_noise(P, acc, _noise(3.0))
    assert not acc[ins.ACC_SO : ins.ACC_SO + 3].any()


@functools.cache
def _declared_consumer() -> tuple[gr.SweepParams, Tables, SensorMeta]:
    p = load_params(REPO / "params.yaml")
    params = gr.SweepParams.of(p.synth.seoul_campus, p.synth.car_drives, p.filters)
    cell = gr.Cell("consumer", 0.0, True, declared=True)
    tables, sensors = gr.prepare(*gr.simulate(params, cell, 2), cell)
    return params, tables, sensors


@pytest.mark.parametrize("name", ["lc_ekf", "tc_ukf"])
def test_the_declared_consumer_imu_is_consistent_with_the_term_and_not_without(
    name: str,
) -> None:
    """The sweep's declared consumer cell, seed 2 (0.5 m/s^2 turn-on biases on every axis,
    1 sigma of the declared model): NEES 8 (lc_ekf) and 18 (tc_ukf) x dof without the term,
    within [0.5, 2] with params.yaml's correlation time; the horizontal error no larger."""
    params, tables, sensors = _declared_consumer()
    section = filter_params(params.filters, name)
    assert section.step.second_order_corr_s > 0.0
    without = dataclasses.replace(
        section, step=dataclasses.replace(section.step, second_order_corr_s=0.0)
    )
    out = {}
    for label, sec in (("with", section), ("without", without)):
        m = compute_metrics(run_filter(tables, sensors, name, sec), tables["truth"])
        out[label] = (m["nees_mean"] / m["nees_dof"], m["pos_err_h_rms_m"])
    assert out["without"][0] > 4.0
    assert 0.5 <= out["with"][0] <= 2.0
    assert out["with"][1] <= 1.05 * out["without"][1]
