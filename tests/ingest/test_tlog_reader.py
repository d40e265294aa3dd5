"""MAVLink tlog reader: decoding parity with pymavlink, scalings, instances, clocks.

Fixtures are written with pymavlink's encoder (``tests.ingest.mavlogs``); the expected values
come from pymavlink's own decoder or from the integers written, never from the reader.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.parquet as pq
import pytest
from pymavlink import mavutil

from navreplay.ingest.api import IngestResult, ingest, inspect
from navreplay.ingest.config import parse_dataset_config
from navreplay.ingest.errors import ConfigError
from navreplay.ingest.timebase import utc_to_gps_ns

from .mavlogs import (
    ALT_ELL_MM,
    ALT_MM,
    BOOT_US,
    LAT_E7,
    LON_E7,
    UTC0_US,
    DriveSpec,
    G,
    mav,
    tlog_drive,
)


def run(path: Path, out: Path, **descriptor: Any) -> IngestResult:
    return ingest([path], out, config=parse_dataset_config({"id": "t", **descriptor}))


def table(out: Path, name: str) -> Any:
    return pq.read_table(out / f"{name}.parquet").to_pandas()


def pymavlink_messages(path: Path, name: str) -> list[Any]:
    conn = mavutil.mavlink_connection(str(path), dialect="ardupilotmega")
    out = []
    while (m := conn.recv_match(type=name)) is not None:
        out.append(m)
    conn.close()
    return out


def gps_ns(boot_us: np.ndarray) -> np.ndarray:
    """The GPS time the fixture's vehicle clock reads (SYSTEM_TIME pairs it with UTC0)."""
    utc_ns = (UTC0_US + np.asarray(boot_us, np.int64) - BOOT_US) * 1000
    return utc_to_gps_ns(utc_ns)


def test_raw_imu_matches_pymavlink_in_si_units_on_gps_time(tmp_path: Path) -> None:
    path = tlog_drive().write(tmp_path / "a.tlog")
    result = run(path, tmp_path / "out", imu={"topic": "RAW_IMU"})
    assert result.report["time_base"]["base"] == "gps"
    imu = table(tmp_path / "out", "imu")
    ref = pymavlink_messages(path, "RAW_IMU")
    assert len(imu) == len(ref) == 200
    acc = np.array([[m.xacc, m.yacc, m.zacc] for m in ref], float) / 1000 * G
    gyro = np.array([[m.xgyro, m.ygyro, m.zgyro] for m in ref], float) / 1000
    np.testing.assert_array_equal(imu[["acc_x_mps2", "acc_y_mps2", "acc_z_mps2"]], acc)
    np.testing.assert_array_equal(imu[["gyro_x_radps", "gyro_y_radps", "gyro_z_radps"]], gyro)
    np.testing.assert_array_equal(imu["t_ns"], gps_ns(np.array([m.time_usec for m in ref])))
    assert imu["acc_z_mps2"].mean() == pytest.approx(-G, abs=0.01)  # FRD: -g on z at rest


def test_gps_raw_int_integer_scalings_and_extensions(tmp_path: Path) -> None:
    # Case 25: 1e-7 deg, mm, cm/s, cdeg, mm accuracies, against the integers written.
    path = tlog_drive().write(tmp_path / "a.tlog")
    result = run(path, tmp_path / "out")
    gnss = table(tmp_path / "out", "gnss")
    assert len(gnss) == 20
    row = gnss.iloc[0]
    assert row["lat_deg"] == LAT_E7 / 1e7
    assert row["lon_deg"] == LON_E7 / 1e7
    assert row["alt_m"] == ALT_ELL_MM / 1000  # alt_ellipsoid, not the MSL alt
    assert row["vel_n_mps"] == pytest.approx(0.0, abs=1e-12)  # 15 cm/s at cog 90.00 deg
    assert row["vel_e_mps"] == pytest.approx(0.15)
    assert np.isnan(row["vel_d_mps"])  # null: GPS_RAW_INT has no vertical velocity
    assert (row["h_acc_m"], row["v_acc_m"], row["speed_acc_mps"]) == (1.5, 2.5, 0.3)
    assert (row["fix_type"], row["num_sats"]) == (3, 12)
    assert pq.read_table(tmp_path / "out" / "gnss.parquet")["vel_d_mps"].null_count == 20
    np.testing.assert_array_equal(gnss["t_ns"], gps_ns(BOOT_US + np.arange(20) * 200_000))
    assert result.report["tables"]["gnss"]["counters"]["no_fix"] == 0


