"""Logs of older vintages and with leading or interleaved garbage, generated with the formats'
own definitions (issue 23):

- ArduPilot DataFlash of 2014-2015 (Copter 3.2/3.3, Plane 3.x): ``TimeMS`` boot clock in ms,
  GPS records whose ``TimeMS`` is the GPS ms of week with ``Week`` and the boot time in
  ``T``, or (older) no boot time at all, ``EKF1``; FMT records with pymavlink's format
  characters, cross-checked by reading the file with pymavlink's ``DFReader``;
- legacy PX4 sdlog2 (``.px4log``): the same framing, records timed by the ``TIME`` record
  before them, ``GPSTime`` whole UTC seconds;
- MAVLink 2 tlogs behind 1,359 bytes of console text and MAVLink 1 tlogs with garbage between
  records (pymavlink's ``MAVLink`` classes of the v20 and v10 ``ardupilotmega`` dialects).
"""

from __future__ import annotations

import random
import struct
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.parquet as pq
import pytest
from pymavlink import mavutil
from pymavlink.dialects.v10 import ardupilotmega as apm1
from pymavlink.dialects.v20 import ardupilotmega as apm2

from navreplay.ingest.api import IngestResult, ingest
from navreplay.ingest.config import parse_dataset_config
from navreplay.ingest.detect import Format, detect
from navreplay.ingest.errors import UnsupportedFormatError
from navreplay.ingest.timebase import SECONDS_PER_WEEK, utc_to_gps_ns

from .mavlogs import DfLog, G

WEEK_NS = SECONDS_PER_WEEK * 10**9
WEEK_2015 = 1871  # 2015-11-15
TOW0_MS = 345_600_000 + 123  # Wednesday
BOOT0_MS = 10_000

# Copter 3.3 (2015) layouts, as its FMT records declare them.
COPTER33 = {
    "IMU": (131, "IffffffIIf", "TimeMS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,ErrG,ErrA,Temp"),
    "IMU2": (135, "IffffffIIf", "TimeMS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,ErrG,ErrA,Temp"),
    "GPS": (
        130,
        "BIHBcLLeeEefI",
        "Status,TimeMS,Week,NSats,HDop,Lat,Lng,RelAlt,Alt,Spd,GCrs,VZ,T",
    ),
    "EKF1": (
        140,
        "IccCffffffccc",
        "TimeMS,Roll,Pitch,Yaw,VN,VE,VD,PN,PE,PD,GX,GY,GZ",
    ),
    "MSG": (132, "Z", "Message"),
    "PARM": (129, "Nf", "Name,Value"),
}
# An older GPS layout: no vertical speed and no boot time (records timed by their neighbours).
GPS_NO_T = (130, "BIHBcLLeeEe", "Status,TimeMS,Week,NSats,HDop,Lat,Lng,RelAlt,Alt,Spd,GCrs")


def run(path: Path, out: Path, **descriptor: Any) -> IngestResult:
    return ingest([path], out, config=parse_dataset_config({"id": "vintage", **descriptor}))


def frame(out: Path, name: str) -> Any:
    return pq.read_table(out / f"{name}.parquet").to_pandas()


def read_all(path: Path, name: str) -> list[Any]:
    conn = mavutil.mavlink_connection(str(path))
    out = []
    while (m := conn.recv_match(type=name)) is not None:
        out.append(m)
    return out


def copter33(
    seconds: float = 4.0, *, gps_t: bool = True, firmware: bytes = b"APM:Copter V3.3 (d6053245)"
) -> DfLog:
    """Copter 3.3 at rest then moving north at 3 m/s: IMU/IMU2 at 50 Hz, GPS 5 Hz, EKF1 10 Hz;
    ``firmware`` is the first MSG record's text."""
    rng = np.random.default_rng(5)
    log = DfLog()
    log.fmt("FMT")
    for name, spec in COPTER33.items():
        log.fmt(name, GPS_NO_T if name == "GPS" and not gps_t else spec)
    log.write("MSG", firmware.ljust(64, b"\0"))
    log.write("PARM", b"SYSID_THISMAV".ljust(16, b"\0"), 1.0)
    for i in range(round(seconds * 50)):
        ms = BOOT0_MS + i * 20
        for name in ("IMU", "IMU2"):
            gyro = rng.normal(0, 1e-3, 3)
            acc = np.array([0.0, 0.0, -G]) + rng.normal(0, 0.01, 3)
            log.write(name, ms, *gyro, *acc, 0, 0, 35.0)
        if i % 10 == 0:
            fix_ms = ms - 5  # the fix arrived 5 ms before this frame
            lat = -353_632_000 + i * 10
            values: list[float] = [
                3,
                TOW0_MS + (ms - BOOT0_MS),
                WEEK_2015,
                10,
                120,
                lat,
                1_491_652_000,
            ]
            values += [1000, 58_400, 300, 0]
            values += [-0.25, fix_ms] if gps_t else []
            log.write("GPS", *values)
        if i % 5 == 0:
            log.write("EKF1", ms + 1, 10, -20, 9000, 3.0, 0.1, -0.2, 1.0, 2.0, -3.0, 0, 0, 0)
    return log


