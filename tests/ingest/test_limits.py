"""What a log cannot give an INS/GNSS replay (``ingest_report.json`` ``limits``), and the PX4
SITL and low-rate ULog cases behind them, on logs generated with the formats' own writers
(pymavlink's ``MAVLink`` classes, the ULog layout read back by pyulog)."""

from __future__ import annotations

import struct
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.parquet as pq
import pytest
from pymavlink.dialects.v20 import ardupilotmega as apm

from navreplay.ingest.api import IngestResult, ingest
from navreplay.pipeline.stages.ingest import format_summary

from .mavlogs import G, UlogLog, tlog_drive

SC_FIELDS = (
    "uint64_t timestamp;float[3] gyro_rad;uint32_t gyro_integral_dt;"
    "int32_t accelerometer_timestamp_relative;float[3] accelerometer_m_s2;"
    "uint32_t accelerometer_integral_dt;"
)
GPS_FIELDS = (
    "uint64_t timestamp;uint64_t time_utc_usec;int32_t lat;int32_t lon;int32_t alt;"
    "int32_t alt_ellipsoid;float s_variance_m_s;float eph;float epv;float vel_n_m_s;"
    "float vel_e_m_s;float vel_d_m_s;uint8_t fix_type;bool vel_ned_valid;uint8_t satellites_used;"
)
GPOS_FIELDS = (
    "uint64_t timestamp;double lat;double lon;float alt;float alt_ellipsoid;float vel_n;"
    "float vel_e;float vel_d;"
)
LAT0, LON0, ALT0 = 47.3977508, 8.5456074, 488.1


def limits(result: IngestResult) -> dict[str, str]:
    return {lim["code"]: lim["reason"] for lim in result.report["limits"]}


