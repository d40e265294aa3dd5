"""Damaged and faulty tlogs (bad-inputs.md cases 7, 13-15, 21, 23-24, 27, 29-33, 35, 37, 40):
the report's counts equal what was injected, errors name the file and offset, and nothing
partial is ever left at the output path."""

from __future__ import annotations

import os
import struct
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.parquet as pq
import pytest
from pymavlink import mavutil

from navreplay.ingest.api import IngestOptions, IngestResult, ingest
from navreplay.ingest.config import parse_dataset_config
from navreplay.ingest.damage import DamageLog
from navreplay.ingest.detect import Detected, Format
from navreplay.ingest.errors import CorruptLogError, PlausibilityError, UnsupportedFormatError
from navreplay.ingest.readers.base import ReadContext
from navreplay.ingest.readers.mavlink.mavclock import ROLLOVER_NS
from navreplay.ingest.readers.mavlink.tlog import TlogReader
from navreplay.ingest.readers.mavlink.tlogclock import decode
from navreplay.ingest.timebase import utc_to_gps_ns

from .mavlogs import BOOT_US, UTC0_US, DriveSpec, G, Tlog, mav, tlog_drive

HIGHRES: dict[str, Any] = {"imu": {"topic": "HIGHRES_IMU"}}


def run(path: Path, out: Path, *, strict: bool = False, **descriptor: Any) -> IngestResult:
    cfg = parse_dataset_config({"id": "t", **descriptor})
    return ingest([path], out, config=cfg, options=IngestOptions(strict=strict))


def file_entry(result: IngestResult) -> dict[str, Any]:
    entry: dict[str, Any] = result.report["files"][0]
    return entry


@pytest.fixture(scope="module")
def drive() -> Tlog:
    return tlog_drive(DriveSpec(seconds=4.0))


def test_garbage_between_packets_is_skipped_and_counted(drive: Tlog, tmp_path: Path) -> None:
    # Case 13: 37 random bytes after every 100th record; pymavlink loses packets and yields
    # BAD_DATA with bogus stamps (canary below); here every packet is recovered.
    rng = np.random.default_rng(13)
    records = drive.records()
    damaged, offsets, at = [], [], 0
    for i, rec in enumerate(records):
        damaged.append(rec)
        at += len(rec)
        if i % 100 == 99:
            junk = rng.integers(0, 256, 37, dtype=np.uint8).tobytes()
            damaged.append(junk)
            offsets.append(at)
            at += len(junk)
    path = drive.write(tmp_path / "a.tlog", damaged)
    result = run(path, tmp_path / "out", **HIGHRES)
    entry = file_entry(result)
    assert entry["counters"]["garbage_runs"] == len(offsets)
    assert entry["counters"]["garbage_bytes"] == 37 * len(offsets)
    assert entry["counters"]["packets_framed"] == len(records)
    assert "bad_data_skipped" in entry["completeness"]
    (defect,) = entry["defects"]
    assert defect["offset"] == offsets[0]
    assert defect["bytes_skipped"] == 37 * len(offsets)
    assert f"{offsets[1]} (+37)" in defect["reason"]
    assert result.tables["imu"] == drive.count("HIGHRES_IMU")
    t = pq.read_table(tmp_path / "out" / "imu.parquet")["t_ns"].to_numpy()
    assert (np.diff(t) == 20_000_000).all()  # no bogus timestamps slipped in
    with pytest.raises(CorruptLogError, match=f"offset {offsets[0]}"):
        run(path, tmp_path / "strict", strict=True, **HIGHRES)
    assert not (tmp_path / "strict").exists()


def test_pymavlink_canary_garbage_yields_bad_data(drive: Tlog, tmp_path: Path) -> None:
    records = drive.records()
    damaged = [r + (b"\x55" * 37 if i % 100 == 99 else b"") for i, r in enumerate(records)]
    path = drive.write(tmp_path / "a.tlog", damaged)
    conn = mavutil.mavlink_connection(str(path))
    kinds = []
    while (m := conn.recv_match()) is not None:
        kinds.append(m.get_type())
    assert "BAD_DATA" in kinds  # why the reader frames and checks on its own


