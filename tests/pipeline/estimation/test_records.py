"""The kernels' records: a run log that is too small grows, and nothing is silently lost."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from navreplay.ingest.meta import SensorMeta
from navreplay.pipeline.estimation.config import FiltersParams
from navreplay.pipeline.estimation.core.runlog import CNT_EV, CNT_INN, CNT_OUT, RunLog
from navreplay.pipeline.estimation.ins.replay import run_filter
from tests.pipeline.estimation.conftest import Tables


def test_grown_is_none_when_everything_fitted_and_large_enough_otherwise() -> None:
    log = RunLog.allocate(4, 5, 6, n=15, full_dim=18)
    assert log.capacity() == (4, 5, 6)
    log.counts[CNT_OUT], log.counts[CNT_INN], log.counts[CNT_EV] = 4, 5, 6
    assert log.grown() is None
    log.counts[CNT_INN], log.counts[CNT_EV] = 9, 2
    bigger = log.grown()
    assert bigger is not None
    assert bigger.capacity() == (4, 9, 6)
    assert bigger.out_P.shape == (4, 15, 15)
    assert bigger.out_x.shape == (4, 18)
    assert not bigger.counts.any()


@pytest.mark.parametrize("name", ["lc_ekf", "tc_ukf_nhc", "fwekf"])
def test_a_run_whose_log_is_too_small_grows_it_and_loses_nothing(
    name: str,
    drive60: tuple[Tables, SensorMeta],
    filters: FiltersParams,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    tables, sensors = drive60
    full = run_filter(tables, sensors, name, filters.get(name))
    allocate = RunLog.allocate
    calls: list[tuple[int, int, int]] = []

    def small_first(n_out: int, n_inn: int, n_ev: int, n: int, full_dim: int) -> Any:
        calls.append((n_out, n_inn, n_ev))
        if len(calls) == 1:  # the first log of the run holds a tenth of what it needs
            n_out, n_inn, n_ev = n_out // 10, n_inn // 10, 1
        return allocate(n_out, n_inn, n_ev, n, full_dim)

    monkeypatch.setattr(RunLog, "allocate", staticmethod(small_first))
    grown = run_filter(tables, sensors, name, filters.get(name))
    assert len(calls) == 2  # one re-run with the grown log
    assert grown.status == full.status == "ok"
    for got, want in ((grown.t_ns, full.t_ns), (grown.x, full.x), (grown.P, full.P),
                      (grown.inn_i, full.inn_i), (grown.inn_f, full.inn_f)):  # fmt: skip
        np.testing.assert_array_equal(got, want)
    assert grown.events == full.events
    assert grown.x.shape[0] > 100
