"""`navreplay run --scenario`, `navreplay montecarlo` and `navreplay outages` end to end on a
small drive, with params.yaml shrunk to fit it."""

from __future__ import annotations

import copy
import csv
import json
import shutil
from pathlib import Path

import pyarrow.parquet as pq
import pytest
import yaml

from navreplay.ingest.meta import DatasetMeta, read_meta, write_meta
from navreplay.ingest.tables import read_table
from navreplay.pipeline.cli import main
from navreplay.pipeline.outages.tables import SAT_REDUCTION_COLUMNS
from navreplay.pipeline.params import read_yaml
from tests.pipeline.scenarios.drives import REPO, drive, short_window_scenarios, write_tables


@pytest.fixture(scope="module")
def tables_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tables, sensors = drive(90.0)
    return write_tables(tmp_path_factory.mktemp("tables"), tables, "drive90", sensors)


@pytest.fixture(scope="module")
def params_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """params.yaml with the scenarios and the Monte Carlo sized for a 90 s drive."""
    data = short_window_scenarios(copy.deepcopy(read_yaml(REPO / "params.yaml")))
    for spec in data["scenarios"]["named"].values():
        for fault in spec.get("faults", []):
            fault["at_s"] = 40.0
    data["run"]["scenarios"] = ["nominal", "outage_60s", "sats_0", "sats_3", "f11_nan_field"]
    data["outages"] = dict(
        data["outages"],
        seeds=[1, 2],
        windows_per_seed=3,
        sats=[0, 3],
        sats_window_s=10.0,
        lengths_s=[5.0, 10.0],
        earliest_s=15.0,
        tail_s=5.0,
        workers=1,
        resamples=500,
        filters=["lc_ekf", "tc_ekf", "tc_ukf", "tc_ukf_nhc"],
    )
    path = tmp_path_factory.mktemp("params") / "params.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_run_all_scenarios_writes_one_run_per_scenario_with_its_windows(
    tables_dir: Path, params_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "tc_ukf"
    args = ["run", str(tables_dir), "--filter", "tc_ukf", "--params", str(params_file)]
    assert main([*args, "--scenario", "all", "--out", str(out)]) == 0
    assert sorted(p.name for p in out.iterdir()) == [
        "f11_nan_field",
        "nominal",
        "outage_60s",
        "sats_0",
        "sats_3",
    ]
    text = capsys.readouterr().out
    assert "2 outage windows" in text
    assert "fault criteria passed" in text
    m = json.loads((out / "sats_3" / "metrics.json").read_text())
    assert m["scenario"] == "sats_3"
    assert [w["sats"] for w in m["windows"]] == [3, 3]
    assert [w["kind"] for w in m["outage_windows"]] == ["partial", "partial"]
    assert all(w["err_end_m"] is not None for w in m["outage_windows"])
    assert len(m["scenario_detail"]["selections"][0]["svs"]) == 3
    est = read_table(out / "sats_3" / "estimate.parquet", "estimator")
    assert json.loads(est.provenance.extra["scenario_windows"]) == m["windows"]
    f11 = json.loads((out / "f11_nan_field" / "metrics.json").read_text())
    assert f11["fault_checks_passed"] is True
    assert {c["criterion"] for c in f11["fault_checks"]} == {
        "state and covariance finite",
        "added skips",
    }
    nominal = json.loads((out / "nominal" / "metrics.json").read_text())
    assert nominal["windows"] == []
    assert "outage_windows" not in nominal
    # every field issue 6 lists
    for key in RUN_FIELDS:
        assert m[key] is not None, key
    assert all(s["nis_mean"] > 0 for s in m["nis"].values())
    assert set(m["nis"]) == {"gnss_obs"}
    for w in m["outage_windows"]:
        assert set(WINDOW_FIELDS) <= set(w)
    # keeping no satellite is the complete outage: replayed once, measured the same
    sats0 = json.loads((out / "sats_0" / "metrics.json").read_text())
    complete = json.loads((out / "outage_60s" / "metrics.json").read_text())
    assert sats0["outage_windows"] == complete["outage_windows"]
    assert sats0["pos_err_3d_rms_m"] == complete["pos_err_3d_rms_m"]


RUN_FIELDS = (
    "pos_err_h_rms_m",
    "pos_err_3d_rms_m",
    "pos_err_3d_max_m",
    "nees_mean",
    "nis_mean",
    "gate_rejections",
    "runtime_s",
    "realtime_factor",
)
WINDOW_FIELDS = (
    "start_s",
    "duration_s",
    "sats",
    "err_end_m",
    "err_max_m",
    "err_rms_m",
    "drift_pct_distance",
    "reconverge_s",
)


def test_one_scenario_writes_the_run_directory_itself(
    tables_dir: Path, params_file: Path, tmp_path: Path
) -> None:
    out = tmp_path / "run"
    args = ["run", str(tables_dir), "--filter", "lc_ekf", "--params", str(params_file)]
    assert main([*args, "--scenario", "outage_60s", "--out", str(out)]) == 0
    assert (out / "metrics.json").is_file()
    assert main([*args, "--scenario", "nope", "--out", str(tmp_path / "x")]) == 2
    assert not (tmp_path / "x").exists()


