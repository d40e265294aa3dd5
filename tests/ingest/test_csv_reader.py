"""CSV/text logs mapped by dataset.yaml (catalogue cases 18, 19, 21) and real CSV data."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.parquet as pq
import pytest

from navreplay.ingest.api import IngestOptions, ingest
from navreplay.ingest.config import DatasetConfig, parse_dataset_config
from navreplay.ingest.errors import CorruptLogError, UnsupportedFormatError

from .commacsv import DERIVED, fix_mapping

WHEEL = {"speed_mps": "v", "yaw_rate_radps": "r"}


def _config(path: str = "wheel.csv", **extra: object) -> DatasetConfig:
    src: dict[str, object] = {
        "path": path,
        "table": "vehicle",
        "time_column": "t",
        "time_unit": "s",
        "columns": WHEEL,
    }
    src.update(extra)
    return parse_dataset_config({"id": "csv_test", "csv": [src]})


def _lines(n: int, t0: float = 1000.0) -> list[str]:
    return [f"{t0 + 0.01 * i:.2f},{1.0 + 0.001 * i:.3f},{0.01 * i:.2f}" for i in range(n)]


def _run(tmp_path: Path, text: str, **kw: Any) -> tuple[dict[str, Any], Path]:
    path = tmp_path / "wheel.csv"
    path.write_text(text)
    out = tmp_path / "out"
    result = ingest([path], out, config=_config(), config_dir=tmp_path, **kw)
    return result.report, out


def test_mapped_columns_round_trip_with_exact_times(tmp_path: Path) -> None:
    text = "t,v,r\n" + "\n".join(_lines(50, t0=1_700_000_000.0)) + "\n"
    report, out = _run(tmp_path, text)
    table = pq.read_table(out / "vehicle.parquet")
    t = table["t_ns"].to_numpy()
    # Decimal seconds -> int64 ns without float rounding, even for epoch-sized values.
    assert t[1] - t[0] == 10_000_000
    assert t[0] == 1_700_000_000 * 10**9
    np.testing.assert_allclose(table["speed_mps"].to_numpy()[:3], [1.0, 1.001, 1.002])
    assert report["files"][0]["completeness"] == ["complete"]


def test_truncated_last_line_is_dropped_and_reported(tmp_path: Path) -> None:
    # Case 18: the final newline and the last digit are missing.
    lines = _lines(20)
    text = "t,v,r\n" + "\n".join(lines)[:-1]
    report, out = _run(tmp_path, text)
    assert pq.read_table(out / "vehicle.parquet").num_rows == 19
    (f,) = report["files"]
    assert f["completeness"] == ["partial_record_dropped"]
    assert f["defects"][0]["offset"] == 21  # the line number
    with pytest.raises(CorruptLogError, match="line 21"):
        _run(tmp_path, text, options=IngestOptions(strict=True))


def test_garbage_lines_and_repeated_headers_are_skipped_with_line_numbers(
    tmp_path: Path,
) -> None:
    # Case 19: a reboot marker, a line of the wrong width, ERR in a number, a repeated header.
    lines = _lines(30)
    lines.insert(5, "#### reboot ####")
    lines.insert(10, "reboot")
    lines[15] = lines[15].replace(lines[15].split(",")[1], "ERR")
    lines.insert(20, "t,v,r")
    report, out = _run(tmp_path, "t,v,r\n" + "\n".join(lines) + "\n")
    assert pq.read_table(out / "vehicle.parquet").num_rows == 30 - 1
    (f,) = report["files"]
    assert f["counters"]["comment_lines"] == 1
    assert f["counters"]["repeated_header_lines"] == 1
    (defect,) = f["defects"]
    assert defect["kind"] == "bad_data_skipped"
    assert "2 malformed lines" in defect["reason"]
    assert "line 12" in defect["reason"]  # header is line 1: inserted "reboot" is line 12
    assert "lines 12, 17" in defect["reason"]
    assert f["notes"] == ["repeated header lines skipped at lines 22"]


def test_ambiguous_duplicate_header_is_fatal_with_line_and_column(tmp_path: Path) -> None:
    path = tmp_path / "wheel.csv"
    path.write_text("t,v,v\n" + "\n".join(_lines(5)) + "\n")
    with pytest.raises(CorruptLogError) as err:
        ingest([path], tmp_path / "out", config=_config(), config_dir=tmp_path)
    assert "line 1" in str(err.value)
    assert "'v'" in str(err.value)
    assert not (tmp_path / "out").exists()


def test_nan_and_inf_literals_stay_nan_and_empty_cells_are_null(tmp_path: Path) -> None:
    # Case 21 in CSV: pyarrow's reader would turn NaN into null; here invalid stays NaN.
    lines = _lines(10)
    lines[2] = "1000.02,NaN,0.1"
    lines[4] = "1000.04,inf,0.1"
    lines[6] = "1000.06,-Infinity,0.1"
    lines[8] = "1000.08,1.5,"
    report, out = _run(tmp_path, "t,v,r\n" + "\n".join(lines) + "\n")
    table = pq.read_table(out / "vehicle.parquet")
    speed = table["speed_mps"]
    assert speed.null_count == 0
    assert np.isnan(speed.to_numpy()[[2, 4, 6]]).all()
    assert table["yaw_rate_radps"].null_count == 1
    stats = report["tables"]["vehicle"]["stats"]
    assert stats["nonfinite"]["speed_mps"] == {"nan": 1, "inf": 2}


def test_unmapped_csv_is_refused_with_a_hint(tmp_path: Path) -> None:
    path = tmp_path / "x.csv"
    path.write_text("a,b\n1,2\n")
    with pytest.raises(UnsupportedFormatError, match="csv:"):
        ingest([path], tmp_path / "out")


def test_csv_with_canonical_header_needs_no_mapping(tmp_path: Path) -> None:
    path = tmp_path / "vehicle.csv"
    path.write_text("t_ns,speed_mps,yaw_rate_radps\n1000,1.0,0.1\n2000,1.1,0.2\n")
    result = ingest([path], tmp_path / "out")
    assert result.tables == {"vehicle": 2}


def test_comma2k19_csv_drive_ingests(tmp_path: Path) -> None:
    if not DERIVED.is_dir():
        pytest.skip(f"shared data not present at {DERIVED}")
    frd = {
        f"{k}_{a}_{u}": f"{k}_{b}_{u}"
        for k, u in (("acc", "mps2"), ("gyro", "radps"))
        for a, b in (("x", "fwd"), ("y", "right"), ("z", "down"))
    }
    cfg = parse_dataset_config(
        {
            "id": "comma2k19",
            "csv": [
                {
                    "path": "imu.csv",
                    "table": "imu",
                    "time_column": "t_boot_s",
                    "time_unit": "s",
                    "columns": frd,
                },
                fix_mapping("ublox"),
            ],
        }
    )
    result = ingest(
        [DERIVED / "imu.csv", DERIVED / "gnss_fix_ublox.csv"],
        tmp_path / "out",
        config=cfg,
        config_dir=DERIVED,
    )
    assert result.tables == {"imu": 6256, "gnss": 579}
    tables = result.report["tables"]
    assert tables["imu"]["stats"]["rate_hz"] == pytest.approx(104.4, abs=0.5)
    assert tables["gnss"]["stats"]["rate_hz"] == pytest.approx(10.0, abs=0.3)
    assert result.report["time_base"]["base"] == "recorder"
    imu = pq.read_table(tmp_path / "out" / "imu.parquet")
    # FRD already: gravity on -z, no mounting needed for a car-mounted phone this level.
    assert imu["acc_z_mps2"].to_numpy().mean() == pytest.approx(-9.66, abs=0.1)
    assert tables["imu"]["plausibility"]["mounting"]["source"] == "none"
    gnss = pq.read_table(tmp_path / "out" / "gnss.parquet")
    lat = gnss["lat_deg"].to_numpy()
    assert 37.72 < lat.min() < lat.max() < 37.731
    assert not math.isnan(gnss["alt_m"].to_numpy().mean())
