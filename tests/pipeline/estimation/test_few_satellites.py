"""Tight coupling uses whatever satellites an epoch has: with 1-3 it still updates."""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pytest

from navreplay.ingest.meta import SensorMeta
from navreplay.pipeline.estimation.config import FiltersParams
from navreplay.pipeline.estimation.ins.replay import RunResult, run_filter
from navreplay.pipeline.estimation.ins.truth import error_states
from tests.pipeline.estimation.conftest import Tables, seoul, t0_ns


def keep_satellites(obs: pa.Table, t0: int, lo_s: float, hi_s: float, k: int) -> pa.Table:
    """Inside the window only the first ``k`` satellites of each epoch remain."""
    t = obs.column("t_ns").to_numpy()
    rank = np.zeros(t.size, dtype=np.int64)
    starts = np.flatnonzero(np.r_[True, np.diff(t) != 0])
    for a, b in zip(starts, np.r_[starts[1:], t.size], strict=True):
        rank[a:b] = np.arange(b - a)
    inside = (t - t0 >= lo_s * 1e9) & (t - t0 < hi_s * 1e9)
    return obs.filter(pa.array(~inside | (rank < k)))


@pytest.fixture(scope="module")
def drive() -> tuple[Tables, SensorMeta]:
    return seoul(150.0, seed=21)


def window_errors(
    tables: Tables, sensors: SensorMeta, filters: FiltersParams, name: str, k: int
) -> tuple[RunResult, np.ndarray, np.ndarray]:
    """The run with k satellites from 60 to 120 s, its errors and sigmas in that window."""
    t0 = t0_ns(tables)
    obs = keep_satellites(tables["gnss_obs"], t0, 60.0, 120.0, k)
    r = run_filter(dict(tables, gnss_obs=obs), sensors, name, filters.get(name))
    inside, err, _ = error_states(r, tables["truth"])
    sig = np.sqrt(np.diagonal(r.P[inside], axis1=1, axis2=2))
    t = (r.t_ns[inside] - t0) * 1e-9
    w = (t >= 60.0) & (t < 120.0)
    return r, err[w], sig[w]


@pytest.mark.parametrize("k", [1, 2, 3])
@pytest.mark.parametrize("name", ["tc_ekf", "tc_ukf", "tc_ukf_nhc"])
def test_updates_continue_with_fewer_than_four_satellites(
    name: str, k: int, filters: FiltersParams, drive: tuple[Tables, SensorMeta]
) -> None:
    tables, sensors = drive
    t0 = t0_ns(tables)
    r, err, sig = window_errors(tables, sensors, filters, name, k)
    assert r.status == "ok"
    sat = r.inn_i[:, 1] == 2
    window = sat & (r.inn_i[:, 0] - t0 >= 60e9) & (r.inn_i[:, 0] - t0 < 120e9)
    epochs = np.unique(r.inn_i[window, 0])
    assert epochs.size == 60  # every epoch of the window updates ...
    assert window.sum() == 60 * k  # ... with its k satellites
    assert np.mean(r.inn_i[window, 4]) > 0.95  # accepted
    assert np.mean(np.abs(err[:, :3]) <= 3.0 * sig[:, :3]) > 0.99
    if not name.endswith("nhc"):  # with the NHC even a complete outage drifts < 2 m here
        _, err0, _ = window_errors(tables, sensors, filters, name, 0)
        # the k pseudoranges hold the error below the free inertial drift of 60 s
        assert np.hypot(err[:, 0], err[:, 1]).max() < 0.8 * np.hypot(err0[:, 0], err0[:, 1]).max()