def sitl_ulog(seconds: float = 20.0, *, imu_hz: int = 250, dt_us: int = 4000) -> UlogLog:
    """A multicopter flying north-east at 3 m/s, heading 0.4 rad: sensor_combined (each
    sample integrating ``dt_us``), vehicle_gps_position at 5 Hz with vel_ned_valid never set
    (as PX4 1.9 SITL logs it) and the simulator's *_groundtruth at 10 Hz."""
    u = UlogLog()
    u.info("sys_name", "PX4")
    u.format("sensor_combined", SC_FIELDS, "Q3fIi3fI")
    u.format("vehicle_gps_position", GPS_FIELDS, "QQiiiiffffffB?B")
    u.format("vehicle_global_position_groundtruth", GPOS_FIELDS, "Qddfffff")
    u.format("vehicle_attitude_groundtruth", "uint64_t timestamp;float[4] q;", "Q4f")
    for name in (
        "sensor_combined",
        "vehicle_gps_position",
        "vehicle_global_position_groundtruth",
        "vehicle_attitude_groundtruth",
    ):
        u.subscribe(name)
    q = (np.cos(0.2), 0.0, 0.0, np.sin(0.2))  # yaw 0.4 rad
    for i in range(round(seconds * imu_hz)):
        t = 1_000_000 + i * (1_000_000 // imu_hz)
        u.data("sensor_combined", t, 0.0, 0.0, 0.0, dt_us, 0, 0.0, 0.0, -G, dt_us)
        k, tenth = divmod(i * 10, imu_hz)
        if tenth:
            continue
        north = east = 3.0 / np.sqrt(2) * k / 10
        lat = LAT0 + north / 111_320.0
        lon = LON0 + east / (111_320.0 * np.cos(np.radians(LAT0)))
        v = 3.0 / np.sqrt(2)
        u.data("vehicle_global_position_groundtruth", t, lat, lon, ALT0, 0.0, v, v, 0.0)
        u.data("vehicle_attitude_groundtruth", t, *q)
        if k % 2 == 0:
            mm = round(ALT0 * 1000)
            values = (t, 0, round(lat * 1e7), round(lon * 1e7), mm, 0, 0.3, 1.0, 1.5)
            u.data("vehicle_gps_position", *values, v, v, 0.0, 3, False, 10)
    return u


def test_sitl_groundtruth_is_the_truth_and_unflagged_velocities_are_used(tmp_path: Path) -> None:
    path = tmp_path / "sitl.ulg"
    path.write_bytes(sitl_ulog().bytes())
    result = ingest([path], tmp_path / "out")
    assert result.tables == {"imu": 5000, "gnss": 100, "truth": 200}
    truth = pq.read_table(tmp_path / "out" / "truth.parquet").to_pandas()
    assert truth["yaw_rad"].to_numpy() == pytest.approx(0.4, abs=1e-6)
    # alt_ellipsoid 0 is "not given": the MSL height (as the GPS heights), not 0 m.
    assert truth["alt_m"].to_numpy() == pytest.approx(ALT0, abs=1e-4)
    assert truth["vel_e_mps"].iloc[5] == pytest.approx(3.0 / np.sqrt(2), rel=1e-6)
    gnss = pq.read_table(tmp_path / "out" / "gnss.parquet").to_pandas()
    assert gnss["vel_n_mps"].notna().all()
    assert gnss["vel_n_mps"].iloc[3] == pytest.approx(3.0 / np.sqrt(2), rel=1e-6)
    counters = result.report["tables"]["gnss"]["counters"]
    assert counters["vel_ned_valid_never_set_velocity_used"] == 100
    assert result.report["limits"] == []


def test_low_rate_profile_imu_is_refused_with_its_coverage(tmp_path: Path) -> None:
    # PX4's reduced logging profile: sensor_combined at 8 Hz, each sample integrating 4 ms.
    path = tmp_path / "lowrate.ulg"
    path.write_bytes(sitl_ulog(imu_hz=8, dt_us=4000).bytes())
    result = ingest([path], tmp_path / "out")
    assert "imu" not in result.tables
    reason = limits(result)["imu_refused"]
    assert "sensor_combined[0] has 160 samples over 19.9 s (8.0 Hz)" in reason
    assert "each integrating 4.0 ms (accelerometer_integral_dt): only 3.2 %" in reason
    assert "Log sensor_combined at full rate" in reason
    assert "not usable for INS/GNSS (imu)" in format_summary(result.report, tmp_path / "out")
    # The same rate with samples integrating their whole interval is an IMU.
    path.write_bytes(sitl_ulog(imu_hz=8, dt_us=125_000).bytes())
    result = ingest([path], tmp_path / "out2")
    assert result.tables["imu"] == 160
    assert "imu_refused" not in limits(result)


def _tlog(path: Path, fix_type: int, speed_cms: int, seconds: float) -> Path:
    link = apm.MAVLink(None, srcSystem=1, srcComponent=1)
    utc0, boot0 = 1_457_306_279_000_000, 20_000_000
    out = []
    for i in range(round(seconds * 50)):
        boot = boot0 + i * 20_000
        msgs: list[Any] = [link.raw_imu_encode(boot, 0, 0, -1000, 1, -1, 0, 10, 20, 30)]
        if i % 10 == 0:
            lat = 523_456_789 + round(i * speed_cms / 100 / 50 / 111_320 * 1e7)
            gps = link.gps_raw_int_encode(
                boot, fix_type, lat, -41_234_567, 120_000, 121, 200, speed_cms, 0, 12
            )
            msgs += [gps, link.system_time_encode(utc0 + i * 20_000, boot // 1000)]
        for m in msgs:
            out.append(struct.pack(">Q", utc0 + i * 20_000 + 3_000) + m.pack(link))
            link.seq = (link.seq + 1) % 256
    path.write_bytes(b"".join(out))
    return path


def test_bench_log_without_fix(tmp_path: Path) -> None:
    path = _tlog(tmp_path / "bench.tlog", fix_type=1, speed_cms=0, seconds=20.0)
    result = ingest([path], tmp_path / "out")
    reason = limits(result)["gnss_no_fix"]
    assert reason.startswith(
        "no GPS fix in the log: 100 GPS records (GPS_RAW_INT), all with fix type < 3 "
        "(100 without any fix"
    )


def test_static_and_short_logs(tmp_path: Path) -> None:
    result = ingest([tlog_drive().write(tmp_path / "rest.tlog")], tmp_path / "rest")
    found = limits(result)
    assert (
        "the vehicle does not move: the GNSS horizontal speed stays below" in found["gnss_static"]
    )
    assert found["short_overlap"].startswith("IMU samples and 3-D GNSS fixes overlap for 3.80 s")
    # Moving at 5 m/s for 30 s: nothing to say.
    path = _tlog(tmp_path / "drive.tlog", fix_type=3, speed_cms=500, seconds=30.0)
    assert ingest([path], tmp_path / "drive").report["limits"] == []


def test_sensor_accel_and_gyro_make_the_imu_when_sensor_combined_is_not_logged(
    tmp_path: Path,
) -> None:
    u = UlogLog()
    u.info("sys_name", "PX4")
    fields = (
        "uint64_t timestamp;uint64_t timestamp_sample;uint32_t device_id;float x;float y;float z;"
    )
    u.format("sensor_accel", fields, "QQIfff")
    u.format("sensor_gyro", fields, "QQIfff")
    u.format("vehicle_gps_position", GPS_FIELDS, "QQiiiiffffffB?B")
    for name in ("sensor_accel", "sensor_gyro", "vehicle_gps_position"):
        u.subscribe(name)
    for i in range(400):  # 2 s at 200 Hz, gyro 1 ms after the accelerometer
        t = 1_000_000 + i * 5_000
        u.data("sensor_accel", t, t, 1, 0.1, -0.2, -G)
        u.data("sensor_gyro", t + 1_000, t + 1_000, 2, 0.01, 0.02, 0.03 + i * 1e-5)
        if i % 40 == 0:
            fix = (t, 0, 473_977_508, 85_456_074, 488_100, 0, 0.3, 1.0, 1.5, 0.0, 0.0, 0.0)
            u.data("vehicle_gps_position", *fix, 3, True, 10)
    path = tmp_path / "accel_gyro.ulg"
    path.write_bytes(u.bytes())
    result = ingest([path], tmp_path / "out")
    assert result.report["tables"]["imu"]["stream"] == "sensor_accel[0]"
    imu = pq.read_table(tmp_path / "out" / "imu.parquet").to_pandas()
    assert len(imu) == 400
    assert imu["acc_z_mps2"].to_numpy() == pytest.approx(-G)
    assert imu["gyro_z_radps"].to_numpy() == pytest.approx(0.03 + np.arange(400) * 1e-5)
