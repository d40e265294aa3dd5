"""The integrity monitor (``core.integrity``): innovations that agree with the covariance are
``ok``; larger ones ``inconsistent``; an estimate that left its measurements ``diverged``;
and a filter started wrong is never reported ``ok`` while far off."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pyarrow as pa
import pytest

from navreplay.pipeline.estimation.config import FiltersParams
from navreplay.pipeline.estimation.core.integrity import IntegrityParams, assess
from navreplay.pipeline.estimation.core.windows import NS
from navreplay.pipeline.estimation.ins.alignment import Alignment
from navreplay.pipeline.estimation.ins.metrics import compute_metrics
from navreplay.pipeline.estimation.ins.models import ins
from navreplay.pipeline.estimation.ins.outputs import innovations_table
from navreplay.pipeline.estimation.ins.replay import run_filter
from navreplay.pipeline.estimation.ins.run import decode
from navreplay.pipeline.nav.rotations import euler_to_quat, quat_to_euler

from .conftest import seoul

P = IntegrityParams()
T0 = 1_800_000_000 * NS


def innovations(
    z: np.ndarray, rate_hz: float = 5.0, dim: int = 2, stream: str = "gnss_pos"
) -> pa.Table:
    """An innovations table of normalized innovations ``z`` (rows x dim) at ``rate_hz``."""
    n = z.shape[0]
    cols: dict[str, pa.Array] = {
        "t_ns": pa.array(T0 + np.arange(n) * round(NS / rate_hz), pa.int64()),
        "stream": pa.array([stream] * n),
        "sv": pa.array([""] * n),
        "dim": pa.array(np.full(n, dim), pa.int8()),
        "nis": pa.array((z**2).sum(axis=1)),
        "gate": pa.array(np.full(n, 20.0)),
        "accepted": pa.array((z**2).sum(axis=1) < 20.0),
    }
    for k in range(3):
        cols[f"innov_{k}"] = pa.array(z[:, k] if k < dim else np.full(n, np.nan))
    for k in range(3):
        cols[f"innov_sigma_{k}"] = pa.array(np.ones(n) if k < dim else np.full(n, np.nan))
    return pa.table(cols)


def test_innovations_that_fit_the_covariance_are_ok() -> None:
    rng = np.random.default_rng(1)
    v = assess(innovations(rng.normal(size=(3000, 2))), P)
    assert v.status == "ok"
    s = v.streams["gnss_pos"]
    assert s.windows > 100
    assert s.failed <= 0.02 * s.windows
    assert s.rho < 0.1


def test_innovations_twice_the_sigma_are_inconsistent() -> None:
    rng = np.random.default_rng(2)
    v = assess(innovations(2.0 * rng.normal(size=(3000, 2))), P)
    assert v.status == "inconsistent"
    assert v.reason is not None
    assert "gnss_pos innovations are larger than the filter's covariance says" in v.reason


def test_slowly_drifting_errors_are_not_mistaken_for_inconsistency() -> None:
    """AR(1) innovations (rho 0.9) of unit variance: the same spread as white ones, with
    fewer independent samples. Without the effective-sample scaling the windowed chi-square
    test fails far more often."""
    rng = np.random.default_rng(3)
    z = np.empty((6000, 2))
    z[0] = rng.normal(size=2)
    for k in range(1, len(z)):
        z[k] = 0.9 * z[k - 1] + np.sqrt(1 - 0.81) * rng.normal(size=2)
    v = assess(innovations(z), P)
    assert v.status == "ok"
    assert v.streams["gnss_pos"].rho == pytest.approx(0.9, abs=0.05)


def test_an_estimate_that_left_its_measurements_diverged_from_then_on() -> None:
    rng = np.random.default_rng(4)
    z = rng.normal(size=(1500, 2))  # 300 s at 5 Hz
    z[600:] += np.linspace(0.0, 40.0, 900)[:, None]  # from 120 s the estimate drifts away
    v = assess(innovations(z), P)
    assert v.status == "diverged"
    assert v.t_ns is not None
    assert 120.0 < (v.t_ns - T0) / NS < 200.0
    assert v.reason is not None
    assert "left the gnss_pos measurements" in v.reason


def test_a_burst_of_outliers_is_not_a_divergence() -> None:
    """10 % of the samples in 30 s at 20 sigma (catalogue F7): rejected by the gate, and the
    median of every window stays small."""
    rng = np.random.default_rng(5)
    z = rng.normal(size=(3000, 2))
    burst = np.flatnonzero(rng.random(150) < 0.1) + 1500
    z[burst] += 20.0
    v = assess(innovations(z), P)
    assert v.status == "ok"
    assert v.streams["gnss_pos"].diverged_ns is None


def test_too_few_blocks_are_not_tested() -> None:
    assert assess(innovations(np.full((3, 2), 50.0)), P).status == "ok"
    assert assess(innovations(np.empty((0, 2))), P).streams == {}


@pytest.mark.slow
@pytest.mark.parametrize("name", ["lc_ekf", "tc_ekf"])
def test_a_filter_started_on_a_wrong_heading_is_not_ok(filters: FiltersParams, name: str) -> None:
    """Started 90 degrees off with the covariance of a good alignment (what a heading taken
    from noise at standstill gives), the filter finishes without a NaN or a limit crossed,
    far from the truth: the monitor says so."""
    tables, sensors = seoul(180.0, seed=11, white_fixes=True)
    section = filters.get(name)
    good = run_filter(tables, sensors, name, section)
    assert good.status == "ok"
    assert assess(innovations_table(good), section.integrity).status == "ok"
    al = good.alignments[0]
    roll, pitch, yaw = quat_to_euler(al.x0[ins.X_Q : ins.X_Q + 4])
    x0 = al.x0.copy()
    x0[ins.X_Q : ins.X_Q + 4] = euler_to_quat(roll, pitch, yaw + np.pi / 2)
    wrong = Alignment(al.t_ns, x0, al.P0, al.method, al.speed_mps, al.static_window_s)
    flag = replace(section, divergence=replace(section.divergence, on_divergence="flag"))
    bad = run_filter(tables, sensors, name, flag, initial=wrong)
    error = compute_metrics(bad, tables["truth"])["pos_err_h_rms_m"]
    verdict = assess(innovations_table(bad), section.integrity)
    assert error > 10.0 * compute_metrics(good, tables["truth"])["pos_err_h_rms_m"]  # far off ...
    assert bad.status != "ok" or verdict.status != "ok"  # ... and never reported ok
    # the run contract applies the verdict: metrics.json and the status carry it
    out = decode(bad, compute_metrics(bad, tables["truth"]), (), section.integrity)
    assert out.metrics["integrity"]["status"] == verdict.status
    assert out.status != "ok"
    assert out.metrics["failure"]
