"""Acceptance on the synthesized seoul_campus drive (params.yaml: 900 s, both directions).

Horizontal RMS error below 1.5 m for every filter with nominal GNSS. The loosely coupled
filters are limited by the receiver's fix errors (1.5 m UERE, correlated over 30 s, which
filtering cannot average out); the tightly coupled ones use the white pseudorange noise.
"""

from __future__ import annotations

import pytest

from navreplay.ingest.meta import SensorMeta
from navreplay.pipeline.estimation.config import FiltersParams
from navreplay.pipeline.estimation.ins.metrics import compute_metrics
from navreplay.pipeline.estimation.ins.replay import run_filter
from navreplay.pipeline.params import load_params
from navreplay.pipeline.synth.seoul_campus import simulate
from tests.pipeline.estimation.conftest import ALL_FILTERS, REPO, Tables


@pytest.fixture(scope="module", params=["cw", "ccw"])
def seoul_campus(request: pytest.FixtureRequest) -> tuple[Tables, SensorMeta]:
    params = load_params(REPO / "params.yaml").synth
    result = simulate(params.seoul_campus, seed=params.seed, variant=request.param)
    return dict(result.tables), result.sensors


@pytest.mark.parametrize("name", ALL_FILTERS)
def test_horizontal_rms_below_1_5_m_with_consistent_covariance(
    name: str, filters: FiltersParams, seoul_campus: tuple[Tables, SensorMeta]
) -> None:
    tables, sensors = seoul_campus
    r = run_filter(tables, sensors, name, filters.get(name))
    m = compute_metrics(r, tables["truth"])
    assert r.status == "ok"
    assert m["pos_err_h_rms_m"] < 1.5
    assert m["pos_h_within_3sigma"] > 0.99
    assert m["nees_mean"] < 2.0 * 9  # navigation states; NHC and LC are conservative here
    assert m["gate_rejections"] <= 2
