"""Defects a first fuzzing pass over the readers found (issue 23), each pinned by a test:
a log concatenated with itself, an IMU table of NaN, bit flips in a format without checksums,
a units heuristic misled by a short log, and corrupt text headers reported as "unrecognised
content at offset 0". The output-folder defects are in ``test_output_folder``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from navreplay.ingest.api import UNVERIFIED, IngestOptions, ingest
from navreplay.ingest.errors import CorruptLogError, PlausibilityError, UnsupportedFormatError

from .fuzzseeds import SEEDS
from .mavlogs import UTC0_US, G, UlogLog
from .test_tlog_faults import highres_log

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


def test_a_real_ulog_twice_in_one_file_reads_once(tmp_path: Path) -> None:
    # pyulog resynchronises after the copy's header and loses the copy's first messages: the
    # copy is still recognised (its rows repeat rows of the log's start, not its first row).
    real = Path(__file__).resolve().parents[3] / "shared" / "data" / "pyulog_samples"
    src = real / "sample_log_small.ulg"
    if not src.is_file():
        pytest.skip(f"real data not present: {src} (../shared/data is read in place)")
    once = ingest([src], tmp_path / "once")
    log = tmp_path / "twice.ulg"
    log.write_bytes(src.read_bytes() * 2)
    twice = ingest([log], tmp_path / "twice")
    assert twice.tables == once.tables
    (entry,) = twice.report["files"]
    assert "duplicated_copy_dropped" in entry["completeness"]
    (defect,) = (d for d in entry["defects"] if d["kind"] == "duplicated_copy_dropped")
    assert "offset" not in defect  # pyulog gives no record offsets: none is made up
    assert "at an offset the reader does not give" in defect["reason"]


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


# ------------------------------------------ 5: bit flips in a format that has no checksums
def _ulog_with(tmp_path: Path, gyro_at: dict[int, float]) -> Path:
    """The ULog seed with some samples' gyro x replaced (what a flipped exponent bit does)."""
    ulog = UlogLog()
    ulog.format(
        "sensor_combined",
        "uint64_t timestamp;float[3] gyro_rad;float[3] accelerometer_m_s2;",
        "Q3f3f",
    )
    ulog.subscribe("sensor_combined")
    rng = np.random.default_rng(3)
    for i in range(400):
        gyro = rng.normal(0, 1e-3, 3)
        gyro[0] = gyro_at.get(i, gyro[0])
        acc = np.array([0.0, 0.0, -9.80665]) + rng.normal(0, 0.02, 3)
        ulog.data("sensor_combined", 10_000_000 + i * 5000, *gyro, *acc)
    path = tmp_path / "flight.ulg"
    path.write_bytes(ulog.bytes())
    return path


def test_every_file_says_whether_its_format_could_be_verified(tmp_path: Path) -> None:
    for fmt, verified in (("ulog", False), ("dataflash", False), ("csv", False), ("tlog", True)):
        (tmp_path / fmt).mkdir()
        seed = SEEDS[fmt](tmp_path / fmt)
        (entry,) = ingest(list(seed.logs), tmp_path / fmt / "out").report["files"]
        assert entry["verification"].startswith("unverified") is not verified, fmt
    assert "bit errors change values undetected" in UNVERIFIED


def test_a_ulog_value_flipped_beyond_physical_limits_is_counted_and_flagged(
    tmp_path: Path,
) -> None:
    # A flipped exponent bit made one rate 1e34 rad/s: before, the file was "complete" (or the
    # units check blamed deg/s); now the value is counted, flagged and kept out of decisions.
    log = _ulog_with(tmp_path, {57: 9.9e34, 300: -3.0e12})
    result = ingest([log], tmp_path / "out")
    (entry,) = result.report["files"]
    assert entry["completeness"] == ["implausible_values"]
    assert entry["verification"].startswith("unverified")
    imu = result.report["tables"]["imu"]
    assert imu["stats"]["implausible"] == {"gyro_x_radps": {"count": 2, "limit_abs": 100.0}}
    assert imu["plausibility"]["implausible_samples_ignored"] == 2
    (warning,) = [w for w in result.report["warnings"] if "physical limits" in w]
    assert "no checksums" in warning
    assert result.tables["imu"] == 400  # kept as they are: the report says where to look


