"""The canonical ``mag`` table from every reader that has a magnetometer: ArduPilot DataFlash
``MAG`` (instances, health, legacy names), MAVLink tlog ``RAW_IMU``/``SCALED_IMU2``/
``HIGHRES_IMU`` fields, PX4 ULog ``vehicle_magnetometer``, ROS ``sensor_msgs/MagneticField``;
the IMU's mounting rotation applied to it; logs without a compass get no table. Fixtures are
written with the formats' own encoders (``tests.ingest.mavlogs``, ``tests.ingest.roslogs``)
and read back by pymavlink, pyulog and rosbags as the reference."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.parquet as pq
import pytest
from pymavlink import mavutil
from scipy.spatial.transform import Rotation

from navreplay.ingest.api import IngestResult, ingest, inspect
from navreplay.ingest.config import parse_dataset_config
from navreplay.ingest.schema import TableName

from .mavlogs import UTC0_US, DfLog, G, Tlog, UlogLog, mav, tlog_drive
from .roslogs import ROS2, Stream, header, imu_data, imu_stream, serialize, vec3, write_mcap

IMU_FMT = (162, "QBffffffIIfBBHH", "TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,EG,EA,T,GH,AH,GHz,AHz")
MAG_FMT = (
    111,
    "QBhhhhhhhhhBI",
    "TimeUS,I,MagX,MagY,MagZ,OfsX,OfsY,OfsZ,MOX,MOY,MOZ,Health,S",
)
#: 2015-era names without an instance column: MAG, MAG2
LEGACY_MAG_FMT = "QhhhhhhhhhB"
LEGACY_MAG_COLS = "TimeUS,MagX,MagY,MagZ,OfsX,OfsY,OfsZ,MOfsX,MOfsY,MOfsZ,Health"
M_BODY_MG = np.array([190.0, -60.0, 440.0])  # a UK-like field in milligauss, body FRD
COLS = ["mag_x_gauss", "mag_y_gauss", "mag_z_gauss"]


def _run(path: Path, out: Path, **descriptor: Any) -> IngestResult:
    cfg = parse_dataset_config({"id": "mag", **descriptor})
    return ingest([path], out, config=cfg)


def _frame(out: Path, name: str) -> Any:
    return pq.read_table(out / f"{name}.parquet").to_pandas()


def _reference(path: Path, name: str) -> list[Any]:
    conn = mavutil.mavlink_connection(str(path))
    out = []
    while (m := conn.recv_match(type=name)) is not None:
        out.append(m)
    return out


def df_mag_log(
    rpy_sensor_deg: tuple[float, float, float] = (0.0, 0.0, 0.0),
    *,
    seconds: float = 4.0,
    legacy: bool = False,
    unhealthy: int | None = None,
) -> DfLog:
    """An IMU at 50 Hz and two compasses at 10 Hz, at rest; the sensor axes rotated by
    ``rpy_sensor_deg`` in the body (roll, pitch, yaw), the field ``M_BODY_MG`` in the body."""
    rng = np.random.default_rng(5)
    c_bs = Rotation.from_euler("ZYX", rpy_sensor_deg[::-1], degrees=True)  # sensor -> body
    f_s = c_bs.inv().apply([0.0, 0.0, -G])
    m_s = c_bs.inv().apply(M_BODY_MG)
    log = DfLog()
    log.fmt("FMT")
    log.fmt("IMU", IMU_FMT)
    if legacy:
        log.fmt("MAG", (111, LEGACY_MAG_FMT, LEGACY_MAG_COLS))
        log.fmt("MAG2", (112, LEGACY_MAG_FMT, LEGACY_MAG_COLS))
    else:
        log.fmt("MAG", MAG_FMT)
    t0 = 50_000_000
    for i in range(round(seconds * 50)):
        t = t0 + i * 20_000
        acc = f_s + rng.normal(0, 0.01, 3)
        log.write("IMU", t, 0, *rng.normal(0, 1e-3, 3), *acc, 0, 0, 40.0, 1, 1, 8000, 4000)
        if i % 5:
            continue
        k = i // 5
        for inst in (0, 1):
            mag = np.rint(m_s + 100 * inst + rng.normal(0, 1.0, 3)).astype(int)
            ofs = (12, -7, 30)
            health = 0 if (unhealthy == k and inst == 0) else 1
            if legacy:
                name = "MAG" if inst == 0 else "MAG2"
                log.write(name, t + 5 + inst, *mag, *ofs, 0, 0, 0, health)
            else:
                log.write("MAG", t + 5 + inst, inst, *mag, *ofs, 0, 0, 0, health, t // 1000)
    return log


def test_dataflash_mag_instances_units_and_health(tmp_path: Path) -> None:
    path = df_mag_log(unhealthy=3).save(tmp_path / "a.bin")
    _, plans = inspect([path])
    assert plans[TableName.MAG].key == "MAG[0]"
    assert plans[TableName.MAG].reason == "automatic: most messages"
    assert plans[TableName.MAG].alternatives == ("MAG[1]",)
    result = _run(path, tmp_path / "out")
    assert result.tables["mag"] == 40
    ref = [m for m in _reference(path, "MAG") if m.I == 0]
    mag = _frame(tmp_path / "out", "mag")
    want = np.array([[m.MagX, m.MagY, m.MagZ] for m in ref], float) / 1000.0
    want[3] = np.nan  # Health 0
    np.testing.assert_array_equal(mag[COLS].to_numpy(), want)
    report = result.report["tables"]["mag"]
    assert report["counters"] == {"mag_unhealthy": 1}
    assert report["info"]["units"] == "milligauss scaled to gauss"
    imu = _frame(tmp_path / "out", "imu")
    # the compass on the IMU's clock: TimeUS 5 us after the IMU record of the same frame
    assert int(mag["t_ns"].iloc[0]) == int(imu["t_ns"].iloc[0]) + 5_000
    second = _run(path, tmp_path / "second", mag={"instance": 1})
    assert second.report["tables"]["mag"]["stream"] == "MAG[1]"
    m1 = _frame(tmp_path / "second", "mag")
    ref1 = [m for m in _reference(path, "MAG") if m.I == 1]
    assert not np.isnan(m1[COLS].to_numpy()).any()  # the second compass stayed healthy
    np.testing.assert_array_equal(m1["mag_x_gauss"], [m.MagX / 1000.0 for m in ref1])
    np.testing.assert_allclose(m1[COLS].mean() - mag[COLS].mean(), 0.1, atol=0.002)


def test_dataflash_legacy_mag2_is_the_second_compass(tmp_path: Path) -> None:
    path = df_mag_log(legacy=True).save(tmp_path / "a.bin")
    inv, plans = inspect([path])
    keys = {s.key: s.instance for s in inv[0].streams if s.table == TableName.MAG}
    assert keys == {"MAG": 0, "MAG2": 1}
    assert plans[TableName.MAG].key == "MAG"
    result = _run(path, tmp_path / "out", mag={"instance": 1})
    assert result.report["tables"]["mag"]["stream"] == "MAG2"
    ref = _reference(path, "MAG2")
    mag = _frame(tmp_path / "out", "mag")
    np.testing.assert_array_equal(mag["mag_z_gauss"], [m.MagZ / 1000.0 for m in ref])


def test_the_imu_mounting_rotates_the_field_too(tmp_path: Path) -> None:
    """A board mounted rolled 30 deg and pitched -20 deg: ingest levels the IMU from gravity
    and turns the compass by the same rotation, back to the body's field."""
    path = df_mag_log((30.0, -20.0, 0.0)).save(tmp_path / "a.bin")
    result = _run(path, tmp_path / "out")
    imu_report = result.report["tables"]["imu"]["plausibility"]
    assert imu_report["specific_force_sensor_mps2"][1] < -4.0  # the board is tilted
    imu = _frame(tmp_path / "out", "imu")
    np.testing.assert_allclose(imu[["acc_x_mps2", "acc_y_mps2"]].mean(), 0.0, atol=0.01)
    mag = _frame(tmp_path / "out", "mag")
    np.testing.assert_allclose(mag[COLS].mean().to_numpy(), M_BODY_MG / 1000.0, atol=0.002)
    assert "the IMU's" in result.report["tables"]["mag"]["mounting"]
    # without the rotation the field would be the board's, 30 deg away
    level = _run(path, tmp_path / "level", imu={"mounting_rpy_deg": [0.0, 0.0, 0.0]})
    raw = _frame(tmp_path / "level", "mag")[COLS].mean().to_numpy()
    angle = math.degrees(math.acos(raw @ M_BODY_MG / np.linalg.norm(raw) / 484.0))
    assert angle > 20.0
    assert level.report["tables"]["mag"]["mounting"].startswith("the IMU's (")


