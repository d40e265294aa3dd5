"""One model, two backends: the compiled kernels and filterpy agree on every filter."""

from __future__ import annotations

import pyarrow as pa
import pytest

from navreplay.ingest.meta import SensorMeta
from navreplay.pipeline.estimation.config import FiltersParams
from navreplay.pipeline.estimation.ins.replay import run_filter
from tests.pipeline.estimation.conftest import ALL_FILTERS, assert_backends_agree


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
    assert_backends_agree(fast, ref)
    assert [e.kind for e in fast.events] == [e.kind for e in ref.events]