@pytest.mark.parametrize("gps_t", [True, False], ids=["gps_boot_T", "gps_without_T"])
def test_timems_era_dataflash_on_gps_time(tmp_path: Path, gps_t: bool) -> None:
    path = copter33(gps_t=gps_t).save(tmp_path / "log171.bin")
    # The fixture is a DataFlash log as pymavlink reads it.
    ref_imu, ref_gps = read_all(path, "IMU"), read_all(path, "GPS")
    assert len(ref_imu) == 200
    assert len(ref_gps) == 20
    assert ref_gps[0].Week == WEEK_2015
    result = run(path, tmp_path / "out")
    notes = result.report["files"][0]["inventory_notes"]
    assert any(n.startswith("TimeMS paired with GPS week/ms") for n in notes), notes
    assert "platform: APM:Copter V3.3 (d6053245)" in notes
    assert result.report["time_base"]["base"] == "gps"
    imu, gnss = frame(tmp_path / "out", "imu"), frame(tmp_path / "out", "gnss")
    assert len(imu) == 200
    assert len(gnss) == 20
    np.testing.assert_array_equal(imu["acc_z_mps2"], [m.AccZ for m in ref_imu])
    np.testing.assert_array_equal(imu["gyro_x_radps"], [m.GyrX for m in ref_imu])
    # Fixes at their own GPS epoch (Week, TimeMS of week) ...
    expected = WEEK_2015 * WEEK_NS + np.array([m.TimeMS for m in ref_gps], np.int64) * 10**6
    np.testing.assert_array_equal(gnss["t_ns"], expected)
    assert gnss["lat_deg"].iloc[0] == pytest.approx(-35.3632, abs=1e-9)
    assert gnss["alt_m"].iloc[0] == pytest.approx(584.0)  # MSL: no geoid in the log
    # ... and the boot clock paired with it: GPS - boot from T (5 ms before the frame), or,
    # without T, from the record before the GPS record (IMU2 of the same frame, 0 ms).
    lag_ms = 5 if gps_t else 0
    offset_ns = (WEEK_2015 * WEEK_NS + (TOW0_MS - BOOT0_MS) * 10**6) + lag_ms * 10**6
    t_imu = np.array([m.TimeMS for m in ref_imu], np.int64) * 10**6 + offset_ns
    np.testing.assert_array_equal(imu["t_ns"], t_imu)
    if gps_t:
        assert gnss["vel_d_mps"].iloc[0] == pytest.approx(-0.25)
    else:
        assert gnss["vel_d_mps"].isna().all()  # the layout has no VZ: null, not 0
    est = frame(tmp_path / "out", "estimator")
    assert len(est) == 40
    assert est["yaw_rad"].iloc[0] == pytest.approx(np.pi / 2)
    assert est["vel_n_mps"].iloc[0] == pytest.approx(3.0)
    # No ORGN before 2016: the origin is the median of fix minus EKF offset (PN 1 m, PE 2 m,
    # PD -3 m here), so the EKF track sits on the fixes (within their 1 m spread).
    assert result.report["tables"]["estimator"]["counters"]["ekf_origin_estimated_from_gps"] == 40
    assert est["lat_deg"].to_numpy() == pytest.approx(gnss["lat_deg"].median(), abs=1e-5)
    assert est["lon_deg"].to_numpy() == pytest.approx(gnss["lon_deg"].median(), abs=1e-5)
    assert est["alt_m"].to_numpy() == pytest.approx(584.0, abs=1e-6)


