"""Defects a first fuzzing pass over the readers found (issue 23), each pinned by a test:
a log concatenated with itself, an IMU table of NaN, bit flips in a format without checksums,
a units heuristic misled by a short log, and corrupt text headers reported as "unrecognised
content at offset 0". The output-folder defects are in ``test_output_folder``."""

from __future__ import annotations

from pathlib import Path

import pytest

from navreplay.ingest.api import IngestOptions, ingest
from navreplay.ingest.errors import CorruptLogError, PlausibilityError, UnsupportedFormatError

from .fuzzseeds import SEEDS

pytestmark = pytest.mark.filterwarnings("ignore")


# ------------------------------------------------------------------ 3: a log twice in one file
@pytest.mark.parametrize("fmt", ["tlog", "dataflash", "csv", "nmea", "rinex_obs"])
def test_a_log_concatenated_with_itself_is_a_dropped_copy_not_a_reboot(
    tmp_path: Path, fmt: str
) -> None:
    seed = SEEDS[fmt](tmp_path)
    once = ingest(list(seed.logs), tmp_path / "once")
    size = seed.target.stat().st_size
    seed.target.write_bytes(seed.target.read_bytes() * 2)
    twice = ingest(list(seed.logs), tmp_path / "twice")
    assert twice.tables == once.tables  # the copy adds no rows and no second segment
    entry = next(f for f in twice.report["files"] if f["name"] == seed.target.name)
    assert "duplicated_copy_dropped" in entry["completeness"]
    (defect,) = (d for d in entry["defects"] if d["kind"] == "duplicated_copy_dropped")
    text_format = fmt in ("csv", "nmea", "rinex_obs")
    if not text_format:  # the copy's first rows lie past the original's end (and its FMTs)
        assert size <= defect["offset"] < size + 1000
    assert "duplicated copy" in defect["reason"]
    assert any("duplicated copy" in w and seed.target.name in w for w in twice.report["warnings"])
    for table in twice.report["tables"].values():
        assert table["hygiene"]["clock_steps_backward"] == []
        assert table["stats"]["duration_s"] < 30  # no segment appended minutes later
    # --strict refuses it (RINEX first meets the copy's header lines: text outside any epoch)
    first = "text outside any epoch" if fmt == "rinex_obs" else "duplicated copy"
    with pytest.raises(CorruptLogError, match=first):
        ingest(list(seed.logs), tmp_path / "strict", options=IngestOptions(strict=True))


def test_a_real_clock_step_with_other_values_is_still_a_step(tmp_path: Path) -> None:
    seed = SEEDS["csv"](tmp_path)
    header, *rows = seed.target.read_text().splitlines()
    again = [f"{r},".rsplit(",", 2)[0] + ",0.0123" for r in rows]  # same times, other gyro_z
    seed.target.write_text("\n".join([header, *rows, *again]) + "\n")
    result = ingest(list(seed.logs), tmp_path / "out")
    (step,) = result.report["tables"]["imu"]["hygiene"]["clock_steps_backward"]
    assert step["step_s"] < 0
    assert result.report["tables"]["imu"]["hygiene"]["duplicated_copies"] == []
    assert result.tables["imu"] == 2 * len(rows)


# ------------------------------------------- 7: a damaged text line is named, not "offset 0"
def test_a_corrupt_rinex_nav_body_names_the_bad_line(tmp_path: Path) -> None:
    seed = SEEDS["rinex_nav"](tmp_path)
    lines = seed.target.read_bytes().split(b"\n")
    lines[30] = lines[30][:20] + b"\xff\x00" + lines[30][22:]  # invalid UTF-8 and a NUL
    seed.target.write_bytes(b"\n".join(lines))
    result = ingest(list(seed.logs), tmp_path / "out")
    nav = next(f for f in result.report["files"] if f["name"] == "drive.nav")
    assert nav["completeness"] == ["bad_data_skipped"]
    (defect,) = nav["defects"]
    assert defect["offset"] == 31
    assert "line 31" in defect["reason"]
    assert result.tables["gnss_obs"] > 0  # the other records still give every orbit


