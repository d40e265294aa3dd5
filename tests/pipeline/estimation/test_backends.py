"""One model, two backends: the compiled kernels and filterpy agree on every filter."""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pytest

from navreplay.ingest.meta import SensorMeta
from navreplay.pipeline.estimation.config import FiltersParams
from navreplay.pipeline.estimation.ins.models import ins
from navreplay.pipeline.estimation.ins.replay import run_filter
from tests.pipeline.estimation.conftest import ALL_FILTERS


@pytest.mark.parametrize("name", ALL_FILTERS)
def test_numba_and_filterpy_backends_agree_within_1e_6_sigma(
    name: str, filters: FiltersParams, drive60: tuple[dict[str, pa.Table], SensorMeta]
) -> None:
    """Same states (within 1e-6 sigma), covariances, innovations and gating decisions."""
    tables, sensors = drive60
    fast = run_filter(tables, sensors, name, filters.get(name), backend="numba")
    ref = run_filter(tables, sensors, name, filters.get(name), backend="filterpy")
    assert fast.status == ref.status == "ok"
    assert fast.t_ns.size > 500
    np.testing.assert_array_equal(fast.t_ns, ref.t_ns)
    sigma = np.sqrt(np.diagonal(fast.P, axis1=1, axis2=2))
    dx = np.array([ins.difference(ref.x[k], fast.x[k], fast.n) for k in range(fast.t_ns.size)])
    assert np.max(np.abs(dx) / sigma) < 1e-6
    np.testing.assert_allclose(np.sqrt(np.diagonal(ref.P, axis1=1, axis2=2)), sigma, rtol=1e-6)
    np.testing.assert_array_equal(fast.inn_i, ref.inn_i)  # times, streams, satellites, gating
    np.testing.assert_allclose(fast.inn_f[:, 0], ref.inn_f[:, 0], rtol=1e-6, atol=1e-9)
    assert [e.kind for e in fast.events] == [e.kind for e in ref.events]
