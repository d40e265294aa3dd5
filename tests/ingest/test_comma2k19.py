"""comma2k19 segments: a synthetic segment written with NumPy's own writer round-trips, damaged
arrays are salvaged with exact counts, and the real example segment (../shared/data) gives the
figures its SOURCE.txt states: 6,256 IMU samples at ~104.4 Hz, 579 u-blox fixes, 1,200 poses at
20 Hz, GPS week 2012, fixes 1.43 m (median) from the reference pose."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pymap3d
import pytest
from scipy.spatial.transform import Rotation

from navreplay.ingest.api import IngestOptions, IngestResult, ingest, inspect
from navreplay.ingest.config import parse_dataset_config
from navreplay.ingest.detect import Format, detect
from navreplay.ingest.ecef import c_ned_ecef
from navreplay.ingest.errors import CorruptLogError, UnsupportedFormatError
from navreplay.ingest.gpstime import GPS_EPOCH_UNIX_NS, NS_PER_S, NS_PER_WEEK

from .commacsv import DERIVED, SEGMENT, fix_mapping

WEEK, TOW0, BOOT0 = 2100, 3600.0, 1000.0
LAT0, LON0, ALT0 = 37.7, -122.4, 30.0
SPEED, HEADING_DEG, ROLL_DEG, PITCH_DEG = 10.0, 30.0, 2.0, -3.0


def _save(path: Path, array: np.ndarray) -> None:
    """As comma2k19 stores them: .npy content, no extension, 2-D arrays column-major."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("wb") as fh:
        np.save(fh, np.asfortranarray(array) if array.ndim == 2 else array)


