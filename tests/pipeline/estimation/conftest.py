"""Fixtures of the estimation tests: the repository's filter params and seoul_campus-type runs."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pytest

from navreplay.ingest.meta import SensorMeta
from navreplay.pipeline.estimation.config import FiltersParams
from navreplay.pipeline.estimation.ins.alignment import Alignment
from navreplay.pipeline.estimation.ins.config import FILTER_KINDS, InsFilterParams
from navreplay.pipeline.estimation.ins.models import ins
from navreplay.pipeline.estimation.ins.replay import RunResult
from navreplay.pipeline.nav.rotations import euler_to_quat
from navreplay.pipeline.params import load_params
from navreplay.pipeline.synth.seoul_campus import simulate

REPO = Path(__file__).resolve().parents[3]
# The six filters of paper 001 (issue 5); fwekf (paper 004) has its own tests.
ALL_FILTERS = tuple(name for name, kind in FILTER_KINDS.items() if not kind.adaptive)


@pytest.fixture(scope="session")
def filters() -> FiltersParams:
    """The ``filters`` section of the repository's params.yaml."""
    return load_params(REPO / "params.yaml").filters


def section(filters: FiltersParams, name: str, **step: Any) -> InsFilterParams:
    """Filter ``name``'s params, optionally with changed ``step`` settings."""
    p = filters.get(name)
    return replace(p, step=replace(p.step, **step)) if step else p


Tables = dict[str, pa.Table]


def seoul(
    duration_s: float,
    seed: int,
    *,
    variant: str = "cw",
    white_fixes: bool = False,
    stationary_s: float = 10.0,
) -> tuple[Tables, SensorMeta]:
    """A seoul_campus drive (params.yaml's synthesizer settings) with 10 s (``stationary_s``)
    at rest first.

    The vehicle starts moving at 10 s and turns 90 degrees at about 45 s. ``white_fixes``
    makes the receiver's position-fix errors white (the synthesizer's default correlates them
    over 30 s, which the loosely coupled filters do not model).
    """
    sp = load_params(REPO / "params.yaml").synth.seoul_campus
    sp = replace(sp, duration_s=duration_s, stationary_s=stationary_s)
    if white_fixes:
        sp = replace(sp, gnss=replace(sp.gnss, fix_tau_s=1e-3))
    result = simulate(sp, seed=seed, variant=variant)  # type: ignore[arg-type]
    return dict(result.tables), result.sensors


def t0_ns(tables: Tables) -> int:
    """The first IMU time (the synthesizer's clock is GPS time)."""
    return int(tables["imu"].column("t_ns")[0].as_py())


@pytest.fixture(scope="session")
def drive60() -> tuple[Tables, SensorMeta]:
    """A 70 s seoul_campus drive: 10 s at rest, then 60 s with a 90 degree turn."""
    return seoul(70.0, seed=7)


def truth_state(truth: pa.Table, k: int) -> np.ndarray:
    """The full state (``models.ins`` layout) of truth row ``k``."""
    row = {c: truth.column(c)[k].as_py() for c in truth.column_names}
    X = np.zeros(ins.FULL_DIM)
    X[ins.X_LAT], X[ins.X_LON] = math.radians(row["lat_deg"]), math.radians(row["lon_deg"])
    X[ins.X_H] = row["alt_m"]
    X[ins.X_VEL : ins.X_VEL + 3] = (row["vel_n_mps"], row["vel_e_mps"], row["vel_d_mps"])
    X[ins.X_Q : ins.X_Q + 4] = euler_to_quat(row["roll_rad"], row["pitch_rad"], row["yaw_rad"])
    for j, axis in enumerate("xyz"):
        X[ins.X_BA + j] = row[f"acc_bias_{axis}_mps2"]
        X[ins.X_BG + j] = row[f"gyro_bias_{axis}_radps"]
    X[ins.X_CB], X[ins.X_CD] = row.get("clock_bias_m", 0.0), row.get("clock_drift_mps", 0.0)
    return X


def drawn_start(
    truth: pa.Table, k: int, n: int, sigmas: np.ndarray, rng: np.random.Generator
) -> Alignment:
    """A start at truth row ``k`` with an error drawn from ``P0 = diag(sigmas^2)``.

    Biases start at zero (their truth is itself a draw from the bias prior), everything else
    at the truth plus the drawn error: the textbook Monte Carlo NEES set-up.
    """
    X = truth_state(truth, k)
    dx = rng.normal(0.0, sigmas[:n])
    dx[ins.E_BA : ins.E_BG + 3] = 0.0
    x0 = X.copy()
    ins.inject(x0, -dx, n)  # estimate = truth - error
    x0[ins.X_BA : ins.X_BG + 3] = 0.0
    t0 = int(truth.column("t_ns")[k].as_py())
    return Alignment(t0, x0, np.diag(sigmas[:n] ** 2), "drawn", 0.0, 0.0)


def assert_backends_agree(fast: RunResult, ref: RunResult) -> None:
    """The numba and filterpy runs of one filter: the same output times, states within 1e-6
    of their sigma, sigmas, innovation rows (times, streams, satellites, gating) and NIS."""
    np.testing.assert_array_equal(fast.t_ns, ref.t_ns)
    sigma = np.sqrt(np.diagonal(fast.P, axis1=1, axis2=2))
    dx = np.array([ins.difference(ref.x[k], fast.x[k], fast.n) for k in range(fast.t_ns.size)])
    assert np.max(np.abs(dx) / sigma) < 1e-6
    np.testing.assert_allclose(np.sqrt(np.diagonal(ref.P, axis1=1, axis2=2)), sigma, rtol=1e-6)
    np.testing.assert_array_equal(fast.inn_i, ref.inn_i)
    np.testing.assert_allclose(fast.inn_f[:, 0], ref.inn_f[:, 0], rtol=1e-6, atol=1e-9)
