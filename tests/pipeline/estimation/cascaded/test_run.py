"""``navreplay run`` on a cascaded filter: the CSV recording through ingest and replay, the
run-directory contract, and the filter-family dispatch."""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from navreplay.ingest.schema import TableName
from navreplay.ingest.tables import read_table
from navreplay.pipeline.cli import main
from navreplay.pipeline.estimation.cascaded.backends import replay
from navreplay.pipeline.estimation.cascaded.config import CascadedFilterParams
from navreplay.pipeline.estimation.cascaded.engine import make_setup
from navreplay.pipeline.estimation.cascaded.inputs import prepare_inputs
from navreplay.pipeline.estimation.cascaded.outputs import STATE_COLUMNS
from navreplay.pipeline.estimation.families import FAMILIES, family_of
from navreplay.pipeline.synth.tractor import TractorStraightParams
from navreplay.pipeline.synth.tractor_log import synthesize, write
from tests.pipeline.estimation.cascaded.conftest import REPO


@pytest.fixture(scope="module")
def tables_dir(tmp_path_factory: pytest.TempPathFactory, sim_params: TractorStraightParams) -> Path:
    """A 10 s recording written as the dataset's CSV logs and ingested by its descriptor."""
    root = tmp_path_factory.mktemp("tractor")
    short = dataclasses.replace(sim_params, duration_s=10.0)
    write(short, 5, root / "raw")
    shutil.copy(REPO / "datasets" / "tractor_straight" / "dataset.yaml", root / "dataset.yaml")
    cfg = str(root / "dataset.yaml")
    assert main(["-q", "ingest", "--dataset-config", cfg, "--out", str(root / "tables")]) == 0
    return root / "tables"


def test_navreplay_run_writes_the_run_directory_contract(
    tables_dir: Path, tmp_path: Path, sim_params: TractorStraightParams,
    sections: dict[str, CascadedFilterParams],
) -> None:  # fmt: skip
    out = tmp_path / "run"
    assert (
        main(["-q", "run", str(tables_dir), "--filter", "cascaded_hybrid", "--out", str(out)]) == 0
    )
    est = read_table(out / "estimate.parquet", TableName.ESTIMATOR).table  # validated
    assert est.num_rows == 501
    for _, name, sigma in STATE_COLUMNS:
        assert name in est.column_names
        assert sigma in est.column_names
    streams = set(pq.read_table(out / "innovations.parquet").column("stream").to_pylist())
    assert streams == {"gnss_pos", "gnss_heading", "yaw_rate", "speed", "steer"}
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["filter"] == "cascaded_hybrid"
    assert metrics["status"] == "ok"
    assert metrics["pos_err_h_rms_m"] < 0.1
    assert set(metrics["bias_convergence_s"]) == {
        "radar_bias_mps", "gyro_bias_z_radps", "heading_bias_rad", "steer_bias_rad"}  # fmt: skip
    # the CSV round trip changes nothing: the same replay on the in-memory recording
    tables = dict(synthesize(dataclasses.replace(sim_params, duration_s=10.0), 5).tables)
    inp = prepare_inputs(tables, "cascaded_hybrid")
    ref = replay(make_setup("cascaded_hybrid", sections["cascaded_hybrid"]), inp.veh_t,
                 inp.veh, inp.gps_t, inp.gps, "numba")  # fmt: skip
    np.testing.assert_allclose(est.column("east_m").to_numpy(), ref.x[:, 0], atol=1e-6)
    np.testing.assert_allclose(est.column("steer_bias_rad").to_numpy(), ref.x[:, 11], atol=1e-9)


def test_the_dispatch_routes_each_family_to_its_own_runner() -> None:
    assert family_of("cascaded_ekf") is family_of("cascaded_hybrid")
    assert family_of("cascaded_ukf") is not family_of("lc_ekf")
    assert family_of("lc_ekf") is family_of("tc_ukf_nhc")
    assert family_of("vehicle_imm").name == "vehicle"
    assert [f.name for f in FAMILIES] == ["ins", "vehicle", "cascaded"]
    with pytest.raises(KeyError, match="cascaded_hybrid"):
        family_of("cascaded_pf")


def test_an_unknown_filter_is_a_params_error_naming_the_known_ones(
    tables_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["run", str(tables_dir), "--filter", "cascaded_pf", "--out", str(tmp_path)]) == 2
    assert "cascaded_ukf" in capsys.readouterr().err
