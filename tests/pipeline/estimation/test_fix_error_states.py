"""Correlated fix errors as Gauss-Markov states of the loosely coupled filters
(``gnss.fix_error_states``): the start, both backends, and what they buy over the inflation."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from navreplay.pipeline.estimation.config import FiltersParams
from navreplay.pipeline.estimation.ins import outputs
from navreplay.pipeline.estimation.ins.alignment import Alignment
from navreplay.pipeline.estimation.ins.config import InsFilterParams
from navreplay.pipeline.estimation.ins.metrics import compute_metrics
from navreplay.pipeline.estimation.ins.models import ins
from navreplay.pipeline.estimation.ins.replay import RunResult, run_filter, with_fix_error_states
from navreplay.pipeline.estimation.ins.truth import error_states
from navreplay.pipeline.report.inputs import Run
from navreplay.pipeline.report.sections import noise_rows
from tests.pipeline.estimation.conftest import Tables, assert_backends_agree, seoul


def _inflation_only(section: InsFilterParams) -> InsFilterParams:
    return replace(section, gnss=replace(section.gnss, fix_error_states=False))


def _h_rms(result: RunResult, tables: Tables) -> float:
    _, err, _ = error_states(result, tables["truth"])
    return float(np.sqrt(np.mean(err[:, 0] ** 2 + err[:, 1] ** 2)))


def _fix_h_rms(tables: Tables) -> float:
    """The raw fixes' horizontal RMS against the truth's IMU position (the campus car's
    antenna is 0.3 m ahead of it, small beside the fixes' 1-2 m errors)."""
    g, tr = tables["gnss"], tables["truth"]
    t_g = g.column("t_ns").to_numpy()
    t_t = tr.column("t_ns").to_numpy()
    k = np.searchsorted(t_t, t_g).clip(0, t_t.size - 1)
    lat0 = math.radians(float(tr.column("lat_deg")[0].as_py()))
    dn = np.radians(g.column("lat_deg").to_numpy() - tr.column("lat_deg").to_numpy()[k]) * 6.371e6
    de = (np.radians(g.column("lon_deg").to_numpy() - tr.column("lon_deg").to_numpy()[k])
          * 6.371e6 * math.cos(lat0))  # fmt: skip
    return float(np.sqrt(np.mean(dn**2 + de**2)))


def test_the_start_makes_the_fix_error_the_opposite_of_the_position_error() -> None:
    P0 = np.diag(np.arange(1.0, 16.0))
    al = Alignment(0, np.ones(ins.FULL_DIM), P0, "gnss_velocity", 5.0, 0.0)
    white = with_fix_error_states(al, (0.0, 2.0))  # no states: only the clock slots zeroed
    np.testing.assert_array_equal(white.P0, P0)
    assert white.x0[ins.X_CB] == white.x0[ins.X_CD] == 0.0
    np.testing.assert_array_equal(np.delete(white.x0, [ins.X_CB, ins.X_CD]), 1.0)
    gm = with_fix_error_states(al, (30.0, 2.0))
    assert gm.P0.shape == (ins.N_TIGHT, ins.N_TIGHT)
    np.testing.assert_array_equal(gm.P0[:15, 2:15], P0[:15, 2:15])
    for axis in range(2):
        g, p = ins.E_CB + axis, ins.E_POS + axis
        assert gm.P0[g, g] == 4.0
        assert gm.P0[p, p] == P0[p, p] + 4.0
        assert gm.P0[p, g] == gm.P0[g, p] == -4.0
    assert np.all(np.linalg.eigvalsh(gm.P0) > 0.0)
    assert gm.x0[ins.X_CB] == gm.x0[ins.X_CD] == 0.0
    assert with_fix_error_states(gm, (30.0, 2.0)) is gm  # once


@pytest.mark.parametrize("seed", [3, 4])
def test_correlated_fix_errors_as_states_beat_the_fixes_and_stay_consistent(
    filters: FiltersParams, seed: int
) -> None:
    """Five minutes of the campus drive, its fix errors correlated over 30 s. The states are
    learned from the log (tau, size) and carried; the filter is then no worse than the raw
    fixes, as accurate as the inflation within 10 % (on this drive the two are alike; the
    robustness sweep's 60 s cells are where the states win), its NEES within [0.5, 2] x dof."""
    tables, sensors = seoul(300.0, seed=seed)
    section = filters.get("lc_ekf")
    gm = run_filter(tables, sensors, "lc_ekf", section)
    assert gm.fix_noise["states"] is True
    assert gm.n == ins.N_TIGHT
    inflated = run_filter(tables, sensors, "lc_ekf", _inflation_only(section))
    assert inflated.fix_noise["states"] is False
    assert inflated.n == ins.N_LOOSE
    fixes = _fix_h_rms(tables)
    assert _h_rms(gm, tables) <= fixes
    assert _h_rms(gm, tables) <= 1.1 * _h_rms(inflated, tables)
    m = compute_metrics(gm, tables["truth"])
    assert 0.5 * m["nees_dof"] <= m["nees_mean"] <= 2.0 * m["nees_dof"]
    assert m["nees_states"] == [n for n in m["nees_states"] if not n.startswith("fix_error")]
    cols = outputs.estimate_columns(gm)
    assert {"fix_error_n_m", "fix_error_e_sigma_m"} <= set(cols)
    assert "clock_bias_m" not in cols
    # the report's noise table says which model each filter used
    runs = [Run(Path(name), name, "nominal", {"fix_noise": r.fix_noise}, None, None, [])
            for name, r in (("lc_ekf", gm), ("lc_ekf_inflated", inflated))]  # fmt: skip
    rows = {row["filter"]: row for row in noise_rows(runs)}
    assert rows["lc_ekf"]["states"] == gm.fix_noise["states_sigma_m"] > 0.0
    assert rows["lc_ekf_inflated"]["states"] is None
    assert rows["lc_ekf_inflated"]["inflation"] == inflated.fix_noise["inflation"] > 1.0


def test_numba_and_filterpy_agree_with_fix_error_states(filters: FiltersParams) -> None:
    tables, sensors = seoul(150.0, seed=5)
    section = filters.get("lc_ekf_nhc")
    fast = run_filter(tables, sensors, "lc_ekf_nhc", section, backend="numba")
    ref = run_filter(tables, sensors, "lc_ekf_nhc", section, backend="filterpy")
    assert fast.fix_noise["states"] is True
    assert fast.status == ref.status == "ok"
    assert_backends_agree(fast, ref)
