"""Real autopilot logs from ../shared/data, read in place (skipped when absent), and the
synthesized ``fwekf_reference`` tlog round trip.

Counts, rates and sites are those the folders' SOURCE.txt describe; each log goes through
``ingest()`` like any user log.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.parquet as pq
import pytest

from navreplay.ingest.api import IngestResult, ingest
from navreplay.ingest.config import load_dataset_config, parse_dataset_config
from navreplay.ingest.tables import read_table
from navreplay.ingest.timebase import gps_week_tow_to_ns
from navreplay.pipeline.synth import fwekf
from navreplay.pipeline.synth.fwekf import FwekfReferenceParams

REPO = Path(__file__).resolve().parents[2]
DATA = REPO.parent / "shared" / "data"
VTOL = DATA / "uavlogviewer_sitl_tlog" / "vtol.tlog"
BIN = DATA / "uob_flightlab_ardupilot_bin" / "2023-07-06_10-12-18.bin"
ULOGS = DATA / "pyulog_samples"


def need(path: Path) -> Path:
    if not path.exists():
        pytest.skip(f"{path} is absent (../shared/data is not mounted here)")
    return path


def run(path: Path, out: Path, **descriptor: Any) -> IngestResult:
    return ingest([path], out, config=parse_dataset_config({"id": "real", **descriptor}))


def frame(out: Path, name: str) -> Any:
    return pq.read_table(out / f"{name}.parquet").to_pandas()


@pytest.fixture(scope="module")
def vtol(tmp_path_factory: pytest.TempPathFactory) -> tuple[IngestResult, Path]:
    out = tmp_path_factory.mktemp("vtol") / "tables"
    # In flight from the first sample: a steady 0.23 rad/s turn passes the accelerometer-only
    # rest test, so the gyro unit check is told the units (radps) instead of guessing.
    return run(need(VTOL), out, imu={"gyro_units": "radps"}), out


def test_vtol_tlog_streams_counts_and_rates(vtol: tuple[IngestResult, Path]) -> None:
    result, _ = vtol
    streams = {s["key"]: s for s in result.report["files"][0]["streams"]}
    expected = {"RAW_IMU": 795, "SCALED_IMU2": 796, "GPS_RAW_INT": 799}
    expected |= {"GLOBAL_POSITION_INT": 807, "SIMSTATE": 889}
    for key, count in expected.items():
        assert streams[key]["count"] == count
        assert streams[key]["rate_hz"] == pytest.approx(3.9, abs=0.4)  # ~207 s of telemetry
    assert result.report["files"][0]["completeness"] == ["complete"]
    assert result.report["time_base"]["base"] == "gps"  # SYSTEM_TIME pairs the boot clock


def test_vtol_tlog_values_are_plausible(vtol: tuple[IngestResult, Path]) -> None:
    result, out = vtol
    imu, gnss = frame(out, "imu"), frame(out, "gnss")
    assert result.report["tables"]["imu"]["stream"] == "SCALED_IMU2"
    gravity = result.report["tables"]["imu"]["plausibility"]["gravity_magnitude_mps2"]
    assert gravity == pytest.approx(9.81, abs=0.5)  # steady flight windows, ~1 g
    assert imu["acc_z_mps2"].median() < -8.0  # FRD: the lift/gravity reaction on -z
    assert gnss["lat_deg"].between(-35.37, -35.36).all()  # CMAC, SITL's default home
    assert gnss["lon_deg"].between(149.16, 149.17).all()
    assert (gnss["fix_type"] == 6).all()
    assert gnss["num_sats"].min() >= 6
    est, truth = frame(out, "estimator"), frame(out, "truth")
    assert len(truth) > 850
    np.testing.assert_allclose(est["lat_deg"].median(), truth["lat_deg"].median(), atol=1e-3)
    # 2018-08-08 in GPS time (the vehicle's SITL clock).
    assert gps_week_tow_to_ns(2013, 0) < imu["t_ns"].iloc[0] < gps_week_tow_to_ns(2014, 0)


def test_vtol_imu_instances_are_selectable(tmp_path: Path) -> None:
    result = run(need(VTOL), tmp_path / "t", imu={"instance": 0, "gyro_units": "radps"})
    imu = result.report["tables"]["imu"]
    assert imu["stream"] == "RAW_IMU"
    # One packet arrived 1.4 s late over the telemetry link: dropped by the reorder window.
    assert imu["hygiene"]["dropped_late"] == 1
    assert result.tables["imu"] == 795 - 1


@pytest.fixture(scope="module")
def dataflash(tmp_path_factory: pytest.TempPathFactory) -> tuple[IngestResult, Path]:
    out = tmp_path_factory.mktemp("bin") / "tables"
    return run(need(BIN), out), out


def test_dataflash_streams_counts_and_rates(dataflash: tuple[IngestResult, Path]) -> None:
    result, _ = dataflash
    entry = result.report["files"][0]
    streams = {s["key"]: s for s in entry["streams"]}
    for i in range(3):
        assert streams[f"IMU[{i}]"]["count"] == 2450
        assert streams[f"IMU[{i}]"]["rate_hz"] == pytest.approx(25.0, abs=0.1)
        assert streams[f"XKF1[{i}]"]["rate_hz"] == pytest.approx(10.0, abs=0.1)
    assert streams["GPS[0]"]["count"] == 490
    assert streams["GPS[0]"]["rate_hz"] == pytest.approx(5.0, abs=0.05)
    assert entry["counters"]["records_framed"] == 63_254  # SOURCE.txt: 63,254 messages
    # The log ends inside a record (the logger stopped mid-write): reported, not hidden.
    assert entry["completeness"] == ["partial_record_dropped"]
    assert entry["defects"][0]["offset"] == 3_452_893


def test_dataflash_gps_time_accuracies_and_site(dataflash: tuple[IngestResult, Path]) -> None:
    result, out = dataflash
    assert result.report["time_base"]["base"] == "gps"
    gnss = frame(out, "gnss")
    assert len(gnss) == 490
    week = gnss["t_ns"] // gps_week_tow_to_ns(1, 0)
    assert (week == 2269).all()  # GWk 2269 = 2023-07-06
    assert gnss["h_acc_m"].median() == pytest.approx(0.27, abs=0.01)  # GPA HAcc
    assert gnss["v_acc_m"].notna().all()
    assert gnss["num_sats"].between(21, 22).all()
    assert gnss["lat_deg"].between(52.80, 52.81).all()
    assert gnss["lon_deg"].between(-4.13, -4.12).all()
    # Ellipsoidal: MSL ~15-30 m plus the logged undulation (GPA.Und = -50.5 m).
    assert gnss["alt_m"].median() == pytest.approx(70, abs=10)
    imu = frame(out, "imu")
    assert imu["t_ns"].iloc[0] >= gnss["t_ns"].iloc[0] - 2 * 10**9


def test_dataflash_gravity_at_rest_and_instances(tmp_path: Path) -> None:
    need(BIN)
    for inst in range(3):
        result = run(BIN, tmp_path / str(inst), imu={"instance": inst})
        assert result.report["tables"]["imu"]["stream"] == f"IMU[{inst}]"
        plaus = result.report["tables"]["imu"]["plausibility"]
        assert plaus["gravity_magnitude_mps2"] == pytest.approx(9.75, abs=0.2)
        assert plaus["gravity_estimate"] == "rest"


def test_dataflash_ekf_position_agrees_with_the_autopilots_pos(
    dataflash: tuple[IngestResult, Path],
) -> None:
    from pymavlink import mavutil

    _, out = dataflash
    est = frame(out, "estimator")
    conn = mavutil.mavlink_connection(str(BIN))
    pos, offset_ns = [], None
    while (m := conn.recv_match(type=["POS", "GPS"])) is not None:
        if m.get_type() == "GPS" and offset_ns is None:
            offset_ns = gps_week_tow_to_ns(m.GWk, m.GMS * 10**6) - m.TimeUS * 1000
        elif m.get_type() == "POS":
            pos.append((m.TimeUS, m.Lat, m.Lng))
    assert offset_ns is not None
    p = np.array(pos, dtype=float)
    t = p[:, 0] * 1000 + offset_ns
    inside = (t > est["t_ns"].iloc[0]) & (t < est["t_ns"].iloc[-1])
    lat = np.interp(t[inside], est["t_ns"], est["lat_deg"])
    lon = np.interp(t[inside], est["t_ns"], est["lon_deg"])
    north_m = (lat - p[inside, 1]) * 111_200
    east_m = (lon - p[inside, 2]) * 111_200 * np.cos(np.radians(52.807))
    assert np.percentile(np.hypot(north_m, east_m), 95) < 0.15  # POS is EKF core 0 too


@pytest.mark.parametrize(
    ("name", "gnss_rows", "imu_rows", "base"),
    [("sample.ulg", None, 17_070, "recorder"), ("sample_log_small.ulg", 32, 1_298, "gps")],
)
def test_pyulog_samples(
    name: str, gnss_rows: int | None, imu_rows: int, base: str, tmp_path: Path
) -> None:
    result = run(need(ULOGS / name), tmp_path / "out")
    assert result.tables.get("gnss") == gnss_rows
    assert result.tables["imu"] == imu_rows
    assert result.report["time_base"]["base"] == base
    plaus = result.report["tables"]["imu"]["plausibility"]
    assert plaus["gravity_magnitude_mps2"] == pytest.approx(9.7, abs=0.2)
    imu = frame(tmp_path / "out", "imu")
    assert imu["acc_z_mps2"].median() < -9.0  # FRD
    if gnss_rows:
        gnss = frame(tmp_path / "out", "gnss")
        assert gnss["lat_deg"].between(63.41, 63.42).all()  # Trondheim
        assert (gnss["fix_type"] == 3).all()
        assert gnss["h_acc_m"].notna().all()
        week = int(gnss["t_ns"].iloc[0] // gps_week_tow_to_ns(1, 0))
        assert week == 2154  # 2021-04-21
    else:
        assert result.report["tables"]["imu"]["stats"]["rate_hz"] == pytest.approx(250, abs=5)


def test_fwekf_reference_tlog_round_trips(tmp_path: Path) -> None:
    # The synthesizer's own tables come back within the tlog's quantisation.
    params = dataclasses.replace(FwekfReferenceParams(), alignment_s=5.0, motion_s=10.0)
    fwekf.write(params, 3, tmp_path / "synth")
    descriptor = tmp_path / "dataset.yaml"
    descriptor.write_text((REPO / "datasets" / "fwekf_reference" / "dataset.yaml").read_text())
    cfg = load_dataset_config(descriptor)
    log = tmp_path / "synth" / "fwekf_reference.tlog"
    result = ingest([log], tmp_path / "tables", config=cfg, config_dir=tmp_path)
    assert result.report["time_base"]["base"] == "utc"
    tolerances = {  # column -> absolute tolerance of what the tlog can hold
        "t_ns": 0,
        "lat_deg": 0.5e-7,  # 1e-7 deg integers
        "lon_deg": 0.5e-7,
        "alt_m": 1e-4,  # float32 at ~100 m
        "vel_n_mps": 1e-5,  # float32
        "vel_e_mps": 1e-5,
        "vel_d_mps": 1e-5,
        "roll_rad": 1e-7,
        "pitch_rad": 1e-7,
        "yaw_rad": 1e-6,
    }
    for name in ("imu", "gnss", "truth"):
        ref = read_table(tmp_path / "synth" / "reference" / f"{name}.parquet", name).table
        got = read_table(tmp_path / "tables" / f"{name}.parquet", name).table
        assert got.num_rows == ref.num_rows, name
        for col in ref.column_names:
            if col not in got.column_names:
                assert col == "track_distance_m"  # a truth extra the tlog does not carry
                continue
            want = ref[col].to_numpy(zero_copy_only=False).astype(float)
            have = got[col].to_numpy(zero_copy_only=False).astype(float)
            assert got[col].null_count == ref[col].null_count, f"{name}.{col}"
            if name == "truth":
                np.testing.assert_allclose(have, want, rtol=0, atol=tolerances[col], err_msg=col)
            else:  # imu and gnss references are already as the tlog holds them
                np.testing.assert_array_equal(have, want, err_msg=f"{name}.{col}")