def test_tlog_mag_fields_of_the_imu_messages(tmp_path: Path) -> None:
    """RAW_IMU and SCALED_IMU2 carry 10, 20, 30 mgauss; HIGHRES_IMU carries 0, 0, 0 (no
    compass): no stream of it."""
    log = tlog_drive()
    path = log.write(tmp_path / "a.tlog")
    inv, plans = inspect([path])
    mags = {s.key: (s.msgtype, s.count) for s in inv[0].streams if s.table == TableName.MAG}
    n = log.count("RAW_IMU")
    assert mags == {"RAW_IMU.mag": ("RAW_IMU", n), "SCALED_IMU2.mag": ("SCALED_IMU2", n)}
    assert plans[TableName.MAG].key == "RAW_IMU.mag"
    result = _run(path, tmp_path / "out")
    assert result.tables["mag"] == n
    ref = _reference(path, "RAW_IMU")
    mag = _frame(tmp_path / "out", "mag")
    np.testing.assert_array_equal(mag["mag_y_gauss"], [m.ymag / 1000.0 for m in ref])
    imu = _frame(tmp_path / "out", "imu")
    np.testing.assert_array_equal(mag["t_ns"], imu["t_ns"])  # the same messages
    other = _run(path, tmp_path / "other", mag={"topic": "SCALED_IMU2.mag"})
    assert other.report["tables"]["mag"]["msgtype"] == "SCALED_IMU2"


