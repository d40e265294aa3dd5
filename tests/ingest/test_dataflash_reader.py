"""ArduPilot DataFlash reader: parity with pymavlink's DFReader, GPS time, instances, and
damaged logs (bad-inputs.md cases 7, 15, 16, 17, 35, 37). Fixtures are packed with ``struct``
from pymavlink's format-character table (``tests.ingest.mavlogs``)."""

from __future__ import annotations

import os
import struct
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.parquet as pq
import pytest
from pymavlink import mavutil

from navreplay.ingest.api import IngestOptions, IngestResult, ingest, inspect
from navreplay.ingest.config import parse_dataset_config
from navreplay.ingest.errors import CorruptLogError
from navreplay.ingest.timebase import SECONDS_PER_WEEK, gps_week_tow_to_ns

from .mavlogs import DF_FORMATS, GMS0, GWK, DfLog, df_drive

WEEK_NS = SECONDS_PER_WEEK * 10**9


def run(path: Path, out: Path, *, strict: bool = False, **descriptor: Any) -> IngestResult:
    cfg = parse_dataset_config({"id": "df", **descriptor})
    return ingest([path], out, config=cfg, options=IngestOptions(strict=strict))


def frame(out: Path, name: str) -> Any:
    return pq.read_table(out / f"{name}.parquet").to_pandas()


def dfreader(path: Path, name: str) -> list[Any]:
    conn = mavutil.mavlink_connection(str(path))
    out = []
    while (m := conn.recv_match(type=name)) is not None:
        out.append(m)
    return out


@pytest.fixture(scope="module")
def drive() -> DfLog:
    return df_drive()


def test_imu_matches_pymavlink_per_instance(drive: DfLog, tmp_path: Path) -> None:
    path = drive.save(tmp_path / "a.bin")
    ref = [m for m in dfreader(path, "IMU") if m.I == 1]
    result = run(path, tmp_path / "out", imu={"instance": 1})
    assert result.report["tables"]["imu"]["stream"] == "IMU[1]"
    imu = frame(tmp_path / "out", "imu")
    assert len(imu) == len(ref) == 200
    np.testing.assert_array_equal(imu["acc_z_mps2"], [m.AccZ for m in ref])
    np.testing.assert_array_equal(imu["gyro_x_radps"], [m.GyrX for m in ref])
    # TimeUS on GPS time: GPS records pair GWk/GMS with TimeUS (fix logged 10 us later).
    gps0 = dfreader(path, "GPS")[0]
    offset = gps_week_tow_to_ns(gps0.GWk, gps0.GMS * 10**6) - gps0.TimeUS * 1000
    np.testing.assert_array_equal(imu["t_ns"], np.array([m.TimeUS for m in ref]) * 1000 + offset)


def test_gps_epochs_scalings_and_gpa_accuracies(drive: DfLog, tmp_path: Path) -> None:
    # Case 25 for DataFlash: L (1e-7 deg), e (cm), c (cdeg), C accuracies (cm).
    path = drive.save(tmp_path / "a.bin")
    result = run(path, tmp_path / "out")
    gnss = frame(tmp_path / "out", "gnss")
    ref = dfreader(path, "GPS")
    assert len(gnss) == len(ref) == 20
    np.testing.assert_array_equal(
        gnss["t_ns"], [gps_week_tow_to_ns(m.GWk, m.GMS * 10**6) for m in ref]
    )
    row = gnss.iloc[0]
    assert row["lat_deg"] == 528_069_428 / 1e7
    assert row["lon_deg"] == -41_224_417 / 1e7
    assert row["alt_m"] == pytest.approx(17.72 + 50.507)  # MSL - GPA.Und
    assert row["vel_n_mps"] == pytest.approx(0.0, abs=1e-9)  # 0.5 m/s on a 90 deg track
    assert row["vel_e_mps"] == pytest.approx(0.5)
    assert row["vel_d_mps"] == pytest.approx(-0.1)
    assert (row["h_acc_m"], row["v_acc_m"], row["speed_acc_mps"]) == (0.27, 0.36, 0.08)
    assert (row["fix_type"], row["num_sats"]) == (3, 21)
    assert result.report["tables"]["gnss"]["counters"]["no_fix"] == 0


