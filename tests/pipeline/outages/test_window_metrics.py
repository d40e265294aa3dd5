"""Outage-window metrics: drift without re-alignment, against the truth or the withheld fixes."""

from __future__ import annotations

import math

import numpy as np
import pytest

from navreplay.pipeline.estimation.core.windows import (
    NS,
    ErrorTrack,
    Window,
    WindowMetricsParams,
    reconverge_s,
    table_track,
    window_metrics,
)
from navreplay.pipeline.estimation.ins.metrics import compute_metrics
from navreplay.pipeline.estimation.ins.outputs import estimate_table
from navreplay.pipeline.estimation.ins.replay import run_filter
from navreplay.pipeline.estimation.ins.tracks import (
    fixes_track,
    truth_track,
)
from navreplay.pipeline.scenarios.apply import apply_scenario
from navreplay.pipeline.scenarios.config import ScenarioSpec, WindowsSpec
from tests.pipeline.scenarios.drives import drive, params


def known_track() -> ErrorTrack:
    """10 Hz for 100 s, moving east at 10 m/s; 0.5 m north error, quadratic growth inside
    [20, 50) s, then an exponential decay with a 2 s time constant."""
    t = np.arange(0, 1000) * (NS // 10)
    s = t / NS
    err_n = np.where(s < 20, 0.5, np.where(s < 50, 0.5 + 0.1 * (s - 20) ** 2, 0.0))
    after = s >= 50
    err_n[after] = 0.3 + 90.5 * np.exp(-(s[after] - 50) / 2.0)
    err = np.column_stack([err_n, np.zeros(s.size), np.zeros(s.size)])
    ref = np.column_stack([np.zeros(s.size), 10.0 * s, np.zeros(s.size)])
    return ErrorTrack(t, err, np.full((s.size, 3), 100.0), ref, "truth")


def test_window_metrics_on_a_known_error_track() -> None:
    track = known_track()
    w = Window(20 * NS, 50 * NS, "outage", 0, "GNSS outage")
    (m,) = window_metrics(track, [w], 0, WindowMetricsParams())
    inside = (track.t_ns >= 20 * NS) & (track.t_ns < 50 * NS)
    e = track.err_ned_m[inside, 0]
    assert m["samples"] == 300
    assert m["err_start_m"] == pytest.approx(0.5)
    assert m["err_end_m"] == pytest.approx(0.5 + 0.1 * 29.9**2)
    assert m["err_max_m"] == pytest.approx(e.max())
    assert m["err_mean_m"] == pytest.approx(e.mean())
    assert m["err_rms_m"] == pytest.approx(math.sqrt(np.mean(e**2)))
    assert m["distance_m"] == pytest.approx(299.0)
    assert m["drift_pct_distance"] == pytest.approx(100 * m["err_end_m"] / 299.0)
    # moving east with a north error: all of it is cross-track
    assert m["err_end_cross_m"] == pytest.approx(m["err_end_m"])
    assert m["err_end_along_m"] == pytest.approx(0.0, abs=1e-9)
    # re-converged when 0.3 + 90.5 exp(-x / 2) <= max(1 m, 2 x 0.5 m), held for 5 s
    assert m["reconverge_threshold_m"] == pytest.approx(1.0)
    assert m["reconverge_s"] == pytest.approx(2.0 * math.log(90.5 / 0.7), abs=0.1)
    assert m["inside_3sigma_frac"] == 1.0


def test_reconvergence_needs_the_error_to_stay_below_for_the_hold() -> None:
    t = np.arange(0, 200) * (NS // 10)
    err = np.ones(200) * 5.0
    err[50:55] = 0.5  # a dip shorter than the hold
    err[120:] = 0.5
    assert reconverge_s(t, err, 0, 20 * NS, 1.0, 5.0) == pytest.approx(12.0)
    assert reconverge_s(t, err, 0, 15 * NS, 1.0, 5.0) is None  # not held before the cut


def test_drift_is_measured_from_the_state_at_outage_start_without_realignment() -> None:
    """The filter enters the window with a 2 m error: the end error includes it."""
    track = known_track()
    shifted = ErrorTrack(
        track.t_ns,
        track.err_ned_m + np.array([2.0, 0.0, 0.0]),
        track.sigma_ned_m,
        track.ref_ned_m,
        "truth",
    )
    w = [Window(20 * NS, 50 * NS, "outage", 0, "")]
    a = window_metrics(track, w, 0, WindowMetricsParams())[0]
    b = window_metrics(shifted, w, 0, WindowMetricsParams())[0]
    assert b["err_end_m"] == pytest.approx(a["err_end_m"] + 2.0)
    assert b["err_start_m"] == pytest.approx(2.5)


def test_withheld_fixes_measure_the_antenna_error_like_the_truth() -> None:
    tables, sensors = drive()
    r = run_filter(tables, sensors, "lc_ekf", params().filters.lc_ekf)
    by_truth = truth_track(r, tables["truth"])
    by_fixes = fixes_track(r, tables["gnss"], sensors.lever_arm_m)
    assert by_fixes.reference == "withheld_fixes"
    # the fixes carry ~1.5 m UERE errors (correlated over 30 s) the truth does not have
    h = np.hypot(by_fixes.err_ned_m[:, 0], by_fixes.err_ned_m[:, 1])
    h_truth = np.hypot(by_truth.err_ned_m[:, 0], by_truth.err_ned_m[:, 1])
    assert 0.2 < np.sqrt(np.mean(h**2)) < 3.0
    assert np.sqrt(np.mean(h**2)) != pytest.approx(np.sqrt(np.mean(h_truth**2)), abs=1e-3)
    lever_down_m = sensors.lever_arm_m[2]
    assert lever_down_m < -1.0  # a roof antenna
    unlevered = fixes_track(r, tables["gnss"], (0.0, 0.0, 0.0))
    # the lever arm is applied: on a level vehicle it moves the estimate by its down component
    shift = unlevered.err_ned_m[:, 2] - by_fixes.err_ned_m[:, 2]
    np.testing.assert_allclose(shift, lever_down_m, atol=0.05)
    assert by_truth.t_ns.size > by_fixes.t_ns.size


def test_run_metrics_without_truth_use_the_withheld_fixes() -> None:
    tables, sensors = drive(90.0)
    spec = ScenarioSpec(windows=WindowsSpec("explicit", 20.0, starts_s=(40.0,)))
    applied = apply_scenario(tables, "o", spec)
    r = run_filter(applied.tables, sensors, "tc_ukf", params().filters.tc_ukf)
    kw = {"windows": applied.outage_windows, "t0_ns": applied.t0_ns, "lever_b": sensors.lever_arm_m}
    with_truth = compute_metrics(r, tables["truth"], fixes=tables["gnss"], **kw)  # type: ignore[arg-type]
    without = compute_metrics(r, None, fixes=tables["gnss"], **kw)  # type: ignore[arg-type]
    (a,) = with_truth["outage_windows"]
    (b,) = without["outage_windows"]
    assert (a["reference"], b["reference"]) == ("truth", "withheld_fixes")
    assert a["samples"] == 200
    assert b["samples"] == 20
    assert abs(a["err_end_m"] - b["err_end_m"]) < 3 * 2.5  # within the fixes' noise
    assert without["truth"] is False


def test_the_estimate_table_gives_the_errors_the_full_state_gives() -> None:
    """``table_track`` (any family, from estimate.parquet) agrees with the INS error states:
    the same errors within a millimetre, the same sigmas, against the truth and the fixes."""
    tables, sensors = drive(90.0)
    r = run_filter(tables, sensors, "lc_ekf", params().filters.lc_ekf)
    est = estimate_table(r)
    full = truth_track(r, tables["truth"])
    from_table = table_track(est, tables["truth"], tables["gnss"])
    assert from_table is not None
    assert from_table.axes == 3
    assert from_table.reference == "truth"
    np.testing.assert_array_equal(from_table.t_ns, full.t_ns)
    np.testing.assert_allclose(from_table.err_ned_m, full.err_ned_m, atol=1e-3)
    np.testing.assert_allclose(from_table.sigma_ned_m, full.sigma_ned_m, rtol=1e-6)
    by_fixes = table_track(est, None, tables["gnss"])
    unlevered = fixes_track(r, tables["gnss"], (0.0, 0.0, 0.0))
    assert by_fixes is not None
    assert by_fixes.reference == "withheld_fixes"
    np.testing.assert_allclose(by_fixes.err_ned_m, unlevered.err_ned_m, atol=1e-3)
    assert table_track(est, None, None) is None


def test_a_planar_track_measures_horizontal_errors_only() -> None:
    """Without a height estimate the window's errors, 3-sigma test and sigma are horizontal."""
    track = known_track()
    err = track.err_ned_m.copy()
    err[:, 2] = 50.0  # a height error the planar model does not estimate
    sig = track.sigma_ned_m.copy()
    sig[:, 2] = np.nan
    planar = ErrorTrack(track.t_ns, err, sig, track.ref_ned_m, "truth", axes=2)
    w = [Window(20 * NS, 50 * NS, "outage", 0, "")]
    (a,) = window_metrics(track, w, 0, WindowMetricsParams())
    (b,) = window_metrics(planar, w, 0, WindowMetricsParams())
    assert b["err_end_m"] == pytest.approx(a["err_end_m"])
    assert b["err_end_down_m"] is None
    assert b["inside_3sigma_frac"] == a["inside_3sigma_frac"]
    assert b["sigma_end_m"] == pytest.approx(100.0 * math.sqrt(2.0))
