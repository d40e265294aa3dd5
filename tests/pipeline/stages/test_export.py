"""``navreplay export``: a table as the flat CSV PlotJuggler opens, or a TUM trajectory."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from navreplay.ingest.schema import from_columns
from navreplay.ingest.tables import Provenance, write_table
from navreplay.pipeline.cli import main

T0 = 1_372_669_956_358_514_000  # GPS ns of 2023: beyond float64's exact integers


def _truth(path: Path, n: int = 5) -> Path:
    table = from_columns("truth", {
        "t_ns": T0 + np.arange(n, dtype=np.int64) * 100_000_000,
        "lat_deg": np.linspace(52.0, 52.001, n), "lon_deg": np.full(n, -4.1),
        "alt_m": np.full(n, 100.0), "yaw_rad": np.full(n, 0.5),
    })  # fmt: skip
    write_table(path, "truth", table, Provenance.create("truth"))
    return path


def test_csv_has_time_s_first_and_every_column_as_stored(tmp_path: Path) -> None:
    src = _truth(tmp_path / "truth.parquet")
    assert main(["export", str(src), "--csv", str(tmp_path / "t.csv")]) == 0
    header = (tmp_path / "t.csv").read_text().splitlines()[0]
    assert header.startswith("time_s,t_ns,lat_deg,lon_deg,alt_m")  # unquoted names
    frame = pd.read_csv(tmp_path / "t.csv")
    assert frame["t_ns"].tolist() == [T0 + i * 100_000_000 for i in range(5)]  # exact
    np.testing.assert_allclose(frame["time_s"], frame["t_ns"] / 1e9, rtol=0, atol=1e-6)
    np.testing.assert_allclose(frame["lat_deg"], np.linspace(52.0, 52.001, 5), rtol=1e-15)
    assert frame["vel_n_mps"].isna().all()  # a null stays empty


def test_text_columns_survive_commas_and_quotes(tmp_path: Path) -> None:
    table = from_columns("events", {
        "t_ns": np.array([T0, T0], np.int64), "seq": [0, 1], "kind": ["message"] * 2,
        "severity": [4, None], "text": ['PreArm: "GPS", 3D fix', "ok"], "source": ["MSG"] * 2,
    })  # fmt: skip
    src = tmp_path / "events.parquet"
    write_table(src, "events", table, Provenance.create("events"))
    assert main(["export", str(src), "--csv", str(tmp_path / "e.csv")]) == 0
    frame = pd.read_csv(tmp_path / "e.csv")
    assert frame["text"].tolist() == ['PreArm: "GPS", 3D fix', "ok"]
    assert frame["severity"].isna().tolist() == [False, True]


def test_tum_of_a_solution_and_refusals(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    src = _truth(tmp_path / "truth.parquet")
    assert main(["export", str(src), "--tum", str(tmp_path / "t.tum")]) == 0
    lines = [ln for ln in (tmp_path / "t.tum").read_text().splitlines() if not ln.startswith("#")]
    assert len(lines) == 5
    # an existing output is kept unless --force
    before = (tmp_path / "t.tum").read_bytes()
    assert main(["export", str(src), "--tum", str(tmp_path / "t.tum")]) == 2
    assert "exists" in capsys.readouterr().err
    assert (tmp_path / "t.tum").read_bytes() == before
    # a table without a position is not a trajectory; a missing file is named
    events = tmp_path / "events.parquet"
    write_table(events, "events", from_columns("events", {
        "t_ns": np.array([T0], np.int64), "seq": [0], "kind": ["mode"], "text": ["AUTO"],
        "source": ["MODE"]}), Provenance.create("events"))  # fmt: skip
    assert main(["export", str(events), "--tum", str(tmp_path / "e.tum")]) == 2
    assert "not a navigation solution" in capsys.readouterr().err
    assert not (tmp_path / "e.tum").exists()
    assert main(["export", str(tmp_path / "nope.parquet"), "--csv", str(tmp_path / "n.csv")]) == 2
    assert "nope.parquet: no such file" in capsys.readouterr().err