def test_ekf_output_from_the_origin(drive: DfLog, tmp_path: Path) -> None:
    path = drive.save(tmp_path / "a.bin")
    result = run(path, tmp_path / "out", estimator={"instance": 1})
    assert result.report["tables"]["estimator"]["stream"] == "XKF1[1]"
    est = frame(tmp_path / "out", "estimator")
    assert len(est) == 40
    row = est.iloc[0]
    # ORGN 52.8070002, -4.1222271 moved 2 m north, 3 m west (ArduPilot's flat earth).
    assert row["lat_deg"] == pytest.approx(52.8070002 + 2.0 / 111_319.5, abs=2e-9)
    east = (row["lon_deg"] + 4.1222271) * 111_319.5 * np.cos(np.radians(52.807))
    assert east == pytest.approx(-3.0, abs=1e-3)
    assert row["alt_m"] == pytest.approx(17.53 - 0.5 + 50.507, abs=1e-4)
    np.testing.assert_allclose(
        [row["roll_rad"], row["pitch_rad"], row["yaw_rad"]],
        np.radians([-0.42, 0.38, 330.08 - 360]),
    )
    assert (row["vel_n_mps"], row["vel_d_mps"]) == pytest.approx((0.1, -0.05))


def test_trailing_partial_record(drive: DfLog, tmp_path: Path) -> None:
    # Case 15: the last record cut 3 bytes after its header.
    data = drive.data()
    cut = len(data) - len(drive.records[-1])
    path = drive.save(tmp_path / "a.bin", data[: cut + 6])
    result = run(path, tmp_path / "out")
    (defect,) = result.report["files"][0]["defects"]
    assert defect["kind"] == "partial_record_dropped"
    assert defect["offset"] == cut
    assert defect["bytes_skipped"] == 6
    with pytest.raises(CorruptLogError, match=f"offset {cut}"):
        run(path, tmp_path / "strict", strict=True)


def test_garbage_mid_file_is_skipped_with_offsets(drive: DfLog, tmp_path: Path) -> None:
    # Case 16: 50 random bytes between records, three times (one starts like a header).
    rng = np.random.default_rng(16)
    parts, offsets, at = [], [], 0
    for i, rec in enumerate(drive.records):
        if i in (100, 200, 300):
            junk = rng.integers(0, 256, 50, dtype=np.uint8).tobytes()
            if i == 200:
                junk = b"\xa3\x95" + bytes([DF_FORMATS["IMU"][0]]) + junk[3:]
            parts.append(junk)
            offsets.append(at)
            at += len(junk)
        parts.append(rec)
        at += len(rec)
    path = drive.save(tmp_path / "a.bin", b"".join(parts))
    result = run(path, tmp_path / "out")
    entry = result.report["files"][0]
    assert entry["counters"]["garbage_runs"] == 3
    assert entry["counters"]["garbage_bytes"] == 150
    assert entry["counters"]["records_framed"] == len(drive.records)
    (defect,) = entry["defects"]
    assert defect["offset"] == offsets[0]
    assert all(f"{o} (+50)" in defect["reason"] for o in offsets)
    assert result.tables["imu"] == 200


def test_fmt_records_anywhere_and_fmt_of_fmt_not_first(tmp_path: Path) -> None:
    # Case 17: the FMT describing FMT comes after others, IMU's FMT only mid-log.
    log = DfLog()
    log.fmt("GPS")
    log.fmt("FMT")
    log.fmt("GPA")
    for i in range(10):
        log.write(
            "GPS",
            1000 + i * 200_000,
            0,
            3,
            GMS0 + i * 200,
            GWK,
            12,
            80,
            1,
            2,
            300,
            0.0,
            0.0,
            0.0,
            0.0,
            1,
        )
    log.fmt("IMU")
    for i in range(100):
        log.write(
            "IMU", 1000 + i * 20_000, 0, 0.0, 0.0, 0.0, 0.0, 0.0, -9.8, 0, 0, 30.0, 1, 1, 1000, 1000
        )
    path = log.save(tmp_path / "a.bin")
    result = run(path, tmp_path / "out")
    assert result.tables == {"imu": 100, "gnss": 10}
    assert result.report["files"][0]["completeness"] == ["complete"]


