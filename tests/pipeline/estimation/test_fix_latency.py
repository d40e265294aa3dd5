"""Fixes stamped late against the IMU (a receiver's delay a log's clock pairing kept): the
latency ingest measures against the onboard estimator, or the dataset declares, moves each fix
to its epoch in the filters and in the errors against the fixes; tumbles end a segment."""

from __future__ import annotations

import math

import numpy as np
import pyarrow as pa
import pytest

from navreplay.pipeline.estimation.config import FiltersParams
from navreplay.pipeline.estimation.core.tables import fix_epochs, with_fix_latency
from navreplay.pipeline.estimation.ins import inputs as inp
from navreplay.pipeline.estimation.ins.config import StepParams
from navreplay.pipeline.estimation.ins.replay import RunResult, run_filter
from navreplay.pipeline.estimation.ins.tracks import fixes_track
from navreplay.pipeline.estimation.ins.truth import error_states
from tests.pipeline.estimation.conftest import Tables, seoul

LATE_S = 0.25


def _stamped_late(tables: Tables, late_s: float) -> Tables:
    """The drive with every fix stamped ``late_s`` after its epoch (as on arrival)."""
    out = dict(tables)
    g = tables["gnss"]
    t = pa.array(g.column("t_ns").to_numpy() + round(late_s * 1e9), pa.int64())
    out["gnss"] = g.set_column(g.column_names.index("t_ns"), "t_ns", t)
    return out


def _h_rms(result: RunResult, tables: Tables) -> float:
    _, err, _ = error_states(result, tables["truth"])
    return float(np.sqrt(np.mean(err[:, 0] ** 2 + err[:, 1] ** 2)))


def test_the_dataset_latency_becomes_a_column_unless_the_reader_gave_one() -> None:
    g = pa.table({"t_ns": pa.array([10**9, 2 * 10**9], pa.int64())})
    tables = {"gnss": g}
    with_fix_latency(tables, None)
    assert tables["gnss"] is g
    with_fix_latency(tables, 0.2)
    assert fix_epochs(tables["gnss"]).tolist() == [800_000_000, 1_800_000_000]
    own = {"gnss": g.append_column("latency_s", pa.array([0.1, math.nan]))}
    with_fix_latency(own, 0.2)  # the reader's per-fix latency wins; NaN: none known
    assert fix_epochs(own["gnss"]).tolist() == [900_000_000, 2_000_000_000]


def test_late_fixes_cost_accuracy_and_their_latency_wins_it_back(filters: FiltersParams) -> None:
    tables, sensors = seoul(120.0, 3)
    section = filters.get("lc_ekf")
    on_time = _h_rms(run_filter(tables, sensors, "lc_ekf", section), tables)
    late = _stamped_late(tables, LATE_S)
    ignored = _h_rms(run_filter(late, sensors, "lc_ekf", section), tables)
    with_fix_latency(late, LATE_S)
    result = run_filter(late, sensors, "lc_ekf", section)
    applied = _h_rms(result, tables)
    assert result.fix_noise["latency_s"] == pytest.approx(LATE_S)
    # at 5-10 m/s a quarter second is 1-2.5 m along the track
    assert ignored > 1.3 * on_time
    assert applied == pytest.approx(on_time, rel=0.05)
    # the errors against the fixes are taken at their epochs too
    at_epochs = fixes_track(result, late["gnss"], sensors.lever_arm_m)
    stamped = fixes_track(result, late["gnss"].drop_columns(["latency_s"]), sensors.lever_arm_m)
    h = [np.sqrt(np.mean(np.sum(tr.err_ned_m[:, :2] ** 2, axis=1))) for tr in (at_epochs, stamped)]
    assert h[0] < 0.8 * h[1]


def test_a_tumble_ends_the_segment_until_the_imu_settles() -> None:
    rate_hz, n = 50, 1000  # 20 s at 50 Hz
    t = np.arange(n, dtype=np.int64) * (1_000_000_000 // rate_hz)
    data = np.zeros((n, 6))
    data[:, 2] = -9.81
    data[500:520, 3] = 18.0  # 0.4 s of a flip at 18 rad/s: 0.36 rad between samples
    data[530, 4] = 30.0  # a last jolt 0.2 s later belongs to the same tumble
    out = inp.clean_imu(t, data, StepParams())
    (tumble,) = [e for e in out.events if e.kind == "imu_tumble"]
    assert tumble.t_ns == t[500]
    assert tumble.value == pytest.approx(30.0)
    settled = 531 + rate_hz * StepParams().tumble_settle_s - 1  # 1 s after the last jolt
    assert out.segments == ((0, 500), (int(settled), n))
    # a fast but well-sampled turn (10 rad/s at 400 Hz: 0.025 rad a sample) is no tumble
    fast = np.arange(n, dtype=np.int64) * 2_500_000
    calm = inp.clean_imu(fast, np.where(np.arange(6) == 3, 10.0, data), StepParams())
    assert calm.segments == ((0, n),)
