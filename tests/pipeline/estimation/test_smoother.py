"""RTS smoothing of the INS filters (``kernels.smoother``): the backward pass agrees with
filterpy's ``rts_smoother``, bridges an outage with both of its ends, is chi-square consistent
(Monte Carlo), keeps its memory small, and ``navreplay run --smooth`` writes it."""

from __future__ import annotations

import copy
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest
import yaml
from scipy.stats import chi2

from navreplay.ingest.meta import SensorMeta
from navreplay.ingest.schema import TableName
from navreplay.ingest.tables import read_table
from navreplay.pipeline.cli import main
from navreplay.pipeline.estimation.config import FiltersParams
from navreplay.pipeline.estimation.core.consistency import nees
from navreplay.pipeline.estimation.ins import replay
from navreplay.pipeline.estimation.ins.config import FILTER_KINDS
from navreplay.pipeline.estimation.ins.kernels import smoother as sk
from navreplay.pipeline.estimation.ins.replay import run_filter
from navreplay.pipeline.estimation.ins.tracks import ins_track
from navreplay.pipeline.estimation.ins.truth import error_states
from navreplay.pipeline.params import read_yaml
from tests.pipeline.estimation.conftest import (
    REPO,
    assert_backends_agree,
    drawn_start,
    seoul,
    t0_ns,
)
from tests.pipeline.scenarios.drives import short_window_scenarios, write_tables

Tables = dict[str, pa.Table]
EVERY_FILTER = tuple(FILTER_KINDS)


def without_gnss(tables: Tables, start_s: float, end_s: float) -> Tables:
    """``tables`` with no fix and no observation from ``start_s`` to ``end_s`` of the drive."""
    t0 = t0_ns(tables)
    out = dict(tables)
    for name in ("gnss", "gnss_obs"):
        t = tables[name].column("t_ns").to_numpy() - t0
        out[name] = tables[name].filter(~((t > start_s * 1e9) & (t < end_s * 1e9)))
    return out


def smoothed(filters: FiltersParams, name: str) -> object:
    return replace(filters.get(name), smooth=True)


@pytest.fixture(scope="module")
def drive30() -> tuple[Tables, SensorMeta]:
    """A 30 s drive (10 s at rest) with a 6 s outage in its motion."""
    tables, sensors = seoul(30.0, seed=5)
    return without_gnss(tables, 18.0, 24.0), sensors


@pytest.mark.parametrize("name", EVERY_FILTER)
def test_backward_pass_agrees_with_filterpys_rts_smoother(
    name: str, filters: FiltersParams, drive30: tuple[Tables, SensorMeta]
) -> None:
    """Same smoothed states (every error state within 1e-6 sigma), sigmas and covariances
    from the compiled pass and from filterpy's ``rts_smoother`` over the filterpy backend's
    own forward run."""
    tables, sensors = drive30
    p = smoothed(filters, name)
    fast = run_filter(tables, sensors, name, p, backend="numba")  # type: ignore[arg-type]
    ref = run_filter(tables, sensors, name, p, backend="filterpy")  # type: ignore[arg-type]
    assert fast.smoothing is not None
    assert fast.smoothing.status == "ok"
    assert ref.smoothing is not None
    assert ref.smoothing.status == "ok"
    a, b = fast.smoothed_run(), ref.smoothed_run()
    assert a is not None
    assert b is not None
    assert a.t_ns.size > 150
    # the smoothing changed the estimate (the comparison below is not of two forward runs)
    moved = np.abs(a.x[:, :3] - fast.x[:, :3]).max(axis=0) * np.array([6.4e6, 5e6, 1.0])
    assert moved.max() > 0.05
    assert_backends_agree(a, b)
    scale = np.abs(a.P).max(axis=(1, 2))[:, None, None]
    assert np.max(np.abs(a.P - b.P) / scale) < 1e-6


@pytest.mark.parametrize("name", ["lc_ekf", "tc_ekf", "tc_ukf"])
def test_smoother_bridges_an_outage_from_both_ends(name: str, filters: FiltersParams) -> None:
    """A 60 s outage of a 150 s drive: the smoothed error inside it is at most 30 % of the
    forward filter's, and no worse outside it."""
    tables, sensors = seoul(150.0, seed=11, white_fixes=True)
    run = run_filter(without_gnss(tables, 60.0, 120.0), sensors, name, smoothed(filters, name))  # type: ignore[arg-type]
    sm = run.smoothed_run()
    assert sm is not None
    t0 = t0_ns(tables)
    errs = []
    for r in (run, sm):
        track = ins_track(r, tables["truth"], None, (0.0, 0.0, 0.0))
        assert track is not None
        s = (track.t_ns - t0) * 1e-9
        h = np.hypot(track.err_ned_m[:, 0], track.err_ned_m[:, 1])
        inside, outside = (s > 60.0) & (s < 120.0), s > 20.0
        errs.append((h[inside].mean(), np.sqrt(np.mean(h[outside & ~inside] ** 2))))
    (fwd_in, fwd_out), (sm_in, sm_out) = errs
    assert fwd_in > 2.0  # a drift worth bridging
    assert sm_in <= 0.3 * fwd_in
    assert sm_out <= 1.05 * fwd_out