def test_unknown_format_character(tmp_path: Path) -> None:
    # Case 17: an FMT with a character pymavlink does not know ('X').
    log = df_drive(seconds=1.0)
    body = struct.pack("<BB4s16s64s", 77, 3 + 8 + 1, b"ODD", b"QX", b"TimeUS,Odd")
    log.records.insert(3, b"\xa3\x95\x80" + body)
    log.records.insert(4, bytes([0xA3, 0x95, 77]) + struct.pack("<QB", 5, 1))
    path = log.save(tmp_path / "a.bin")
    result = run(path, tmp_path / "out")  # not needed for any table: skipped with a note
    notes = result.report["files"][0]["notes"]
    assert any("ODD skipped" in n and "'X'" in n for n in notes)
    assert result.tables["imu"] == 50
    # The same for the IMU format: E-FATAL naming the type and the FMT's offset.
    log = df_drive(seconds=1.0)
    bad = DF_FORMATS["IMU"][1].replace("f", "X", 1)
    imu_fmt = log.names.index("FMT", 1 + list(DF_FORMATS).index("IMU"))
    offset = sum(len(r) for r in log.records[:imu_fmt])
    rec = bytearray(log.records[imu_fmt])
    rec[3 + 6 : 3 + 22] = bad.encode().ljust(16, b"\0")
    log.records[imu_fmt] = bytes(rec)
    path = log.save(tmp_path / "b.bin")
    listed, _ = inspect([path])
    stream = listed[0].stream("IMU[0]")
    assert stream is not None
    assert "unsupported format character 'X'" in stream.detail
    with pytest.raises(CorruptLogError, match=rf"offset {offset}: FMT of IMU: .*IMU.*'X'"):
        run(path, tmp_path / "out_b")
    assert not (tmp_path / "out_b").exists()


def test_gps_week_rollover_is_snapped_to_the_file_time(tmp_path: Path) -> None:
    # Case 35: GWk - 1024 (a receiver with the 10-bit week bug), file written today.
    path = df_drive(week=GWK - 1024).save(tmp_path / "a.bin")
    result = run(path, tmp_path / "out")
    entry = result.report["files"][0]
    assert entry["counters"]["gps_week_rollover_corrected"] == 20
    assert any("+1024 weeks" in n for n in entry["notes"])
    gnss = frame(tmp_path / "out", "gnss")
    assert (gnss["t_ns"] // WEEK_NS == GWK).all()
    imu = frame(tmp_path / "out", "imu")
    assert imu["t_ns"].iloc[0] // WEEK_NS == GWK
    # A reference date in dataset.yaml wins over the file time: 2004 is nearest to 2005.
    result = run(path, tmp_path / "dated", utc_date="2005-01-01")
    assert "gps_week_rollover_corrected" not in result.report["files"][0]["counters"]
    assert (frame(tmp_path / "dated", "gnss")["t_ns"] // WEEK_NS == GWK - 1024).all()


def test_reboot_mid_file_pairs_each_boot(tmp_path: Path) -> None:
    # Case 37: TimeUS restarts; both boots have GPS, so both land on GPS time.
    log = DfLog()
    log.fmt("FMT")
    for name in ("IMU", "GPS"):
        log.fmt(name)
    for boot, (t0, gms0) in enumerate(((600_000_000, GMS0), (3_000_000, GMS0 + 1_000_000))):
        for i in range(250):
            t = t0 + i * 20_000
            log.write("IMU", t, 0, 0.0, 0.0, 0.0, 0.0, 0.0, -9.8, 0, 0, 30.0, 1, 1, 1000, 1000)
            if i % 10 == 0:
                log.write(
                    "GPS", t, 0, 3, gms0 + i * 20, GWK, 12, 80, 1, 2, 300, 0.0, 0.0, 0.0, 0.0, 1
                )
        del boot
    path = log.save(tmp_path / "a.bin")
    result = run(path, tmp_path / "out")
    assert result.report["files"][0]["counters"]["boot_resets"] == 1
    imu = frame(tmp_path / "out", "imu")
    assert len(imu) == 500
    assert (np.diff(imu["t_ns"]) > 0).all()
    assert (imu["t_ns"].iloc[250] - imu["t_ns"].iloc[249]) / 1e9 == pytest.approx(1000 - 4.98)


def test_dataflash_without_gps_stays_on_the_recorder_clock(tmp_path: Path) -> None:
    log = DfLog()
    log.fmt("FMT")
    log.fmt("IMU")
    for i in range(100):
        log.write(
            "IMU",
            5_000 + i * 20_000,
            0,
            0.0,
            0.0,
            0.0,
            0.0,
            0.0,
            -9.8,
            0,
            0,
            30.0,
            1,
            1,
            1000,
            1000,
        )
    result = run(log.save(tmp_path / "a.bin"), tmp_path / "out")
    assert result.report["time_base"]["base"] == "recorder"
    assert frame(tmp_path / "out", "imu")["t_ns"].iloc[0] == 5_000_000


def test_dataflash_magic_followed_by_noise(tmp_path: Path) -> None:
    # Case 7: the magic alone does not make a log; the error names the file.
    path = tmp_path / "x.bin"
    path.write_bytes(b"\xa3\x95\x80" + os.urandom(2000))
    with pytest.raises(CorruptLogError, match=str(path)):
        run(path, tmp_path / "out")
    assert not (tmp_path / "out").exists()