def _geodetic(t_rel: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    north = SPEED * t_rel * math.cos(math.radians(HEADING_DEG))
    east = SPEED * t_rel * math.sin(math.radians(HEADING_DEG))
    lat, lon, alt = pymap3d.ned2geodetic(north, east, 0.0 * t_rel, LAT0, LON0, ALT0)
    return np.asarray(lat), np.asarray(lon), np.asarray(alt)


def write_segment(root: Path, *, seconds: float = 10.0, pose: bool = True) -> Path:
    """A car driving straight at 10 m/s, heading 30 deg, as a comma2k19 segment directory."""
    log = root / "processed_log"
    t_imu = BOOT0 + np.arange(0.0, seconds, 0.01)
    acc = np.tile([0.1, 0.0, -9.8], (len(t_imu), 1))
    gyro = np.tile([0.001, -0.002, 0.003], (len(t_imu), 1))
    for name, value in (("accelerometer", acc), ("gyro", gyro)):
        _save(log / "IMU" / name / "t", t_imu)
        _save(log / "IMU" / name / "value", value)
    t_fix = BOOT0 + 0.05 + np.arange(0.0, seconds - 0.1, 0.1)
    lat, lon, alt = _geodetic(t_fix - BOOT0 - 0.2)  # the fix describes 0.2 s before arrival
    gps_ns = _gps_ns(t_fix - 0.2)
    utc_ms = (gps_ns + GPS_EPOCH_UNIX_NS - 18 * NS_PER_S) / 1e6
    fixes = np.stack(
        [lat, lon, np.full_like(lat, SPEED), utc_ms, alt, np.full_like(lat, HEADING_DEG)], axis=1
    )
    _save(log / "GNSS/live_gnss_ublox/t", t_fix)
    _save(log / "GNSS/live_gnss_ublox/value", fixes)
    _save(log / "GNSS/raw_gnss_ublox/t", np.repeat(t_fix, 3))
    _save(log / "GNSS/raw_gnss_ublox/value", np.zeros((3 * len(t_fix), 10)))
    t_can = BOOT0 + 0.003 + np.arange(0.0, seconds - 0.1, 0.012)
    _save(log / "CAN/speed/t", t_can)
    _save(log / "CAN/speed/value", np.full((len(t_can), 1), SPEED))
    _save(log / "CAN/wheel_speed/t", t_can)
    _save(log / "CAN/wheel_speed/value", np.full((len(t_can), 4), SPEED))
    _save(log / "CAN/steering_angle/t", t_can - 0.005)
    _save(log / "CAN/steering_angle/value", np.full(len(t_can), 15.0))  # 15 deg to the left
    if pose:
        t_pose = BOOT0 + np.arange(0.0, seconds, 0.05)
        lat, lon, alt = _geodetic(t_pose - BOOT0)
        ecef = np.stack(pymap3d.geodetic2ecef(lat, lon, alt), axis=1)
        c_ecef_ned = np.transpose(c_ned_ecef(lat, lon), (0, 2, 1))
        v_ned = SPEED * np.array(
            [math.cos(math.radians(HEADING_DEG)), math.sin(math.radians(HEADING_DEG)), 0.0]
        )
        c_ned_cam = Rotation.from_euler("ZYX", [HEADING_DEG, PITCH_DEG, ROLL_DEG], degrees=True)
        q = Rotation.from_matrix(c_ecef_ned @ c_ned_cam.as_matrix()).as_quat(scalar_first=True)
        week_tow = np.stack([np.full_like(t_pose, WEEK), TOW0 + (t_pose - BOOT0)], axis=1)
        _save(root / "global_pose/frame_times", t_pose)
        _save(root / "global_pose/frame_gps_times", week_tow)
        _save(root / "global_pose/frame_positions", ecef)
        _save(root / "global_pose/frame_velocities", c_ecef_ned @ v_ned)
        _save(root / "global_pose/frame_orientations", q)
    return root


def _gps_ns(boot_s: np.ndarray | float) -> np.ndarray:
    return np.rint((np.asarray(boot_s) - BOOT0 + TOW0) * NS_PER_S).astype(np.int64) + (
        WEEK * NS_PER_WEEK
    )


def _tables(out: Path, *names: str) -> dict[str, pd.DataFrame]:
    return {n: pd.read_parquet(out / f"{n}.parquet") for n in names}


def test_segment_directory_is_detected_by_its_arrays(tmp_path: Path) -> None:
    seg = write_segment(tmp_path / "seg")
    found = detect(seg)
    assert found.format == Format.COMMA2K19
    assert seg / "global_pose/frame_times" in found.files
    with pytest.raises(UnsupportedFormatError, match="segment directory"):
        detect(seg / "processed_log/IMU/gyro/value")  # one array alone is not a log
    (tmp_path / "empty").mkdir()
    with pytest.raises(UnsupportedFormatError, match="comma2k19"):
        detect(tmp_path / "empty")


def test_synthetic_segment_round_trips_onto_gps_time(tmp_path: Path) -> None:
    seg = write_segment(tmp_path / "seg")
    out = tmp_path / "out"
    result = ingest([seg], out)
    assert result.report["time_base"]["base"] == "gps"
    t = _tables(out, "imu", "gnss", "vehicle", "truth")
    # Boot time -> GPS time through the global_pose pairing, exactly.
    np.testing.assert_array_equal(
        t["imu"]["t_ns"].to_numpy()[:3], _gps_ns(BOOT0 + np.arange(3) * 0.01)
    )
    truth = t["truth"]
    assert truth["t_ns"].iloc[0] == WEEK * NS_PER_WEEK + TOW0 * NS_PER_S
    lat, lon, alt = _geodetic(np.arange(0.0, 10.0, 0.05))
    np.testing.assert_allclose(truth["lat_deg"], lat, atol=1e-9)
    np.testing.assert_allclose(truth["lon_deg"], lon, atol=1e-9)
    np.testing.assert_allclose(truth["alt_m"], alt, atol=1e-4)
    heading = math.radians(HEADING_DEG)
    np.testing.assert_allclose(truth["vel_n_mps"], SPEED * math.cos(heading), atol=1e-6)
    np.testing.assert_allclose(truth["vel_e_mps"], SPEED * math.sin(heading), atol=1e-6)
    np.testing.assert_allclose(truth["vel_d_mps"], 0.0, atol=1e-6)
    np.testing.assert_allclose(np.degrees(truth["roll_rad"]), ROLL_DEG, atol=1e-6)
    np.testing.assert_allclose(np.degrees(truth["pitch_rad"]), PITCH_DEG, atol=1e-6)
    np.testing.assert_allclose(np.degrees(truth["yaw_rad"]), HEADING_DEG, atol=1e-6)
    gnss = t["gnss"]
    np.testing.assert_allclose(gnss["vel_n_mps"], SPEED * math.cos(heading), atol=1e-9)
    assert gnss["vel_d_mps"].isna().all()
    assert gnss["h_acc_m"].isna().all()
    assert set(gnss["fix_type"]) == {3}
    # The fix's own UTC epoch (leap seconds applied) is 0.2 s before its arrival.
    np.testing.assert_allclose(gnss["latency_s"], 0.2, atol=2e-6)
    imu = t["imu"]
    np.testing.assert_allclose(imu[["acc_x_mps2", "acc_z_mps2"]].iloc[0], [0.1, -9.8])
    np.testing.assert_allclose(imu["gyro_y_radps"], -0.002)


def test_can_speed_and_steering_keep_their_own_stamps(tmp_path: Path) -> None:
    seg = write_segment(tmp_path / "seg")
    n = len(np.arange(0.0, 9.9, 0.012))
    cfg = parse_dataset_config({"id": "c", "vehicle": {"steer_ratio": 15.0}})
    result = ingest([seg], tmp_path / "out", config=cfg)
    assert result.tables["vehicle"] == 2 * n  # union of the two stamp sets, none shared
    veh = pd.read_parquet(tmp_path / "out" / "vehicle.parquet")
    speed_rows = veh["speed_mps"].notna()
    assert speed_rows.sum() == n == veh["steer_wheel_rad"].notna().sum()
    assert (speed_rows != veh["steer_wheel_rad"].notna()).all()
    np.testing.assert_allclose(veh.loc[speed_rows, ["wheel_fl_mps", "wheel_rr_mps"]], SPEED)
    # 15 deg counter-clockwise at the wheel: negative (left) in the FRD convention.
    steer = veh["steer_wheel_rad"].dropna()
    np.testing.assert_allclose(steer, -math.radians(15.0))
    np.testing.assert_allclose(veh["steer_rad"].dropna(), -math.radians(15.0) / 15.0)
    vehicle = result.report["tables"]["vehicle"]
    assert "steer_ratio 15.0" in vehicle["info"]["steer_rad"]
    assert vehicle["counters"] == {
        "rows_with_both": 0,
        "rows_with_speed": n,
        "rows_with_steering": n,
    }
    plain = ingest([seg], tmp_path / "plain")  # no ratio: road-wheel angle not provided
    assert pd.read_parquet(tmp_path / "plain" / "vehicle.parquet")["steer_rad"].isna().all()
    assert "null" in plain.report["tables"]["vehicle"]["info"]["steer_rad"]


def test_raw_pseudoranges_are_listed_as_not_convertible(tmp_path: Path) -> None:
    seg = write_segment(tmp_path / "seg")
    (inv,), plans = inspect([seg])
    raw = inv.stream("GNSS/raw_gnss_ublox")
    assert raw is not None
    assert raw.table is None
    assert raw.count == 3 * 99
    assert "99 epochs" in raw.detail
    assert any("no broadcast ephemeris" in n for n in inv.notes)
    assert "gnss_obs" not in {t.value for t in plans}


def test_without_global_pose_the_boot_clock_is_kept(tmp_path: Path) -> None:
    seg = write_segment(tmp_path / "seg", pose=False)
    result = ingest([seg], tmp_path / "out")
    assert result.report["time_base"]["base"] == "recorder"
    assert "truth" not in result.tables
    imu = pd.read_parquet(tmp_path / "out" / "imu.parquet")
    assert imu["t_ns"].iloc[0] == BOOT0 * NS_PER_S
    assert "latency_s" not in pd.read_parquet(tmp_path / "out" / "gnss.parquet")


def test_truncated_array_yields_its_complete_rows(tmp_path: Path) -> None:
    seg = write_segment(tmp_path / "seg")
    value = seg / "processed_log/IMU/accelerometer/value"
    size = value.stat().st_size
    # Column-major (n, 3): cutting 100 values and a half leaves the last column 101 short.
    cut = size - 100 * 8 - 4
    with value.open("r+b") as fh:
        fh.truncate(cut)
    result = ingest([seg], tmp_path / "out")
    n = 1000
    assert result.tables["imu"] == n - 101
    (f,) = result.report["files"]
    assert f["completeness"] == ["truncated"]
    (defect,) = f["defects"]
    assert defect["messages_lost"] == 101
    assert defect["messages_recovered"] == n - 101
    assert defect["offset"] == 128 + (2 * n + n - 101) * 8  # first missing value
    assert "value" in defect["reason"]
    with pytest.raises(CorruptLogError, match="accelerometer/value"):
        ingest([seg], tmp_path / "strict", options=IngestOptions(strict=True))
    assert not (tmp_path / "strict").exists()


def test_time_faults_in_the_arrays_reach_the_stream_hygiene(tmp_path: Path) -> None:
    seg = write_segment(tmp_path / "seg")
    t = BOOT0 + np.arange(0.0, 10.0, 0.01)
    for i in (100, 300, 500):  # case 29: swapped neighbours
        t[[i, i + 1]] = t[[i + 1, i]]
    t[700] = t[699]  # case 30: a repeated stamp
    keep = np.ones(len(t), bool)
    keep[800:900] = False  # case 33: a 1 s hole
    for name, row in (("accelerometer", [0.1, 0.0, -9.8]), ("gyro", [0.0, 0.0, 0.01])):
        _save(seg / "processed_log/IMU" / name / "t", t[keep])
        _save(seg / "processed_log/IMU" / name / "value", np.tile(row, (int(keep.sum()), 1)))
    result = ingest([seg], tmp_path / "out")
    imu = result.report["tables"]["imu"]
    assert imu["hygiene"]["reordered"] == 3
    assert imu["hygiene"]["duplicates_exact_dropped"] == 1
    assert imu["stats"]["gaps"]["count"] == 1
    assert imu["stats"]["gaps"]["longest_s"] == pytest.approx(1.01)


def test_bad_array_fails_naming_the_file(tmp_path: Path) -> None:
    seg = write_segment(tmp_path / "seg")
    (seg / "processed_log/CAN/speed/value").write_bytes(b"\x93NUMPY\x01\x00garbage")
    with pytest.raises(CorruptLogError, match=r"CAN/speed/value.*header"):
        ingest([seg], tmp_path / "out")
    assert not (tmp_path / "out").exists()


# ------------------------------------------------------------------------------ real segment
@pytest.fixture(scope="module")
def real(tmp_path_factory: pytest.TempPathFactory) -> tuple[IngestResult, dict[str, pd.DataFrame]]:
    if not SEGMENT.is_dir():
        pytest.skip(f"shared data not present at {SEGMENT}")
    out = tmp_path_factory.mktemp("comma") / "tables"
    result = ingest([SEGMENT], out)
    return result, _tables(out, "imu", "gnss", "vehicle", "truth")


def test_real_segment_counts_rates_and_time_base(
    real: tuple[IngestResult, dict[str, pd.DataFrame]],
) -> None:
    result, t = real
    assert result.tables == {"imu": 6256, "gnss": 579, "vehicle": 4974 + 4974 - 21, "truth": 1200}
    report = result.report
    assert report["files"][0]["completeness"] == ["complete"]
    assert report["tables"]["vehicle"]["counters"] == {
        "rows_with_both": 21,
        "rows_with_speed": 4974,
        "rows_with_steering": 4974,
    }
    stats = {k: v["stats"] for k, v in report["tables"].items()}
    assert stats["imu"]["rate_hz"] == pytest.approx(104.4, abs=0.1)  # median dt 9.58 ms
    assert stats["truth"]["rate_hz"] == pytest.approx(20.0, abs=0.01)
    assert stats["gnss"]["rate_hz"] == pytest.approx(10.0, abs=0.05)
    assert 579 / stats["gnss"]["duration_s"] == pytest.approx(9.7, abs=0.1)
    assert report["time_base"]["base"] == "gps"
    for name, frame in t.items():
        week, rem = np.divmod(frame["t_ns"].to_numpy(), NS_PER_WEEK)
        assert set(week) == {2012}, name
        assert rem.min() / 1e9 >= 404_105.0, name  # SOURCE: TOW 404106..404166
        assert rem.max() / 1e9 <= 404_167.0, name
    assert all(v["hygiene"]["reordered"] == 0 for v in report["tables"].values())


def test_real_imu_is_frd_with_gravity_down(
    real: tuple[IngestResult, dict[str, pd.DataFrame]],
) -> None:
    result, t = real
    plaus = result.report["tables"]["imu"]["plausibility"]
    # The car never stops: gravity is the mean over the minute (quasi-static).
    assert plaus["rest_windows_1s"] == 0
    assert plaus["gravity_magnitude_mps2"] == pytest.approx(9.68, abs=0.05)
    assert plaus["tilt_before_mounting_deg"] < 5.0
    assert plaus["mounting"]["source"] == "none"
    imu = t["imu"]
    assert imu["acc_z_mps2"].mean() == pytest.approx(-9.66, abs=0.05)
    # The gyro's z axis tracks the reference's yaw rate (both FRD: positive turning right).
    truth = t["truth"]
    tt = truth["t_ns"].to_numpy()
    yaw_rate = np.gradient(np.unwrap(truth["yaw_rad"].to_numpy()), tt * 1e-9)
    gz = np.interp(tt, imu["t_ns"], imu["gyro_z_radps"])
    assert np.corrcoef(gz, yaw_rate)[0, 1] > 0.75
    assert np.polyfit(yaw_rate, gz, 1)[0] == pytest.approx(0.92, abs=0.1)


def test_real_steering_sign_follows_the_yaw_rate(
    real: tuple[IngestResult, dict[str, pd.DataFrame]],
) -> None:
    _, t = real
    veh = t["vehicle"].dropna(subset=["steer_wheel_rad"])
    gz = np.interp(veh["t_ns"], t["imu"]["t_ns"], t["imu"]["gyro_z_radps"])
    kernel = np.ones(50) / 50
    smooth = np.convolve(veh["steer_wheel_rad"], kernel, "valid"), np.convolve(gz, kernel, "valid")
    assert np.corrcoef(*smooth)[0, 1] > 0.85  # positive right in both
    assert np.degrees(veh["steer_wheel_rad"]).between(-5.0, 5.0).all()  # a straight road
    speed = t["vehicle"]["speed_mps"].dropna()
    assert 7.9 < speed.min() < speed.max() < 19.9


def test_real_fixes_agree_with_the_reference_pose(
    real: tuple[IngestResult, dict[str, pd.DataFrame]],
) -> None:
    result, t = real
    gnss, truth = t["gnss"], t["truth"]
    tg, tt = gnss["t_ns"].to_numpy(), truth["t_ns"].to_numpy()
    inside = (tg > tt[0]) & (tg < tt[-1])
    ref = [np.interp(tg, tt, truth[c]) for c in ("lat_deg", "lon_deg", "alt_m")]
    n, e, d = pymap3d.geodetic2ned(gnss["lat_deg"], gnss["lon_deg"], gnss["alt_m"], *ref)
    horizontal = np.hypot(n, e)[inside]
    assert np.median(horizontal) == pytest.approx(1.43, abs=0.02)  # SOURCE.txt's check
    assert np.percentile(horizontal, 95) == pytest.approx(1.87, abs=0.05)
    assert np.median(np.abs(d[inside])) == pytest.approx(1.12, abs=0.03)  # ellipsoidal alt
    assert gnss["latency_s"].median() == pytest.approx(0.204, abs=0.005)
    assert 37.7209 < gnss["lat_deg"].min() < gnss["lat_deg"].max() < 37.7302
    assert -122.473 < gnss["lon_deg"].min() < gnss["lon_deg"].max() < -122.471
    # Speed-based alignment (ingest.alignment): fixes stamped at arrival trail the CAN speed
    # and the reference by ~0.15 s, the CAN speed and the reference agree within 0.05 s.
    lags = {tuple(a["streams"]): a for a in result.report["time_base"]["alignment"]}
    assert lags[("gnss", "truth")]["lag_s"] == pytest.approx(-0.14, abs=0.05)
    assert lags[("gnss", "vehicle")]["lag_s"] == pytest.approx(-0.16, abs=0.05)
    assert abs(lags[("vehicle", "truth")]["lag_s"]) < 0.05
    assert lags[("vehicle", "truth")]["speed_ratio"] == pytest.approx(1.008, abs=0.005)
    assert result.report["warnings"] == []


def test_real_reference_is_the_camera_pose(
    real: tuple[IngestResult, dict[str, pd.DataFrame]],
) -> None:
    result, t = real
    truth = t["truth"]
    course = np.degrees(np.arctan2(truth["vel_e_mps"], truth["vel_n_mps"]))
    yaw_minus_course = np.degrees(truth["yaw_rad"]) - course
    assert np.median(yaw_minus_course) == pytest.approx(-0.9, abs=0.3)  # camera yaw mounting
    assert np.abs(np.degrees(truth[["roll_rad", "pitch_rad"]].to_numpy())).max() < 7.0
    assert truth["vel_d_mps"].abs().max() < 1.1
    assert "road camera" in result.report["tables"]["truth"]["info"]["truth"]
    notes: list[Any] = result.report["files"][0]["inventory_notes"]
    assert any("357697.849502" in n for n in notes)


def test_real_derived_csv_copy_carries_the_same_fixes(tmp_path: Path) -> None:
    if not DERIVED.is_dir():
        pytest.skip(f"shared data not present at {DERIVED}")
    cfg = parse_dataset_config({"id": "q", "gnss": {"topic": "GNSS/live_gnss_qcom"}})
    seg = ingest([SEGMENT], tmp_path / "seg", config=cfg)
    assert seg.tables["gnss"] == 30
    csv_cfg = parse_dataset_config({"id": "q", "csv": [fix_mapping("qcom")]})
    ingest([DERIVED / "gnss_fix_qcom.csv"], tmp_path / "csv", config=csv_cfg, config_dir=DERIVED)
    a = pd.read_parquet(tmp_path / "seg" / "gnss.parquet")
    b = pd.read_parquet(tmp_path / "csv" / "gnss.parquet")
    np.testing.assert_allclose(
        a[["lat_deg", "lon_deg", "alt_m"]], b[["lat_deg", "lon_deg", "alt_m"]], atol=1e-9
    )
    # The CSV stays on the boot clock; the segment reader adds the global_pose pairing.
    offset = (a["t_ns"] - b["t_ns"]).to_numpy()
    expected = 2012 * NS_PER_WEEK + 357_697_849_502_000
    assert np.abs(offset - expected).max() < 1_000  # the CSV keeps 9 decimals of a second