def test_a_plausible_ulog_flip_leaves_the_file_unverified_not_complete_and_sure(
    tmp_path: Path,
) -> None:
    log = _ulog_with(tmp_path, {57: 0.5})  # wrong but within limits: nothing can tell
    (entry,) = ingest([log], tmp_path / "out").report["files"]
    assert entry["completeness"] == ["complete"]
    assert entry["verification"] == UNVERIFIED


# --------------------------- 6: a units heuristic misled by a truncated or turning log
def _standing_then_turning(tmp_path: Path, *, yaw_at_rest: float, turn_s: float) -> Path:
    """HIGHRES_IMU at 100 Hz: 10 s level at rest (yawing at ``yaw_at_rest`` rad/s, as a SITL
    vehicle spinning on the ground does), then a steady 19 deg banked turn at 0.2 rad/s."""
    rng = np.random.default_rng(8)
    n_rest, n_turn = 1000, round(turn_s * 100)
    bank = np.radians(19.0)
    acc = np.vstack(
        [np.tile([0.0, 0.0, -G], (n_rest, 1)), np.tile([0.0, 0.0, -G / np.cos(bank)], (n_turn, 1))]
    ) + rng.normal(0, 0.02, (n_rest + n_turn, 3))
    gyro = np.vstack(
        [
            np.tile([0.0, 0.0, yaw_at_rest], (n_rest, 1)),
            np.tile([0.0, 0.2 * np.sin(bank), 0.2 * np.cos(bank)], (n_turn, 1)),
        ]
    ) + rng.normal(0, 0.003, (n_rest + n_turn, 3))
    t = UTC0_US + np.arange(n_rest + n_turn, dtype=np.int64) * 10_000
    return highres_log(acc, gyro, t).write(tmp_path / "flight.tlog")


@pytest.mark.parametrize("keep", [0.05, 0.2, 0.5, 1.0])
def test_a_truncated_tlog_of_a_vehicle_yawing_at_rest_is_not_called_deg_per_s(
    tmp_path: Path, keep: float
) -> None:
    log = _standing_then_turning(tmp_path, yaw_at_rest=-0.229, turn_s=0.0)
    data = log.read_bytes()
    log.write_bytes(data[: round(len(data) * keep)])
    result = ingest([log], tmp_path / "out")  # before: "probable deg/s", set degps
    plaus = result.report["tables"]["imu"]["plausibility"]
    assert plaus["gyro_bias_at_rest_horizontal_radps"] in (None, pytest.approx(0.0, abs=0.01))


def test_steady_banked_turns_that_pass_for_rest_are_not_units_evidence(tmp_path: Path) -> None:
    log = _standing_then_turning(tmp_path, yaw_at_rest=0.0, turn_s=30.0)
    result = ingest([log], tmp_path / "out")  # before: rate at rest 0.15 rad/s, deg/s
    plaus = result.report["tables"]["imu"]["plausibility"]
    assert plaus["rest_windows_level"] == 10
    assert plaus["gyro_bias_at_rest_horizontal_radps"] == pytest.approx(0.0, abs=0.005)


def test_gyro_in_deg_per_s_at_rest_is_still_refused(tmp_path: Path) -> None:
    rng = np.random.default_rng(9)
    acc = np.array([0.0, 0.0, -G]) + rng.normal(0, 0.01, (600, 3))
    gyro = np.degrees(np.array([0.004, -0.003, 0.002]) + rng.normal(0, 0.002, (600, 3)))
    t = UTC0_US + np.arange(600, dtype=np.int64) * 10_000
    log = highres_log(acc, gyro, t).write(tmp_path / "a.tlog")
    with pytest.raises(PlausibilityError, match="about horizontal axes\\) - probable deg/s"):
        ingest([log], tmp_path / "out")