def test_a_zeroed_block_in_a_rinex_nav_body_is_salvaged(tmp_path: Path) -> None:
    seed = SEEDS["rinex_nav"](tmp_path)
    data = bytearray(seed.target.read_bytes())
    at = data.index(b"END OF HEADER") + 2000
    data[at : at + 300] = bytes(300)
    seed.target.write_bytes(bytes(data))
    result = ingest(list(seed.logs), tmp_path / "out")
    nav = next(f for f in result.report["files"] if f["name"] == "drive.nav")
    assert nav["completeness"] == ["bad_data_skipped"]
    assert all("line" in d["reason"] for d in nav["defects"])


def test_a_corrupt_csv_header_names_the_line_and_the_missing_columns(tmp_path: Path) -> None:
    seed = SEEDS["csv"](tmp_path)
    data = bytearray(seed.target.read_bytes())
    data[data.index(b"acc_y_mps2") + 2] ^= 0x80  # a bit flip: not UTF-8 any more
    seed.target.write_bytes(bytes(data))
    with pytest.raises(UnsupportedFormatError) as err:
        ingest(list(seed.logs), tmp_path / "out")
    assert err.value.record == "line 1"
    assert "lacks acc_y_mps2" in str(err.value)
    assert "table imu" in str(err.value)
    assert "unrecognised content" not in str(err.value)


def test_a_csv_header_unlike_any_table_lists_it(tmp_path: Path) -> None:
    path = tmp_path / "wheel.csv"
    path.write_text("time,left,right\n0.1,1,2\n0.2,1,2\n")
    with pytest.raises(UnsupportedFormatError, match="no column mapping") as err:
        ingest([path], tmp_path / "out")
    assert "header: time, left, right" in str(err.value)
    assert err.value.record == "line 1"


def test_a_damaged_first_rinex_line_is_named(tmp_path: Path) -> None:
    seed = SEEDS["rinex_obs"](tmp_path)
    data = bytearray(seed.target.read_bytes())
    data[65] ^= 0x01  # inside "RINEX VERSION / TYPE"
    seed.target.write_bytes(bytes(data))
    with pytest.raises(CorruptLogError, match="not a valid 'RINEX VERSION / TYPE' line") as err:
        ingest(list(seed.logs), tmp_path / "out")
    assert err.value.record == "line 1"
    assert str(seed.target) in str(err.value)


# ------------------------------------------------------------------ 4: an IMU table of NaN
def _imu_csv(path: Path, rows: list[str]) -> Path:
    header = "t_ns,acc_x_mps2,acc_y_mps2,acc_z_mps2,gyro_x_radps,gyro_y_radps,gyro_z_radps"
    path.write_text("\n".join([header, *rows]) + "\n")
    return path


def test_an_imu_table_of_nan_is_refused_at_ingest(tmp_path: Path) -> None:
    t0 = 1_700_000_000 * 10**9
    rows = [f"{t0 + i * 10_000_000},nan,nan,nan,nan,nan,nan" for i in range(300)]
    log = _imu_csv(tmp_path / "imu.csv", rows)
    with pytest.raises(PlausibilityError, match="every one of the 300 imu rows has NaN") as err:
        ingest([log], tmp_path / "out")
    assert str(log) in str(err.value)
    assert "no filter can run" in str(err.value)
    assert not (tmp_path / "out").exists()


def test_a_mostly_nan_imu_table_is_kept_with_a_counted_warning(tmp_path: Path) -> None:
    t0 = 1_700_000_000 * 10**9
    rows = []
    for i in range(300):
        values = "0.01,-0.02,-9.81,0.001,0.0,-0.001" if i % 4 == 0 else "nan,0,-9.81,0,0,0"
        rows.append(f"{t0 + i * 10_000_000},{values}")
    result = ingest([_imu_csv(tmp_path / "imu.csv", rows)], tmp_path / "out")
    assert result.tables["imu"] == 300  # NaN stays NaN (catalogue case 21), counted
    (warning,) = [w for w in result.report["warnings"] if "NaN or inf" in w]
    assert "225 of 300 rows (75 %)" in warning