N_RUNS = 20
P0_SIGMA = np.array(
    [2.0] * 3 + [0.2] * 3 + [0.02, 0.02, 0.1] + [0.05] * 3 + [5e-4] * 3 + [10.0, 1.0]
)


@pytest.mark.parametrize("name", ["lc_ekf", "tc_ekf"])
def test_smoothed_nees_is_within_its_chi_square_bounds(name: str, filters: FiltersParams) -> None:
    """Monte Carlo (the set-up of ``test_consistency``: white fix errors, starts drawn from
    ``P0``) with a 20 s outage: the smoothed position-velocity-attitude NEES averaged over the
    runs is inside its two-sided 99 % interval at 90 % of the steps, and its grand mean is
    between 0.8 and 1.05 times the forward filter's over the same runs: the backward pass adds
    no overconfidence of its own. (Through this outage the forward lc_ekf's grand mean is
    ~1.15 times its dimension, 3.4-3.6 per 3-state block: the forward model's, issue 22.)"""
    section = filters.get(name)
    p = replace(section, smooth=True, gnss=replace(section.gnss, pos_error_corr_time_s=0.0))
    n = 17 if FILTER_KINDS[name].coupling == "tight" else 15
    per_run: dict[str, list[np.ndarray]] = {"forward": [], "smoothed": []}
    for seed in range(N_RUNS):
        tables, sensors = seoul(70.0, seed=2000 + seed, white_fixes=True)
        tables = without_gnss(tables, 35.0, 55.0)
        rng = np.random.default_rng(seed)
        start = drawn_start(tables["truth"], 1200, n, P0_SIGMA, rng)
        run = run_filter(tables, sensors, name, p, initial=start)
        sm = run.smoothed_run()
        assert sm is not None
        for label, r in (("forward", run), ("smoothed", sm)):
            inside, err, _ = error_states(r, tables["truth"])
            per_run[label].append(nees(err[:, :9], r.P[inside][:, :9, :9]))
    k = min(len(e) for e in per_run["smoothed"])
    avg = {label: np.mean([e[:k] for e in runs], axis=0) for label, runs in per_run.items()}
    lo = float(chi2.ppf(0.005, N_RUNS * 9)) / N_RUNS
    hi = float(chi2.ppf(0.995, N_RUNS * 9)) / N_RUNS
    assert np.mean((avg["smoothed"] >= lo) & (avg["smoothed"] <= hi)) >= 0.9
    ratio = avg["smoothed"].mean() / avg["forward"].mean()
    assert 0.8 <= ratio <= 1.05


