"""The innovation-based adaptive EKF (``iae_ekf``): the estimator, both backends, a receiver
that reports too optimistic an accuracy, and one that reports the truth."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pyarrow as pa
import pytest

from navreplay.ingest.meta import SensorMeta
from navreplay.pipeline.estimation.config import FiltersParams
from navreplay.pipeline.estimation.ins.iae import N_KINDS, IaeParams, iae_scales, push_innovations
from navreplay.pipeline.estimation.ins.metrics import compute_metrics
from navreplay.pipeline.estimation.ins.models import measurement as me
from navreplay.pipeline.estimation.ins.replay import RunResult, run_filter
from navreplay.pipeline.estimation.ins.truth import error_states
from navreplay.pipeline.experiments.fwekf_faults import optimistic_accuracy
from tests.pipeline.estimation.conftest import assert_backends_agree, seoul


def _ring(window: int, epochs: list[tuple[float, float, float]]) -> tuple[np.ndarray, int]:
    """A ring holding ``epochs`` of horizontal position rows (nu, H P H^T, declared r)."""
    ring = np.full((window, 3 * N_KINDS), math.nan)
    rows = np.zeros((2, 2), np.int64)
    rows[1, 0] = me.K_POS + 1
    count = 0
    for nu, hph, r in epochs:
        S = np.diag([hph + r, hph + r])
        count = push_innovations(ring, count, rows, np.array([nu, -nu]), S, np.full(2, r),
                                 np.ones(me.K_PR), 2)  # fmt: skip
    return ring, count


def test_the_estimate_is_the_innovation_variance_less_the_prior_spread() -> None:
    """Mohamed & Schwarz: R^ = mean(nu^2) - H P- H^T, here as a multiple of the declared R."""
    fz = IaeParams(window=4, min_epochs=2).vector()
    ring, count = _ring(4, [(3.0, 1.0, 2.0)] * 4)  # 9 - 1 = 8 = 4 x the declared 2
    scale = np.ones(me.K_PR)
    iae_scales(ring, count, fz, scale)
    assert scale[0] == scale[1] == pytest.approx(4.0)
    np.testing.assert_array_equal(scale[2:], 1.0)  # no vertical or velocity rows: unchanged
    ring, count = _ring(4, [(0.5, 1.0, 2.0)] * 4)  # smaller than the prior spread alone
    iae_scales(ring, count, fz, scale)
    assert scale[0] == pytest.approx(0.25)  # the lower bound, not a negative variance
    few = np.ones(me.K_PR)
    iae_scales(*_ring(4, [(3.0, 1.0, 2.0)]), fz, few)
    np.testing.assert_array_equal(few, 1.0)  # fewer than min_epochs: the declared variances


def test_the_window_forgets_old_epochs() -> None:
    fz = IaeParams(window=3, min_epochs=1).vector()
    ring, count = _ring(3, [(10.0, 0.0, 1.0)] * 3 + [(1.0, 0.0, 1.0)] * 3)
    scale = np.ones(me.K_PR)
    iae_scales(ring, count, fz, scale)
    assert scale[0] == pytest.approx(1.0)


def test_numba_and_filterpy_iae_agree_while_r_adapts(
    filters: FiltersParams, drive60: tuple[dict[str, pa.Table], SensorMeta]
) -> None:
    """Under F8 (5 m errors, 0.5 m reported) the multiplier leaves 1 and both backends still
    give the same states, covariances, gating decisions and multipliers. The fixes are taken
    as white (a minute is too short to learn their correlation, and the configured 30 s
    would inflate the declared variances 61-fold, leaving the IAE little to find)."""
    tables, sensors = drive60
    tables = optimistic_accuracy(tables, np.random.default_rng(5))
    section = filters.get("iae_ekf")
    section = replace(section, gnss=replace(section.gnss, pos_error_corr_time_s=0.0))
    fast = run_filter(tables, sensors, "iae_ekf", section, backend="numba")
    ref = run_filter(tables, sensors, "iae_ekf", section, backend="filterpy")
    assert fast.status == ref.status == "ok"
    scale = fast.extra["r_scale"]
    assert scale.max() > 10.0
    np.testing.assert_allclose(ref.extra["r_scale"], scale, rtol=1e-9, atol=1e-9)
    assert_backends_agree(fast, ref)


def _settled_nees(result: RunResult, truth: pa.Table, after_s: float = 120.0) -> float:
    """Mean NEES of position, velocity and attitude (9 dof) after ``after_s``."""
    inside, err, _ = error_states(result, truth)
    t = (result.t_ns[inside] - result.t_ns[0]) * 1e-9
    e, P = err[t > after_s, :9], result.P[inside][t > after_s, :9, :9]
    return float(np.mean([e[k] @ np.linalg.solve(P[k], e[k]) for k in range(len(e))]))


def test_an_optimistic_receiver_is_found_out_and_the_filter_stays_consistent(
    filters: FiltersParams,
) -> None:
    """F8 on a 5-minute drive with white fix errors: 5 m errors reported as 0.5 m. lc_ekf on
    the white model (iae_ekf's gnss section) believes the receiver (NEES ~35 x its dof, 7.5 m
    RMS); the IAE learns a variance multiplier near the truth's (5 / 0.5)^2 = 100 and, once
    its window is full, is consistent. Its first ``min_epochs`` fixes are taken at their word,
    which the whole run's NEES still shows."""
    tables, sensors = seoul(300.0, seed=3, white_fixes=True)
    bad = optimistic_accuracy(tables, np.random.default_rng(11))
    section = filters.get("iae_ekf")
    plain = run_filter(bad, sensors, "lc_ekf", replace(filters.get("lc_ekf"), gnss=section.gnss))
    iae = run_filter(bad, sensors, "iae_ekf", section)
    truth = tables["truth"]
    m_plain, m_iae = compute_metrics(plain, truth), compute_metrics(iae, truth)
    dof = m_iae["nees_dof"]
    assert dof == 9
    assert m_plain["nees_mean"] > 10 * dof
    assert _settled_nees(plain, truth) > 10 * dof
    assert _settled_nees(iae, truth) < 2 * dof
    assert m_iae["nees_mean"] < m_plain["nees_mean"] / 5
    assert m_iae["pos_err_h_rms_m"] < 0.5 * m_plain["pos_err_h_rms_m"]
    settled = iae.extra["r_scale"][iae.t_ns > iae.t_ns[0] + 120e9]
    assert 50.0 < np.median(settled) < 200.0


def test_an_honest_receiver_keeps_its_declared_variances(filters: FiltersParams) -> None:
    tables, sensors = seoul(300.0, seed=3, white_fixes=True)
    iae = run_filter(tables, sensors, "iae_ekf", filters.get("iae_ekf"))
    settled = iae.extra["r_scale"][iae.t_ns > iae.t_ns[0] + 120e9]
    assert 0.5 <= np.median(settled) <= 2.0
    assert 0.5 * 9 < _settled_nees(iae, tables["truth"]) < 2 * 9