def test_bad_crc_packets_are_skipped_and_counted(drive: Tlog, tmp_path: Path) -> None:
    # Case 14: a CRC byte flipped on 2 % of the packets.
    records = drive.records()
    hit = list(range(7, len(records), 50))
    damaged = [bytearray(r) for r in records]
    for i in hit:
        damaged[i][-1] ^= 0xFF
    path = drive.write(tmp_path / "a.tlog", [bytes(r) for r in damaged])
    result = run(path, tmp_path / "out", **HIGHRES)
    entry = file_entry(result)
    assert entry["counters"]["packets_bad_crc"] == len(hit)
    lost_imu = sum(drive.names[i] == "HIGHRES_IMU" for i in hit)
    assert result.tables["imu"] == drive.count("HIGHRES_IMU") - lost_imu
    reasons = " ".join(d["reason"] for d in entry["defects"])
    assert f"{len(hit)} packets failed their CRC" in reasons
    assert "dialect" not in reasons  # 2 % of packets: damage, not a dialect mismatch
    with pytest.raises(CorruptLogError, match="CRC"):
        run(path, tmp_path / "strict", strict=True, **HIGHRES)


def test_a_wrong_dialect_is_suspected(drive: Tlog, tmp_path: Path) -> None:
    # Case 14: packed with ardupilotmega, read as `common`: SIMSTATE and AHRS2 are not in
    # common, and every packet of a message whose definition differs fails its CRC.
    records = drive.records()
    link = mav()
    extra = []
    for i in range(60):
        msg = link.ahrs2_encode(0.1, 0.2, 0.3, 10.0, 523_456_789, -41_234_567)
        extra.append(struct.pack(">Q", UTC0_US + i) + msg.pack(link))
    for i in range(20):
        msg = link.raw_imu_encode(BOOT_US + i, 0, 0, -1000, 0, 0, 0, 0, 0, 0)
        packet = bytearray(msg.pack(link))
        packet[-2:] = struct.pack("<H", (struct.unpack("<H", packet[-2:])[0] + 1) & 0xFFFF)
        extra.append(struct.pack(">Q", UTC0_US + i) + bytes(packet))
    path = drive.write(tmp_path / "a.tlog", records + extra)
    result = run(path, tmp_path / "out", mavlink={"dialect": "common"}, **HIGHRES)
    reasons = " ".join(d["reason"] for d in file_entry(result)["defects"])
    assert "suspected wrong MAVLink dialect (common)" in reasons
    counters = file_entry(result)["counters"]
    assert counters["packets_unknown_msgid"] == drive.count("SIMSTATE") + 60
    assert counters["packets_bad_crc"] == 20
    with pytest.raises(CorruptLogError, match="suspected wrong MAVLink dialect"):
        run(path, tmp_path / "strict", strict=True, mavlink={"dialect": "common"}, **HIGHRES)


def test_trailing_partial_record_is_dropped_with_its_offset(drive: Tlog, tmp_path: Path) -> None:
    # Case 15: the file ends 3 bytes into the last packet.
    records = drive.records()
    cut = sum(len(r) for r in records[:-1])
    path = drive.write(tmp_path / "a.tlog", [*records[:-1], records[-1][: 8 + 3]])
    result = run(path, tmp_path / "out", **HIGHRES)
    (defect,) = file_entry(result)["defects"]
    assert defect["kind"] == "partial_record_dropped"
    assert defect["offset"] == cut
    assert defect["bytes_skipped"] == 11
    assert f"dropped at offset {cut}" in defect["reason"]
    assert file_entry(result)["counters"]["packets_framed"] == len(records) - 1


@pytest.mark.parametrize("content", [b"", b"\x89PNG\r\n\x1a\n" + bytes(100), "random"])
def test_not_a_tlog_fails_naming_the_file(content: bytes | str, tmp_path: Path) -> None:
    # Case 7, also with the format forced.
    raw = os.urandom(1000) if content == "random" else content
    assert isinstance(raw, bytes)
    path = tmp_path / "x.tlog"
    path.write_bytes(raw)
    with pytest.raises(UnsupportedFormatError, match=str(path)):
        ingest([path], tmp_path / "out")
    if content == "random":  # past detection (a forced format), the reader finds no packet
        detected = Detected(path, Format.TLOG, (path,))
        reader = TlogReader(detected, ReadContext(DamageLog(path, strict=False)))
        with pytest.raises(CorruptLogError, match="no MAVLink packet"):
            reader.inventory()
    assert not (tmp_path / "out").exists()