def test_mavlink1_gps_without_extensions_falls_back_to_msl_and_eph(tmp_path: Path) -> None:
    path = tlog_drive(DriveSpec(mavlink1_gps=True)).write(tmp_path / "a.tlog")
    result = run(path, tmp_path / "out")
    gnss = table(tmp_path / "out", "gnss")
    assert gnss["alt_m"].iloc[0] == ALT_MM / 1000
    assert gnss["h_acc_m"].iloc[0] == 1.21  # eph 121 (x 0.01): a DOP, reported as such
    counters = result.report["tables"]["gnss"]["counters"]
    assert counters["alt_msl_no_geoid"] == 20
    assert counters["h_acc_from_eph"] == 20


def test_estimator_joins_attitude_and_applies_the_logs_undulation(tmp_path: Path) -> None:
    path = tlog_drive().write(tmp_path / "a.tlog")
    run(path, tmp_path / "out")
    est = table(tmp_path / "out", "estimator")
    assert len(est) == 40
    row = est.iloc[3]
    assert row["alt_m"] == pytest.approx((ALT_MM + ALT_ELL_MM - ALT_MM) / 1000)
    assert (row["vel_n_mps"], row["vel_e_mps"], row["vel_d_mps"]) == (0.1, -0.2, 0.3)
    np.testing.assert_allclose(
        [row["roll_rad"], row["pitch_rad"], row["yaw_rad"]], [0.01, -0.02, 1.5], rtol=1e-7
    )


def test_simstate_truth_takes_the_time_of_its_attitude_burst(tmp_path: Path) -> None:
    path = tlog_drive().write(tmp_path / "a.tlog")
    result = run(path, tmp_path / "out")
    truth, est = table(tmp_path / "out", "truth"), table(tmp_path / "out", "estimator")
    np.testing.assert_array_equal(truth["t_ns"], est["t_ns"])
    assert (truth["lat_deg"] == LAT_E7 / 1e7).all()
    assert truth["alt_m"].isna().all()  # SIMSTATE has no altitude: invalid, counted
    assert result.report["tables"]["truth"]["stats"]["nonfinite"] == {
        "alt_m": {"nan": 40, "inf": 0}
    }


def test_imu_instance_selects_the_sensor_not_the_nth_key(tmp_path: Path) -> None:
    path = tlog_drive().write(tmp_path / "a.tlog")
    inventories, _plans = inspect([path])
    instances = {s.key: s.instance for s in inventories[0].streams if s.table}
    assert instances["SCALED_IMU2"] == 1
    assert instances["RAW_IMU"] == 0
    result = run(path, tmp_path / "one", imu={"instance": 1})
    assert result.report["tables"]["imu"]["stream"] == "SCALED_IMU2"
    result = run(path, tmp_path / "zero", imu={"instance": 0})
    assert result.report["tables"]["imu"]["stream"] in ("RAW_IMU", "HIGHRES_IMU")
    with pytest.raises(ConfigError, match="instance 2"):
        run(path, tmp_path / "two", imu={"instance": 2})


def test_raw_imu_id_field_gives_further_instances_their_own_key(tmp_path: Path) -> None:
    log = tlog_drive(DriveSpec(seconds=2.0))
    link = mav()
    for i in range(30):
        t = BOOT_US + i * 20_000
        log.add(
            UTC0_US + t - BOOT_US + 7_000,
            link,
            link.raw_imu_encode(t, 0, 0, -1000, 0, 0, 0, 0, 0, 0, 1),
        )
    path = log.write(tmp_path / "a.tlog")
    inventories, _ = inspect([path])
    stream = inventories[0].stream("RAW_IMU[1]")
    assert stream is not None
    assert stream.instance == 1
    assert stream.count == 30
    result = run(path, tmp_path / "out", imu={"topic": "RAW_IMU[1]"})
    assert result.tables["imu"] == 30


def test_packets_of_other_senders_are_counted_not_mixed_in(tmp_path: Path) -> None:
    log = tlog_drive(DriveSpec(seconds=2.0))
    gcs = mav(src=255, comp=190)
    for i in range(5):
        log.add(UTC0_US + i * 1000, gcs, gcs.raw_imu_encode(5, 1, 2, 3, 4, 5, 6, 7, 8, 9))
    path = log.write(tmp_path / "a.tlog")
    result = run(path, tmp_path / "out", imu={"topic": "RAW_IMU"})
    assert result.tables["imu"] == 100
    assert result.report["files"][0]["counters"]["packets_from_other_senders"] == 5
