"""Real data: the robot_localization Husky log in all five containers (../shared/data).

The same 395 s drive as a ROS 1 bz2 bag, an uncompressed bag, a ROS 1-profile MCAP and
rosbag2 MCAP and sqlite3 directories. Every one must give the same tables: 11,865 IMU
samples at 30 Hz, 989 fixes at 2.5 Hz, 3,952 odometry samples at 10 Hz. The IMU is mounted
with gravity on its +Y axis; after the detected mounting correction the specific force at
rest is (0, 0, -9.8) m/s^2 in body FRD, and the gyro's z axis tracks the wheel odometry's yaw
rate (both FRD), which checks the axes physically.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.parquet as pq
import pytest

from navreplay.ingest.api import IngestResult, ingest

DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "robot_localization"
FILES = [
    "test1.bag",
    "derived/test1_uncompressed.bag",
    "derived/test1_ros1.mcap",
    "derived/test1_rosbag2_mcap",
    "derived/test1_rosbag2_sqlite3",
]
FORMATS = ["ros1bag", "ros1bag", "mcap", "ros2bag", "ros2bag"]


@pytest.fixture(scope="module")
def ingested(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[IngestResult, Path]]:
    if not DATA.is_dir():
        pytest.skip(f"shared data not present at {DATA}")
    out: dict[str, tuple[IngestResult, Path]] = {}
    for name in FILES:
        target = tmp_path_factory.mktemp("rl") / "tables"
        out[name] = (ingest([DATA / name], target), target)
    return out


def _table(target: Path, name: str) -> Any:
    return pq.read_table(target / f"{name}.parquet").to_pandas()


@pytest.mark.parametrize(("name", "fmt"), list(zip(FILES, FORMATS, strict=True)))
def test_counts_rates_and_completeness(
    ingested: dict[str, tuple[IngestResult, Path]], name: str, fmt: str
) -> None:
    result, _ = ingested[name]
    assert result.tables == {"imu": 11_865, "gnss": 989, "vehicle": 3_952}
    report = result.report
    (f,) = report["files"]
    assert f["format"] == fmt
    assert f["completeness"] == ["complete"]
    rates = {t: report["tables"][t]["stats"]["rate_hz"] for t in ("imu", "gnss", "vehicle")}
    assert rates["imu"] == pytest.approx(30.0, abs=0.05)
    assert rates["gnss"] == pytest.approx(2.5, abs=0.01)
    assert rates["vehicle"] == pytest.approx(10.1, abs=0.1)
    for t in ("imu", "gnss", "vehicle"):
        hyg = report["tables"][t]["hygiene"]
        assert hyg["reordered"] == hyg["dropped_late"] == 0
        assert report["tables"][t]["stats"]["gaps"]["count"] == 0
    assert report["time_base"]["base"] == "utc"


@pytest.mark.parametrize("name", FILES)
def test_imu_comes_out_level_after_the_detected_mounting(
    ingested: dict[str, tuple[IngestResult, Path]], name: str
) -> None:
    result, target = ingested[name]
    plaus = result.report["tables"]["imu"]["plausibility"]
    assert plaus["tilt_before_mounting_deg"] > 80  # gravity on the sensor's Y axis
    mounting = plaus["mounting"]
    assert mounting["source"].startswith("detected from gravity")
    roll, pitch, yaw = mounting["rpy_deg"]
    assert roll == pytest.approx(88.7, abs=0.5)
    assert abs(pitch) < 3.0
    assert yaw == 0.0
    f_rest = np.array(mounting["specific_force_body_mps2"])
    np.testing.assert_allclose(f_rest, [0.0, 0.0, -9.7986], atol=1e-3)
    imu = _table(target, "imu")
    # Over the whole drive too (it includes motion): close to level.
    mean = imu[["acc_x_mps2", "acc_y_mps2", "acc_z_mps2"]].mean().to_numpy()
    assert abs(mean[0]) < 0.2
    assert abs(mean[1]) < 0.2
    assert mean[2] == pytest.approx(-9.79, abs=0.05)
    assert plaus["gravity_magnitude_mps2"] == pytest.approx(9.80, abs=0.05)
    assert np.linalg.norm(plaus["gyro_bias_at_rest_radps"]) < 0.01


@pytest.mark.parametrize("name", FILES)
def test_gyro_yaw_rate_tracks_wheel_odometry_in_frd(
    ingested: dict[str, tuple[IngestResult, Path]], name: str
) -> None:
    _, target = ingested[name]
    imu = _table(target, "imu")
    veh = _table(target, "vehicle")
    odo = np.interp(imu["t_ns"], veh["t_ns"], veh["yaw_rate_radps"])
    assert np.corrcoef(imu["gyro_z_radps"], odo)[0, 1] > 0.8
    slope = np.polyfit(odo, imu["gyro_z_radps"], 1)[0]
    assert slope == pytest.approx(1.0, abs=0.05)
    assert abs(np.corrcoef(imu["gyro_x_radps"], odo)[0, 1]) < 0.2


@pytest.mark.parametrize("name", FILES)
def test_value_ranges(ingested: dict[str, tuple[IngestResult, Path]], name: str) -> None:
    _, target = ingested[name]
    gnss = _table(target, "gnss")
    assert 42.3757 < gnss["lat_deg"].min() < gnss["lat_deg"].max() < 42.3772
    assert -71.1479 < gnss["lon_deg"].min() < gnss["lon_deg"].max() < -71.1470
    assert set(gnss["fix_type"].unique()) == {4}  # SBAS fix -> DGPS
    # Covariance diag (0.81, 0.81, 3.24) m^2 at the start -> 0.9 m / 1.8 m.
    assert gnss["h_acc_m"].iloc[0] == pytest.approx(0.9)
    assert gnss["v_acc_m"].iloc[0] == pytest.approx(1.8)
    veh = _table(target, "vehicle")
    assert -0.01 < veh["speed_mps"].min() < veh["speed_mps"].max() < 1.1
    imu = _table(target, "imu")
    assert imu[["gyro_x_radps", "gyro_y_radps", "gyro_z_radps"]].abs().max().max() < 1.0
    t0 = imu["t_ns"].iloc[0]
    assert 1_432_235_497 * 10**9 < t0 < 1_432_235_499 * 10**9  # 2015-05-21, UTC


def test_all_containers_give_identical_tables(
    ingested: dict[str, tuple[IngestResult, Path]],
) -> None:
    reference = {t: _table(ingested[FILES[0]][1], t) for t in ("imu", "gnss", "vehicle")}
    for name in FILES[1:]:
        for t, ref in reference.items():
            other = _table(ingested[name][1], t)
            assert other.equals(ref), f"{name}: {t}"