def test_tlog_highres_gauss_and_no_compass(tmp_path: Path) -> None:
    link = mav()
    log = Tlog()
    for i in range(50):
        boot_us = 100_000_000 + i * 20_000
        stamp = UTC0_US + i * 20_000
        acc, gyro = (0.0, 0.0, -G), (0.0, 0.0, 0.0)
        log.add(stamp, link, link.raw_imu_encode(boot_us, 0, 0, -1000, 0, 0, 0, 0, 0, 0, 0))
        mag = (0.21, -0.05, 0.43) if i != 7 else (0.0, 0.0, 0.0)
        msg = link.highres_imu_encode(boot_us, *acc, *gyro, *mag, 0, 0, 0, 20.0, 0x1FF, 0)
        log.add(stamp, link, msg)
    path = log.write(tmp_path / "a.tlog")
    inv, _ = inspect([path])
    mags = {s.key: s.count for s in inv[0].streams if s.table == TableName.MAG}
    assert mags == {"HIGHRES_IMU.mag": 49}  # RAW_IMU's fields are all 0: no compass
    result = _run(path, tmp_path / "out", imu={"topic": "HIGHRES_IMU"})
    mag = _frame(tmp_path / "out", "mag")
    assert len(mag) == 50  # the stream is the messages; the one without a field is NaN
    assert mag["mag_x_gauss"].iloc[0] == pytest.approx(0.21)
    assert np.isnan(mag["mag_x_gauss"].iloc[7])
    assert result.report["tables"]["mag"]["counters"] == {"mag_not_reported": 1}
    none = Tlog()
    for i in range(20):
        boot_us = 100_000_000 + i * 20_000
        msg = link.raw_imu_encode(boot_us, 0, 0, -1000, 0, 0, 0, 0, 0, 0, 0)
        none.add(UTC0_US + i * 20_000, link, msg)
    bare = _run(none.write(tmp_path / "b.tlog"), tmp_path / "bare")
    assert "mag" not in bare.tables
    assert not (tmp_path / "bare" / "mag.parquet").exists()


def test_ulog_vehicle_magnetometer(tmp_path: Path) -> None:
    from pyulog import ULog

    ulog = UlogLog()
    ulog.format(
        "sensor_combined",
        "uint64_t timestamp;float[3] gyro_rad;float[3] accelerometer_m_s2;",
        "Q3f3f",
    )
    ulog.format("vehicle_magnetometer", "uint64_t timestamp;float[3] magnetometer_ga;", "Q3f")
    ulog.subscribe("sensor_combined")
    ulog.subscribe("vehicle_magnetometer")
    for i in range(200):
        t = 10_000_000 + i * 5_000
        ulog.data("sensor_combined", t, 0.0, 0.0, 0.0, 0.0, 0.0, -G)
        if i % 4 == 0:
            ulog.data("vehicle_magnetometer", t + 100, 0.2 + 1e-4 * i, 0.01, 0.45)
    path = tmp_path / "a.ulg"
    path.write_bytes(ulog.bytes())
    result = _run(path, tmp_path / "out")
    assert result.tables == {"imu": 200, "mag": 50}
    assert result.report["tables"]["mag"]["stream"] == "vehicle_magnetometer[0]"
    ref = ULog(str(path), ["vehicle_magnetometer"]).data_list[0].data
    mag = _frame(tmp_path / "out", "mag")
    np.testing.assert_array_equal(mag["mag_x_gauss"], ref["magnetometer_ga[0]"])
    np.testing.assert_array_equal(mag["t_ns"], ref["timestamp"].astype(np.int64) * 1000)


def test_ros_magnetic_field_tesla_flu(tmp_path: Path) -> None:
    data = imu_data(200)
    mags = Stream("/imu/mag", "sensor_msgs/msg/MagneticField")
    field_flu = np.array([2.0e-5, 0.5e-5, -4.4e-5])  # tesla, FLU (z up: the field points down)
    for i in range(0, 200, 10):
        t = int(data.t_ns[i]) + 1000
        msg = ROS2.types["sensor_msgs/msg/MagneticField"](
            header=header(False, t, "imu_link"),
            magnetic_field=vec3(False, field_flu),
            magnetic_field_covariance=np.zeros(9),
        )
        mags.messages.append((t, serialize(False, msg)))
    path = write_mcap(tmp_path / "a.mcap", [imu_stream(data), mags])
    result = _run(path, tmp_path / "out")
    assert result.tables["mag"] == 20
    assert "mag: FLU -> FRD" in result.report["tables"]["mag"]["frame_conversions"]
    mag = _frame(tmp_path / "out", "mag")
    np.testing.assert_allclose(mag[COLS].iloc[0].to_numpy(), [0.2, -0.05, 0.44], rtol=1e-12)
