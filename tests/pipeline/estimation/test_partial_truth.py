"""A truth table with positions only (a simulator's ``SIM``/``SIMSTATE`` has no velocity):
position metrics and outage-window tracks as with full truth, velocity metrics absent."""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pytest

from navreplay.ingest.meta import SensorMeta
from navreplay.pipeline.estimation.config import FiltersParams
from navreplay.pipeline.estimation.ins.metrics import compute_metrics
from navreplay.pipeline.estimation.ins.replay import run_filter
from navreplay.pipeline.estimation.ins.tracks import truth_track
from tests.pipeline.estimation.conftest import Tables

VELOCITY = ("vel_n_mps", "vel_e_mps", "vel_d_mps")
ATTITUDE = ("roll_rad", "pitch_rad", "yaw_rad")


def _without(truth: pa.Table, names: tuple[str, ...]) -> pa.Table:
    return truth.drop_columns([n for n in names if n in truth.column_names])


def test_truth_without_velocity_gives_position_metrics_and_no_velocity_metrics(
    filters: FiltersParams, drive60: tuple[Tables, SensorMeta]
) -> None:
    tables, sensors = drive60
    r = run_filter(tables, sensors, "lc_ekf", filters.get("lc_ekf"))
    full = compute_metrics(r, tables["truth"])
    partial = compute_metrics(r, _without(tables["truth"], VELOCITY))
    assert full["truth"]
    assert partial["truth"]
    for key in ("pos_err_h_rms_m", "pos_err_v_rms_m", "pos_err_3d_rms_m", "pos_err_3d_max_m"):
        assert partial[key] == pytest.approx(full[key], rel=1e-12)
    assert full["vel_err_3d_rms_mps"] is not None
    assert partial["vel_err_3d_rms_mps"] is None
    assert partial["truth_missing"] == ["vel_n", "vel_e", "vel_d"]
    assert partial["nees_dof"] == 6
    assert partial["nees_states"][3:] == ["att_n", "att_e", "att_d"]
    assert np.isfinite(partial["nees_mean"])
    bare = compute_metrics(r, _without(tables["truth"], VELOCITY + ATTITUDE))
    assert bare["att_err_rms_rad"] is None
    assert bare["nees_dof"] == 3
    assert bare["pos_err_h_rms_m"] == pytest.approx(full["pos_err_h_rms_m"], rel=1e-12)
    # SIMSTATE: latitude and longitude only, heights NaN.
    t = tables["truth"]
    flat = t.set_column(
        t.schema.get_field_index("alt_m"), "alt_m", pa.array(np.full(len(t), np.nan))
    )
    sim = compute_metrics(r, _without(flat, VELOCITY))
    assert sim["pos_err_h_rms_m"] == pytest.approx(full["pos_err_h_rms_m"], rel=1e-12)
    assert sim["pos_err_v_rms_m"] is None
    assert sim["pos_err_3d_max_m"] is None
    assert sim["truth_missing"] == ["pos_d", "vel_n", "vel_e", "vel_d"]


def test_outage_track_against_truth_without_velocity(
    filters: FiltersParams, drive60: tuple[Tables, SensorMeta]
) -> None:
    # It raised KeyError: 'vel_n_mps' (issue 23: a SITL tlog's SIMSTATE truth).
    tables, sensors = drive60
    r = run_filter(tables, sensors, "lc_ekf", filters.get("lc_ekf"))
    full = truth_track(r, tables["truth"])
    partial = truth_track(r, _without(tables["truth"], VELOCITY + ATTITUDE))
    np.testing.assert_array_equal(partial.err_ned_m, full.err_ned_m)