def test_a_pool_too_small_is_grown_and_the_run_is_the_same(
    filters: FiltersParams, drive30: tuple[Tables, SensorMeta], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A UKF run records a prior and a cross covariance per stop: with a pool of 4 rows the
    run is repeated with a pool that holds them, never truncated."""
    tables, sensors = drive30
    p = smoothed(filters, "tc_ukf")
    whole = run_filter(tables, sensors, "tc_ukf", p)  # type: ignore[arg-type]

    def tiny(_smooth: bool, _kind: object, stops: np.ndarray, _n_out: int, n: int) -> object:
        return sk.allocate(len(stops) + 1, 4, n, nominal=False)

    monkeypatch.setattr(replay, "_smooth_log", tiny)
    grown = run_filter(tables, sensors, "tc_ukf", p)  # type: ignore[arg-type]
    assert whole.smoothed is not None
    assert grown.smoothed is not None
    assert np.array_equal(whole.smoothed[0], grown.smoothed[0])
    assert np.array_equal(whole.smoothed[1], grown.smoothed[1])


def test_a_run_that_never_aligned_says_its_smoothing_did_not_run(filters: FiltersParams) -> None:
    tables, sensors = seoul(20.0, seed=5, stationary_s=30.0)  # parked: no heading
    run = run_filter(tables, sensors, "lc_ekf", smoothed(filters, "lc_ekf"))  # type: ignore[arg-type]
    assert run.status == "not_aligned"
    assert run.smoothing is not None
    assert run.smoothing.status == "not_run"
    assert run.smoothed_run() is None


def test_an_unsmoothed_run_records_nothing_for_smoothing(
    filters: FiltersParams, drive30: tuple[Tables, SensorMeta]
) -> None:
    tables, sensors = drive30
    run = run_filter(tables, sensors, "lc_ekf", filters.get("lc_ekf"))
    assert run.smoothed is None
    assert run.smoothing is None
    assert run.smoothed_run() is None


def test_memory_is_a_small_state_per_stop_plus_covariances_between_outputs(
    filters: FiltersParams, drive30: tuple[Tables, SensorMeta]
) -> None:
    """The EKF keeps no covariance per stop (its priors are recomputed): what the backward
    pass needs is far less than the run's own output covariances."""
    tables, sensors = drive30
    run = run_filter(tables, sensors, "lc_ekf", smoothed(filters, "lc_ekf"))  # type: ignore[arg-type]
    assert run.smoothing is not None
    assert 0 < run.smoothing.memory_bytes < 0.5 * run.P.nbytes


@pytest.fixture(scope="module")
def tables_dir(
    tmp_path_factory: pytest.TempPathFactory, drive30: tuple[Tables, SensorMeta]
) -> Path:
    tables, sensors = drive30
    return write_tables(tmp_path_factory.mktemp("tables"), tables, "drive30", sensors)


def test_run_smooth_writes_smoothed_parquet_and_its_metrics(
    tables_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "run"
    argv = ["run", str(tables_dir), "--filter", "lc_ekf", "--smooth", "--out", str(out)]
    assert main(argv) == 0
    assert "smoothed: horizontal RMS" in capsys.readouterr().out
    estimate = read_table(out / "estimate.parquet", TableName.ESTIMATOR).table
    smooth = read_table(out / "smoothed.parquet", TableName.ESTIMATOR).table
    assert smooth.column_names == estimate.column_names
    assert smooth.num_rows == estimate.num_rows
    metrics = json.loads((out / "metrics.json").read_text())
    sm = metrics["smoothed"]
    assert sm["smoothing"]["status"] == "ok"
    assert sm["pos_err_h_rms_m"] < metrics["pos_err_h_rms_m"]


def test_run_smooth_of_a_vehicle_filter_is_a_clear_error(
    tables_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["run", str(tables_dir), "--filter", "vehicle_kinematic", "--smooth", "--out",
            str(tmp_path / "run")]  # fmt: skip
    assert main(argv) != 0
    assert "smoothing is for the INS/GNSS filters" in capsys.readouterr().err
    assert not (tmp_path / "run").exists()


def test_without_truth_the_smoothed_nominal_run_is_the_outage_reference(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A log without truth: the outage windows are measured against the smoothed nominal
    run (labelled ``smoothed_nominal``), and against the withheld fixes beside it; the
    nominal run is made for it though not asked for."""
    tables, sensors = seoul(90.0, seed=5)
    tables.pop("truth")
    tables_dir = write_tables(tmp_path / "tables", tables, "no_truth", sensors)
    data = short_window_scenarios(copy.deepcopy(read_yaml(REPO / "params.yaml")))
    params = tmp_path / "params.yaml"
    params.write_text(yaml.safe_dump(data))
    out = tmp_path / "run"
    argv = ["run", str(tables_dir), "--filter", "tc_ekf", "--scenario", "outage_60s",
            "--smooth", "--params", str(params), "--out", str(out)]  # fmt: skip
    assert main(argv) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    windows, by_fixes = metrics["outage_windows"], metrics["outage_windows_vs_fixes"]
    assert windows
    assert len(windows) == len(by_fixes)
    assert {w["reference"] for w in windows} == {"smoothed_nominal"}
    assert {w["reference"] for w in by_fixes} == {"withheld_fixes"}
    smoothed_windows = metrics["smoothed"]["outage_windows"]  # measured the same way
    assert {w["reference"] for w in smoothed_windows} == {"smoothed_nominal"}
    assert {w["reference"] for w in metrics["smoothed"]["outage_windows_vs_fixes"]} == {
        "withheld_fixes"
    }
    # the smoothed nominal run is a reference of decimetres: the drift it measures is the
    # filter's, which the withheld fixes' metre-level noise blurs
    for w, f in zip(windows, by_fixes, strict=True):
        assert w["err_end_m"] == pytest.approx(f["err_end_m"], abs=3.0)
    assert not (out.parent / "nominal").exists()


def test_a_report_shows_the_smoothed_run_beside_its_filter(tmp_path: Path) -> None:
    """``<filter> smoothed`` is a run of the report (metrics from ``smoothed``), listed but
    not among the filters that "held best"."""
    from navreplay.pipeline.report.inputs import load_runs

    tables, sensors = seoul(30.0, seed=5)
    tables_dir = write_tables(tmp_path / "tables", tables, "drive", sensors)
    out = tmp_path / "runs" / "lc_ekf"
    argv = ["-q", "run", str(tables_dir), "--filter", "lc_ekf", "--smooth", "--out", str(out)]
    assert main(argv) == 0
    runs = load_runs(tmp_path / "runs")
    assert [r.filter for r in runs] == ["lc_ekf", "lc_ekf smoothed"]
    forward, smooth = runs
    assert smooth.estimate is not None
    assert smooth.innovations is None
    metrics = json.loads((out / "metrics.json").read_text())
    assert smooth.metrics["pos_err_h_rms_m"] == metrics["smoothed"]["pos_err_h_rms_m"]
    assert forward.metrics["pos_err_h_rms_m"] == metrics["pos_err_h_rms_m"]
    assert "smoothed" not in smooth.metrics
