"""The ``mag`` table of the real logs in ``../shared/data`` (skipped when absent), against the
formats' own readers (pymavlink, pyulog): every compass record, in gauss, a field of Earth's
strength (0.2-0.7 G); a log without a magnetometer stream (the Husky bag) gets no table."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.parquet as pq
import pytest
from pymavlink import mavutil

from navreplay.ingest.api import ingest

DATA = Path(__file__).resolve().parents[3] / "shared" / "data"
COLS = ["mag_x_gauss", "mag_y_gauss", "mag_z_gauss"]


def need(path: Path) -> Path:
    if not path.exists():
        pytest.skip(f"{path} is absent (../shared/data is not beside the checkout)")
    return path


def _mag(path: Path, out: Path) -> tuple[Any, dict[str, Any]]:
    result = ingest([path], out)
    return pq.read_table(out / "mag.parquet").to_pandas(), result.report["tables"]["mag"]


def _mavlink(path: Path, name: str, keep: Any = None) -> list[Any]:
    conn = mavutil.mavlink_connection(str(path))
    out = []
    while (m := conn.recv_match(type=name)) is not None:
        if keep is None or keep(m):
            out.append(m)
    return out


def _earth_like(mag: Any) -> None:
    norm = np.linalg.norm(mag[COLS].to_numpy(), axis=1)
    assert 0.2 < float(np.nanmedian(norm)) < 0.7


@pytest.mark.parametrize(
    ("rel", "message", "stream"),
    [
        ("uob_flightlab_ardupilot_bin/2023-07-06_10-12-18.bin", "MAG", "MAG[0]"),
        ("corpus_2026/ap_copter33_2015_log171.bin", "MAG", "MAG"),
    ],
)
def test_ardupilot_mag(rel: str, message: str, stream: str, tmp_path: Path) -> None:
    path = need(DATA / rel)
    mag, report = _mag(path, tmp_path / "out")
    assert report["stream"] == stream
    ref = _mavlink(path, message, lambda m: getattr(m, "I", 0) == 0)
    assert len(mag) == len(ref)
    np.testing.assert_array_equal(mag["mag_z_gauss"], [m.MagZ / 1000.0 for m in ref])
    _earth_like(mag)


def test_px4_sdlog2_imu_mag(tmp_path: Path) -> None:
    path = need(DATA / "corpus_2026" / "px4_sdlog2_2015_purdue.px4log")
    mag, report = _mag(path, tmp_path / "out")
    assert (report["stream"], report["msgtype"]) == ("IMU.mag", "IMU")
    ref = _mavlink(path, "IMU")
    assert len(mag) == len(ref) == 5742
    np.testing.assert_allclose(mag["mag_x_gauss"], [m.MagX for m in ref], rtol=1e-7)
    _earth_like(mag)


def test_tlog_scaled_imu2_mag(tmp_path: Path) -> None:
    path = need(DATA / "uavlogviewer_sitl_tlog" / "vtol.tlog")
    mag, report = _mag(path, tmp_path / "out")
    assert report["stream"] == "SCALED_IMU2.mag"
    # the log holds a few packets out of time order: ingest sorts them by time_boot_ms
    ref = sorted(_mavlink(path, "SCALED_IMU2"), key=lambda m: m.time_boot_ms)
    assert len(mag) == len(ref)
    np.testing.assert_array_equal(mag["mag_x_gauss"], [m.xmag / 1000.0 for m in ref])
    _earth_like(mag)


def test_ulog_vehicle_magnetometer(tmp_path: Path) -> None:
    from pyulog import ULog

    path = need(DATA / "corpus_2026" / "px4_v190_sitl_truth.ulg")
    mag, report = _mag(path, tmp_path / "out")
    assert report["stream"] == "vehicle_magnetometer[0]"
    ref = ULog(str(path), ["vehicle_magnetometer"]).data_list[0].data
    np.testing.assert_array_equal(mag["mag_y_gauss"], ref["magnetometer_ga[1]"])
    _earth_like(mag)


def test_bag_without_magnetometer_has_no_table(tmp_path: Path) -> None:
    path = need(DATA / "robot_localization" / "test1.bag")
    result = ingest([path], tmp_path / "out")
    assert "mag" not in result.tables