def test_2015_log_is_not_moved_by_a_week_rollover(tmp_path: Path) -> None:
    # The file is written today (2026): 11 years after its GPS weeks, more than half a 1024-week
    # rollover. Snapping to the nearest epoch put it in 2034; it must stay in 2015.
    path = copter33().save(tmp_path / "old.bin")
    result = run(path, tmp_path / "out")
    assert "gps_week_rollover_corrected" not in result.report["files"][0]["counters"]
    assert (frame(tmp_path / "out", "gnss")["t_ns"] // WEEK_NS == WEEK_2015).all()


# ------------------------------------------------------------------------------ PX4 sdlog2
PX4 = {
    "TIME": (129, "Q", "StartTime"),
    "IMU": (4, "ffffffffffff", "AccX,AccY,AccZ,GyroX,GyroY,GyroZ,MagX,MagY,MagZ,tA,tG,tM"),
    "IMU1": (22, "ffffffffffff", "AccX,AccY,AccZ,GyroX,GyroY,GyroZ,MagX,MagY,MagZ,tA,tG,tM"),
    "GPS": (
        8,
        "QBffLLfffffBHHH",
        "GPSTime,Fix,EPH,EPV,Lat,Lon,Alt,VelN,VelE,VelD,Cog,nSat,SNR,N,J",
    ),
}
UTC0_US = 1_433_984_879_000_000  # 2015-06-11


def px4log(seconds: float = 4.0) -> DfLog:
    """Frames at 50 Hz, each a TIME record then IMU and IMU1; GPS in every tenth frame with
    GPSTime the last whole UTC second (refreshed once a second, as sdlog2 logged it)."""
    log = DfLog()
    log.fmt("FMT")
    for name, spec in PX4.items():
        log.fmt(name, spec)
    boot0 = 579_461_673
    for i in range(round(seconds * 50)):
        t = boot0 + i * 20_000
        log.write("TIME", t)
        for name in ("IMU", "IMU1"):
            log.write(name, 0.1, -0.2, -G, 0.001, 0.002, -0.003, 0.3, 0.0, 0.4, 35.0, 35.0, 28.0)
        if i % 10 == 0:
            utc = UTC0_US + ((t - boot0) // 1_000_000) * 1_000_000
            lat = 404_660_219 + i
            values = (utc, 3, 1.5, 2.6, lat, -869_697_825, 204.3, 0.5, -0.2, 0.0, 3.27)
            log.write("GPS", *values, 11, 0, 110, 2)
    return log


def test_px4_sdlog2_log(tmp_path: Path) -> None:
    path = px4log().save(tmp_path / "flight.px4log")
    assert detect(path).format == Format.DATAFLASH
    ref_gps = read_all(path, "GPS")
    assert len(ref_gps) == 20
    assert ref_gps[0].Fix == 3
    result = run(path, tmp_path / "out")
    notes = result.report["files"][0]["inventory_notes"]
    assert any(n.startswith("TIME.StartTime paired with GPSTime (UTC)") for n in notes), notes
    imu, gnss = frame(tmp_path / "out", "imu"), frame(tmp_path / "out", "gnss")
    assert len(imu) == 200
    assert len(gnss) == 20
    assert imu["gyro_z_radps"].iloc[0] == pytest.approx(-0.003)
    # Every record carries the time of its frame's TIME record; the clock pairs on the GPS
    # records that bring a new UTC second (t = 0 s, 1 s, ...), where GPSTime is fresh.
    boot = 579_461_673 + np.arange(200) * 20_000
    offset_ns = int(utc_to_gps_ns(np.array([UTC0_US * 1000]))[0]) - 579_461_673 * 1000
    np.testing.assert_array_equal(imu["t_ns"], boot * 1000 + offset_ns)
    np.testing.assert_array_equal(gnss["t_ns"], boot[::10] * 1000 + offset_ns)
    assert gnss["h_acc_m"].iloc[0] == pytest.approx(1.5)
    assert gnss["lat_deg"].iloc[1] == pytest.approx(40.4660229, abs=1e-9)


# ---------------------------------------------------------------------------------- tlogs
def tlog_records(link: Any, n: int = 300) -> list[bytes]:
    """A vehicle at rest: RAW_IMU at 50 Hz, GPS_RAW_INT and SYSTEM_TIME at 5 Hz."""
    utc0, boot0 = 1_457_306_279_000_000, 20_000_000
    out = []
    for i in range(n):
        boot = boot0 + i * 20_000
        stamp = utc0 + i * 20_000 + 3_000
        msgs = [link.raw_imu_encode(boot, 0, 0, -1000, 1, -1, 0, 10, 20, 30)]
        if i % 10 == 0:
            msgs.append(
                link.gps_raw_int_encode(
                    boot, 3, 523_456_789, -41_234_567, 120_000, 121, 200, 15, 9000, 12
                )
            )
            msgs.append(link.system_time_encode(utc0 + i * 20_000, boot // 1000))
        for m in msgs:
            out.append(struct.pack(">Q", stamp) + m.pack(link))
            link.seq = (link.seq + 1) % 256
    return out


CONSOLE = b"".join(
    f"[{i:03d}] APM:Copter V3.4-dev console: init ... waiting for heartbeat\r\n".encode()
    for i in range(40)
)[:1359]


def test_tlog_behind_console_text_is_read_and_the_text_counted(tmp_path: Path) -> None:
    records = tlog_records(apm2.MAVLink(None, srcSystem=1, srcComponent=1))
    clean = tmp_path / "clean.tlog"
    clean.write_bytes(b"".join(records))
    path = tmp_path / "console.log"  # the extension lies too
    path.write_bytes(CONSOLE + b"".join(records))
    assert len(CONSOLE) == 1359
    assert detect(path).format == Format.TLOG
    # pymavlink sniffs a ".log" for DataFlash text and crashes on the binary: give it ".tlog".
    named = tmp_path / "console.tlog"
    named.write_bytes(path.read_bytes())
    ref = mavutil.mavlink_connection(str(named))
    n_ref = 0
    while ref.recv_match(type=["RAW_IMU", "GPS_RAW_INT", "SYSTEM_TIME"]) is not None:
        n_ref += 1
    assert n_ref == len(records)  # pymavlink resynchronises on the first record too
    result = run(path, tmp_path / "out")
    entry = result.report["files"][0]
    assert entry["completeness"] == ["bad_data_skipped"]
    assert any("(1359 bytes) skipped" in d["reason"] for d in entry["defects"])
    assert any("at offsets 0 (+1359)" in d["reason"] for d in entry["defects"])
    run(clean, tmp_path / "clean_out")
    for table in ("imu", "gnss"):
        a, b = frame(tmp_path / "out", table), frame(tmp_path / "clean_out", table)
        assert len(a) == len(b) > 0
        np.testing.assert_array_equal(a.to_numpy(), b.to_numpy())


def test_mavlink1_tlog_with_interleaved_garbage(tmp_path: Path) -> None:
    records = tlog_records(apm1.MAVLink(None, srcSystem=1, srcComponent=1))
    assert all(r[8] == 0xFE for r in records)  # MAVLink 1 framing
    rng = random.Random(23)
    out, junk = [], 0
    for i, rec in enumerate(records):
        out.append(rec)
        if i % 37 == 5:
            bad = bytes(rng.randrange(256) for _ in range(rng.randrange(1, 60)))
            out.append(bad)
            junk += len(bad)
    path = tmp_path / "noisy.tlog"
    path.write_bytes(b"".join(out))
    result = run(path, tmp_path / "out")
    entry = result.report["files"][0]
    skipped = [d for d in entry["defects"] if "not MAVLink packets" in d["reason"]]
    assert len(skipped) == 1
    assert skipped[0]["bytes_skipped"] == junk
    imu = frame(tmp_path / "out", "imu")
    assert len(imu) == 300  # every RAW_IMU record survives
    assert result.tables["gnss"] == 30


@pytest.mark.parametrize("cut", [1, 2])
def test_dataflash_cut_inside_a_record_header_is_a_partial_record(tmp_path: Path, cut: int) -> None:
    # The 2024 80 KiB excerpt ends in "a3 95": a record cut before its type byte.
    data = copter33().data()
    path = tmp_path / "cut.bin"
    path.write_bytes(data + b"\xa3\x95"[:cut])
    result = run(path, tmp_path / "out")
    entry = result.report["files"][0]
    assert entry["completeness"] == ["partial_record_dropped"]
    assert entry["defects"][0]["reason"] == (
        f"1 trailing partial record dropped at offset {len(data)} ({cut} bytes): the file "
        "ends inside it"
    )
    assert "garbage_runs" not in entry["counters"]


def test_dataflash_without_any_boot_clock_is_refused_with_the_reason(tmp_path: Path) -> None:
    # Copter 3.0 (2013): IMU "ffffff" without a time column, GPS with only the GPS time.
    log = DfLog()
    log.fmt("FMT")
    log.fmt("IMU", (131, "ffffff", "GyrX,GyrY,GyrZ,AccX,AccY,AccZ"))
    log.fmt("GPS", (130, "BIBcLLeeEe", "Status,Time,NSats,HDop,Lat,Lng,RelAlt,Alt,Spd,GCrs"))
    for i in range(100):
        log.write("IMU", 0.0, 0.0, 0.0, 0.0, 0.0, -G)
        if i % 10 == 0:
            log.write("GPS", 3, TOW0_MS + i * 20, 9, 120, -353_632_000, 1_491_652_000, 0, 0, 0, 0)
    path = log.save(tmp_path / "ac30.bin")
    with pytest.raises(UnsupportedFormatError, match=r"none of the 110 DataFlash records carries"):
        run(path, tmp_path / "out")
    assert not (tmp_path / "out").exists()
