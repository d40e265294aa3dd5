"""``navreplay run``: tables and meta.json in, an atomic run directory out."""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
import yaml

from navreplay.ingest.meta import SensorMeta
from navreplay.ingest.tables import read_table
from navreplay.pipeline.cli import main
from navreplay.pipeline.params import read_yaml
from tests.pipeline.estimation.conftest import REPO
from tests.pipeline.scenarios.drives import write_tables


@pytest.fixture(scope="module")
def tables_dir(
    tmp_path_factory: pytest.TempPathFactory, drive60: tuple[dict[str, pa.Table], SensorMeta]
) -> Path:
    tables, sensors = drive60
    return write_tables(tmp_path_factory.mktemp("tables"), tables, "drive60", sensors)


def params_file(tmp_path: Path, edit: dict[str, Any]) -> Path:
    """The repository's params.yaml with ``filters.<name>.<section>.<key>`` values replaced."""
    data = copy.deepcopy(read_yaml(REPO / "params.yaml"))
    for dotted, value in edit.items():
        node = data
        *path, last = dotted.split(".")
        for key in path:
            node[key] = dict(node[key])  # YAML anchors share sub-mappings: copy before editing
            node = node[key]
        node[last] = value
    path_out = tmp_path / "params.yaml"
    path_out.write_text(yaml.safe_dump(data))
    return path_out


@pytest.mark.parametrize("name", ["lc_ekf_nhc", "tc_ukf"])
def test_run_writes_estimate_innovations_events_and_metrics(
    name: str, tables_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "run"
    assert main(["run", str(tables_dir), "--filter", name, "--out", str(out)]) == 0
    assert "horizontal RMS" in capsys.readouterr().out
    assert sorted(p.name for p in out.iterdir()) == [
        "estimate.parquet",
        "events.parquet",
        "innovations.parquet",
        "metrics.json",
        "trajectory.tum",
    ]
    est = read_table(out / "estimate.parquet", "estimator")
    assert est.provenance.extra["filter"] == name
    cols = est.table.column_names
    for col in ("lat_sigma_m", "vel_d_sigma_mps", "yaw_sigma_rad", "gyro_bias_z_sigma_radps"):
        assert col in cols
    assert ("clock_bias_m" in cols) == name.startswith("tc")
    assert np.all(np.diff(est.table.column("t_ns").to_numpy()) > 0)
    inn = pq.read_table(out / "innovations.parquet")
    streams = set(inn.column("stream").to_pylist())
    assert streams == ({"gnss_pos", "gnss_vel", "nhc"} if name.endswith("nhc") else {"gnss_obs"})
    m = json.loads((out / "metrics.json").read_text())
    assert m["status"] == "ok"
    assert m["pos_err_h_rms_m"] < 3.0  # sanity; the acceptance is on the full drive
    assert m["realtime_factor"] > 1.0
    assert m["gate_rejections"] == 0
    assert m["nees_dof"] == 9
    assert set(m["nis_mean"]) == streams
    assert m["scenario"] == "nominal"
    assert m["alignment"][0]["method"].startswith("gnss_velocity")


def test_filterpy_backend_from_the_command_line(tables_dir: Path, tmp_path: Path) -> None:
    a, b = tmp_path / "a", tmp_path / "b"
    assert main(["run", str(tables_dir), "--filter", "tc_ekf", "--out", str(a)]) == 0
    args = ["run", str(tables_dir), "--filter", "tc_ekf", "--backend", "filterpy"]
    assert main([*args, "--out", str(b)]) == 0
    ea = pq.read_table(a / "estimate.parquet")
    eb = pq.read_table(b / "estimate.parquet")
    np.testing.assert_allclose(
        ea.column("lat_deg").to_numpy(), eb.column("lat_deg").to_numpy(), rtol=0, atol=1e-12
    )
    assert json.loads((b / "metrics.json").read_text())["backend"] == "filterpy"


def test_divergence_is_an_error_and_nothing_is_written(
    tables_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    params = params_file(tmp_path, {"filters.lc_ekf.divergence.max_speed_mps": 5.0})
    out = tmp_path / "run"
    rc = main(["run", str(tables_dir), "--filter", "lc_ekf", "--params", str(params),
               "--out", str(out)])  # fmt: skip
    assert rc == 2
    assert "diverged" in capsys.readouterr().err
    assert not out.exists()


def test_flagged_divergence_keeps_the_output_up_to_it(tables_dir: Path, tmp_path: Path) -> None:
    params = params_file(
        tmp_path,
        {
            "filters.lc_ekf.divergence.max_speed_mps": 5.0,
            "filters.lc_ekf.divergence.on_divergence": "flag",
        },
    )
    out = tmp_path / "run"
    rc = main(["run", str(tables_dir), "--filter", "lc_ekf", "--params", str(params),
               "--out", str(out)])  # fmt: skip
    assert rc == 3  # written, and said: a diverged run is no answer
    m = json.loads((out / "metrics.json").read_text())
    assert m["status"] == "diverged"
    assert "beyond the divergence limits" in m["failure"]
    assert m["events"]["divergence"] == 1
    est = pq.read_table(out / "estimate.parquet")
    assert np.all(np.hypot(est.column("vel_n_mps"), est.column("vel_e_mps")) <= 5.0)


def test_unknown_filter_and_scenario_are_refused(
    tables_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "run"
    assert main(["run", str(tables_dir), "--filter", "lc_ukf", "--out", str(out)]) == 2
    assert "filters.lc_ukf" in capsys.readouterr().err
    rc = main(["run", str(tables_dir), "--filter", "lc_ekf", "--scenario", "no_such_scenario",
               "--out", str(out)])  # fmt: skip
    assert rc == 2
    assert "no_such_scenario" in capsys.readouterr().err
    assert not out.exists()


def test_missing_meta_json_names_the_fix(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rc = main(["run", str(tmp_path), "--filter", "lc_ekf", "--out", str(tmp_path / "run")])
    assert rc == 2
    assert "meta.json" in capsys.readouterr().err


def test_skip_unfit_marks_a_tight_filter_skipped_on_a_log_without_raw_observables(
    tables_dir: Path, tmp_path: Path
) -> None:
    loose_only = tmp_path / "tables"
    loose_only.mkdir()
    for p in tables_dir.iterdir():
        if p.name != "gnss_obs.parquet":
            (loose_only / p.name).write_bytes(p.read_bytes())
    out = tmp_path / "runs" / "tc_ukf"
    argv = ["-q", "run", str(loose_only), "--filter", "tc_ukf"]
    assert main([*argv, "--out", str(out), "--scenario", "all", "--skip-unfit"]) == 0
    scenarios = sorted(p.name for p in out.iterdir())
    assert scenarios == sorted(read_yaml(REPO / "params.yaml")["run"]["scenarios"])
    m = json.loads((out / "nominal" / "metrics.json").read_text())
    assert m["status"] == "skipped"
    assert "no raw GNSS observables" in m["reason"]
    assert list((out / "nominal").iterdir()) == [out / "nominal" / "metrics.json"]
    # without the flag the same request is an error, not a silent skip
    assert main([*argv, "--out", str(tmp_path / "strict")]) != 0
    assert not (tmp_path / "strict").exists()
