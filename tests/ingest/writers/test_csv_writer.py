"""CSV log writer: deterministic text that parsers read back exactly."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from navreplay.ingest.errors import IngestError
from navreplay.ingest.writers.csv import CsvColumn, quantize, write_csv


def test_written_columns_read_back_with_pandas_as_quantize_predicts(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    x = rng.normal(0.0, 100.0, 500)
    t = np.arange(500, dtype=np.int64) * 20_000 + 1_795_338_000_000_000
    path = tmp_path / "log.csv"
    write_csv(
        path,
        [
            CsvColumn("time_us", t, "%d"),
            CsvColumn("x", x, "%.6f"),
            CsvColumn("nan", x * np.nan, "%.3f"),
        ],
        comment="two\nlines",
    )
    df = pd.read_csv(path, comment="#")
    assert list(df.columns) == ["time_us", "x", "nan"]
    np.testing.assert_array_equal(df["time_us"].to_numpy(), t)
    np.testing.assert_array_equal(df["x"].to_numpy(), quantize(x, "%.6f"))
    assert np.abs(quantize(x, "%.6f") - x).max() <= 5e-7
    assert df["nan"].isna().all()
    assert path.read_text().startswith("# two")


def test_output_is_byte_identical_for_identical_input(tmp_path: Path) -> None:
    cols = [CsvColumn("a", np.linspace(0, 1, 11), "%.3f")]
    write_csv(tmp_path / "1.csv", cols)
    write_csv(tmp_path / "2.csv", cols)
    assert (tmp_path / "1.csv").read_bytes() == (tmp_path / "2.csv").read_bytes()
    assert (tmp_path / "1.csv").read_text().splitlines()[:3] == ["a", "0.000", "0.100"]


def test_ragged_columns_and_bad_names_are_refused(tmp_path: Path) -> None:
    with pytest.raises(IngestError, match="different lengths"):
        write_csv(
            tmp_path / "x.csv",
            [CsvColumn("a", np.zeros(2), "%f"), CsvColumn("b", np.zeros(3), "%f")],
        )
    with pytest.raises(IngestError, match="separator"):
        write_csv(tmp_path / "x.csv", [CsvColumn("a,b", np.zeros(2), "%f")])
    assert not (tmp_path / "x.csv").exists()