def test_montecarlo_and_outages_write_the_reduction_and_drift_tables(
    tables_dir: Path, params_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    mc = tmp_path / "montecarlo"
    for name in ("lc_ekf", "tc_ekf", "tc_ukf", "tc_ukf_nhc"):
        args = ["montecarlo", str(tables_dir), "--filter", name, "--params", str(params_file)]
        assert main([*args, "--out", str(mc / name)]) == 0
    windows = pq.read_table(mc / "tc_ukf" / "windows.parquet")
    assert windows.num_rows == 6 * 3  # 6 starts x (5 s, 10 s, 10 s with 3 satellites)
    assert "replay_s" not in windows.column_names  # timing lives in timing.json
    assert json.loads((mc / "tc_ukf" / "plan.json").read_text())["diverged"] == 0
    out = tmp_path / "experiments"
    args = ["outages", str(mc), "--tables", str(tables_dir), "--params", str(params_file)]
    assert main([*args, "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "paper %" in text
    assert "54.4" in text
    with (out / "sat_reduction.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert tuple(rows[0]) == SAT_REDUCTION_COLUMNS
    assert [(r["pair"], r["sats"]) for r in rows] == [
        (p, k)
        for p in ("tc_ukf->tc_ukf_nhc", "tc_ekf->tc_ukf", "lc_ekf->tc_ukf_nhc")
        for k in ("0", "3")
    ]
    doc = json.loads((out / "sat_reduction.json").read_text())
    assert doc["rows"][0]["windows"] == 6
    assert doc["paper_comparison"]["per_sats"][0]["paper_pct"] == 54.4
    drift = json.loads((out / "drift_vs_length.json").read_text())["rows"]
    assert [(r["filter"], r["length_s"]) for r in drift][:2] == [("lc_ekf", 5.0), ("lc_ekf", 10.0)]
    md = (out / "sat_reduction_vs_paper.md").read_text()
    assert "paper 001" in md
    # the comparison is computed from the rows, not written in advance
    cmp = doc["paper_comparison"]["per_sats"]
    k0 = cmp[0]
    assert f"| 0 | {k0['ours_pct']:.1f} |" in md
    inside = [str(r["sats"]) for r in cmp if r["paper_inside_ci"]]
    assert f"interval for k = {', '.join(inside) or 'none'} " in md


def test_outage_experiments_on_a_log_without_raw_observables(
    tables_dir: Path, params_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """With --skip-unfit the tightly coupled filters' Monte Carlo cells record why they did
    not run, and the outage tables keep what loose coupling can say (its drift), leaving the
    pairs that need a skipped filter out, with the reason in the JSON."""
    fixes_only = tmp_path / "tables"
    fixes_only.mkdir()
    rows = {}
    meta = read_meta(tables_dir)
    for name in ("imu", "gnss", "truth"):
        shutil.copy2(tables_dir / f"{name}.parquet", fixes_only / f"{name}.parquet")
        rows[name] = meta.tables[name]
    write_meta(fixes_only, DatasetMeta("drive90_fixes", "gps", (), rows, sensors=meta.sensors))
    mc = tmp_path / "montecarlo"
    for name in ("lc_ekf", "tc_ekf", "tc_ukf", "tc_ukf_nhc"):
        args = ["montecarlo", str(fixes_only), "--filter", name, "--params", str(params_file)]
        assert main([*args, "--out", str(mc / name), "--skip-unfit"]) == 0
    assert (mc / "lc_ekf" / "windows.parquet").is_file()
    skipped = json.loads((mc / "tc_ukf" / "skipped.json").read_text())
    assert skipped["status"] == "skipped"
    assert "gnss_obs" in skipped["reason"] or "pseudoranges" in skipped["reason"]
    assert not (mc / "tc_ukf" / "windows.parquet").exists()
    out = tmp_path / "experiments"
    args = ["outages", str(mc), "--tables", str(fixes_only), "--params", str(params_file)]
    assert main([*args, "--out", str(out)]) == 0
    assert "tc_ukf skipped" in capsys.readouterr().out
    doc = json.loads((out / "sat_reduction.json").read_text())
    assert doc["rows"] == []  # every default pair needs a tightly coupled filter
    assert set(doc["skipped"]) == {"tc_ekf", "tc_ukf", "tc_ukf_nhc"}
    drift = json.loads((out / "drift_vs_length.json").read_text())["rows"]
    assert {r["filter"] for r in drift} == {"lc_ekf"}
    assert all(r["windows"] == 6 for r in drift)
    note = (out / "sat_reduction_vs_paper.md").read_text()
    assert "No pair of `outages.pairs` could run" in note
    assert f"- tc_ukf: {skipped['reason']}" in note