def highres_log(acc: np.ndarray, gyro: np.ndarray, t_us: np.ndarray) -> Tlog:
    link = mav()
    log = Tlog()
    for i, t in enumerate(t_us.tolist()):
        msg = link.highres_imu_encode(t, *acc[i], *gyro[i], 0, 0, 0, 0, 0, 0, 20.0, 0x3F, 0)
        log.add(UTC0_US + i * 10_000, link, msg)
    return log


def rest(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    acc = np.array([0.0, 0.0, -G]) + rng.normal(0, 0.01, (n, 3))
    gyro = rng.normal(0, 1e-3, (n, 3))
    return acc, gyro, UTC0_US + np.arange(n, dtype=np.int64) * 10_000


def test_nan_and_inf_imu_values_are_kept_and_counted(tmp_path: Path) -> None:
    # Case 21.
    acc, gyro, t = rest(300)
    acc[[5, 6, 7], 0] = np.nan
    gyro[9, 2] = np.inf
    path = highres_log(acc, gyro, t).write(tmp_path / "a.tlog")
    result = ingest([path], tmp_path / "out")
    nonfinite = result.report["tables"]["imu"]["stats"]["nonfinite"]
    assert nonfinite == {"acc_x_mps2": {"nan": 3, "inf": 0}, "gyro_z_radps": {"nan": 0, "inf": 1}}


@pytest.mark.parametrize(
    ("fault", "match"), [("accel_g", "probable g units"), ("gyro_degps", "probable deg/s")]
)
def test_implausible_units_fail(fault: str, match: str, tmp_path: Path) -> None:
    # Cases 23 and 24.
    acc, gyro, t = rest(300)
    if fault == "accel_g":
        acc = acc / G
    else:
        gyro = gyro * 57.29578 + 3.0
    path = highres_log(acc, gyro, t).write(tmp_path / "a.tlog")
    with pytest.raises(PlausibilityError, match=match):
        ingest([path], tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_no_fix_with_stale_position_is_flagged(tmp_path: Path) -> None:
    # Case 27: fix_type 0, 0 satellites, lat/lon repeated.
    link = mav()
    log = Tlog()
    for i in range(20):
        fix, sats = (0, 0) if 10 <= i < 15 else (3, 11)
        msg = link.gps_raw_int_encode(
            UTC0_US + i * 200_000, fix, 523_456_789, -41_234_567, 120_000, 100, 150, 0, 0, sats
        )
        log.add(UTC0_US + i * 200_000, link, msg)
    result = ingest([log.write(tmp_path / "a.tlog")], tmp_path / "out")
    assert result.report["tables"]["gnss"]["counters"]["no_fix"] == 5
    gnss = pq.read_table(tmp_path / "out" / "gnss.parquet").to_pandas()
    assert (gnss["fix_type"][10:15] == 0).all()
    assert (gnss["num_sats"][10:15] == 0).all()


def test_time_faults_in_the_vehicle_clock_are_counted(tmp_path: Path) -> None:
    # Cases 29, 30, 31, 33 on HIGHRES_IMU.time_usec (the clock the table is stamped with).
    acc, gyro, t = rest(3000)
    swaps = list(range(100, 1100, 100))
    for i in swaps:
        t[[i, i + 1]] = t[[i + 1, i]]
    dups = list(range(1205, 1255, 10))
    for i in dups:
        t[i] = t[i - 1]
    keep = np.ones(len(t), bool)
    keep[2000:2200] = False  # a 2 s hole
    path = highres_log(acc[keep], gyro[keep], t[keep]).write(tmp_path / "a.tlog")
    result = ingest([path], tmp_path / "out")
    imu = result.report["tables"]["imu"]
    assert imu["hygiene"]["reordered"] == len(swaps)
    assert imu["hygiene"]["duplicates_conflicting_dropped"] == len(dups)
    assert imu["stats"]["gaps"]["count"] == 1
    assert imu["stats"]["gaps"]["longest_s"] == pytest.approx(2.01)
    assert result.tables["imu"] == 3000 - 200 - len(dups)


@pytest.mark.parametrize("step_s", [-5.0, 3600.0])
def test_clock_steps_are_reported(step_s: float, tmp_path: Path) -> None:
    # Case 31 (backwards: split and re-based) and 32 (forward jump: a reported gap).
    acc, gyro, t = rest(2000)
    t[1500:] += int(step_s * 1e6)
    path = highres_log(acc, gyro, t).write(tmp_path / "a.tlog")
    result = ingest([path], tmp_path / "out")
    imu = result.report["tables"]["imu"]
    assert result.tables["imu"] == 2000
    if step_s < 0:
        (step,) = imu["hygiene"]["clock_steps_backward"]
        assert step["step_s"] == pytest.approx(step_s + 0.01)
    else:
        assert imu["stats"]["gaps"]["longest_s"] == pytest.approx(step_s + 0.01)


def test_gps_week_rollover_is_corrected_against_the_tlog_stamps(tmp_path: Path) -> None:
    # Case 35: the vehicle's UTC (SYSTEM_TIME, epoch-valued HIGHRES_IMU) 1024 weeks early.
    log = tlog_drive(DriveSpec(seconds=2.0))
    rolled = Tlog()
    link = mav()
    shift_us = ROLLOVER_NS // 1000
    for stamp, name in zip(log.stamps_us, log.names, strict=True):
        boot = stamp - UTC0_US + BOOT_US - 3_000
        if name == "SYSTEM_TIME":
            rolled.add(stamp, link, link.system_time_encode(stamp - 3_000 - shift_us, boot // 1000))
        elif name == "HIGHRES_IMU":
            msg = link.highres_imu_encode(
                stamp - 3_000 - shift_us, 0, 0, -G, 0, 0, 0, 0, 0, 0, 0, 0, 0, 20.0, 0x3F, 0
            )
            rolled.add(stamp, link, msg)
    path = rolled.write(tmp_path / "a.tlog")
    result = run(path, tmp_path / "out", **HIGHRES)
    entry = file_entry(result)
    assert entry["counters"]["gps_week_rollover_corrected"] == rolled.count("SYSTEM_TIME") + 100
    t = pq.read_table(tmp_path / "out" / "imu.parquet")["t_ns"].to_numpy()
    first = int(utc_to_gps_ns(np.array([UTC0_US * 1000]))[0])
    assert abs(int(t[0]) - first) < 10**9  # GPS time of 2023, not 2004


def test_a_reboot_mid_log_splits_the_vehicle_clock(tmp_path: Path) -> None:
    # Case 37: time_boot_ms restarts near 0; each boot is paired with its own SYSTEM_TIME.
    link = mav()
    log = Tlog()
    for k, boot0 in enumerate((600_000_000, 2_000_000)):
        utc0 = UTC0_US + k * 700_000_000
        for i in range(300):
            boot = boot0 + i * 20_000
            stamp = utc0 + i * 20_000 + 3_000
            log.add(
                stamp, link, link.scaled_imu2_encode(boot // 1000, 0, 0, -1000, 0, 0, 0, 0, 0, 0)
            )
            if i % 50 == 0:
                log.add(stamp, link, link.system_time_encode(utc0 + i * 20_000, boot // 1000))
    path = log.write(tmp_path / "a.tlog")
    result = ingest([path], tmp_path / "out")
    entry = file_entry(result)
    assert entry["counters"]["boot_resets"] == 1
    assert any("vehicle reboot at offset" in n for n in entry["notes"])
    t = pq.read_table(tmp_path / "out" / "imu.parquet")["t_ns"].to_numpy()
    assert len(t) == 600
    assert (np.diff(t) > 0).all()
    assert (t[300] - t[299]) / 1e9 == pytest.approx(700 - 299 * 0.02, abs=1e-6)


def test_a_failure_mid_read_leaves_the_previous_output_untouched(
    drive: Tlog, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # Case 40: an exception while decoding; the earlier output directory survives intact.
    path = drive.write(tmp_path / "a.tlog")
    out = tmp_path / "out"
    run(path, out, **HIGHRES)
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    calls = {"n": 0}

    def failing(*args: Any) -> Any:
        calls["n"] += 1
        if calls["n"] > 3:
            raise RuntimeError("injected failure")
        return decode(*args)

    monkeypatch.setattr("navreplay.ingest.readers.mavlink.tlog.decode", failing)
    with pytest.raises(RuntimeError, match="injected"):
        run(path, out, **HIGHRES)
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.tlog", "out"]
