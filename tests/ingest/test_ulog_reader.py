"""PX4 ULog reader: columns through pyulog, GPS time pairing, and damaged files (cases 7, 15,
21). Fixtures are packed with ``struct`` in the ULog layout (``tests.ingest.mavlogs``) and
checked to be read by pyulog itself."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from navreplay.ingest.api import IngestOptions, ingest
from navreplay.ingest.errors import CorruptLogError, UnsupportedFormatError
from navreplay.ingest.readers.ulog.ulogmsgs import euler_from_quaternion, reproject
from navreplay.ingest.timebase import utc_to_gps_ns

from .mavlogs import UTC0_US, G, ulog_drive


def test_imu_and_gps_columns_on_gps_time(tmp_path: Path) -> None:
    path = tmp_path / "a.ulg"
    path.write_bytes(ulog_drive().bytes())
    result = ingest([path], tmp_path / "out")
    assert result.tables == {"imu": 400, "gnss": 10}
    assert result.report["time_base"]["base"] == "gps"
    imu = pq.read_table(tmp_path / "out" / "imu.parquet").to_pandas()
    # timestamp (boot us) + (time_utc_usec - timestamp), then UTC -> GPS.
    want = utc_to_gps_ns((UTC0_US + 10_000_000 + np.arange(400) * 5_000) * 1000)
    np.testing.assert_array_equal(imu["t_ns"], want)
    assert imu["acc_z_mps2"].mean() == pytest.approx(-G, abs=0.01)
    gnss = pq.read_table(tmp_path / "out" / "gnss.parquet").to_pandas()
    row = gnss.iloc[0]
    assert row["lat_deg"] == 634_170_622 / 1e7
    assert row["alt_m"] == 106.766  # alt_ellipsoid
    assert (row["h_acc_m"], row["v_acc_m"]) == pytest.approx((1.2, 2.1))
    assert row["speed_acc_mps"] == pytest.approx(0.3)
    assert (row["vel_n_mps"], row["vel_e_mps"], row["vel_d_mps"]) == pytest.approx(
        (0.1, -0.2, 0.05)
    )
    assert (row["fix_type"], row["num_sats"]) == (3, 15)


def test_without_gps_the_boot_clock_is_kept(tmp_path: Path) -> None:
    path = tmp_path / "a.ulg"
    path.write_bytes(ulog_drive(gps=False).bytes())
    result = ingest([path], tmp_path / "out")
    assert result.tables == {"imu": 400}
    assert result.report["time_base"]["base"] == "recorder"
    t = pq.read_table(tmp_path / "out" / "imu.parquet")["t_ns"].to_numpy()
    assert t[0] == 10_000_000 * 1000


def test_truncated_ulog_reports_the_partial_message(tmp_path: Path) -> None:
    # Case 15 for ULog: pyulog drops the cut message silently; the reader reports it.
    data = ulog_drive().bytes()
    path = tmp_path / "a.ulg"
    path.write_bytes(data[:-7])
    result = ingest([path], tmp_path / "out")
    (defect,) = result.report["files"][0]["defects"]
    assert defect["kind"] == "partial_record_dropped"
    last = len(data) - (3 + 2 + 32)  # the last message: a sensor_combined sample
    assert defect["offset"] == last
    assert result.tables["imu"] == 399
    with pytest.raises(CorruptLogError, match=f"offset {last}"):
        ingest([path], tmp_path / "strict", options=IngestOptions(strict=True))


def test_ulog_magic_followed_by_noise_fails_naming_the_file(tmp_path: Path) -> None:
    # Case 7.
    path = tmp_path / "x.ulg"
    path.write_bytes(b"ULog\x01\x12\x35")
    with pytest.raises((CorruptLogError, UnsupportedFormatError), match=str(path)):
        ingest([path], tmp_path / "out")
    for seed in range(5):
        noise = np.random.default_rng(seed).integers(0, 256, 3000, dtype=np.uint8).tobytes()
        path.write_bytes(b"ULog\x01\x12\x35\x01" + bytes(8) + noise)
        with pytest.raises(CorruptLogError, match=str(path)):
            ingest([path], tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_quaternion_to_euler_round_trip() -> None:
    rng = np.random.default_rng(5)
    roll, pitch, yaw = (
        rng.uniform(-1.2, 1.2, 50),
        rng.uniform(-1.2, 1.2, 50),
        rng.uniform(-3, 3, 50),
    )
    cr, sr = np.cos(roll / 2), np.sin(roll / 2)
    cp, sp = np.cos(pitch / 2), np.sin(pitch / 2)
    cy, sy = np.cos(yaw / 2), np.sin(yaw / 2)
    q = np.stack(
        [
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        ],
        axis=1,
    )
    got = euler_from_quaternion(q)
    np.testing.assert_allclose(np.stack(got), np.stack([roll, pitch, yaw]), atol=1e-12)


def test_px4_reprojection_keeps_distances() -> None:
    # Azimuthal equidistant: the distance from the reference is preserved exactly.
    x, y = np.array([0.0, 1000.0, -250.0]), np.array([0.0, 500.0, 2000.0])
    lat, lon = reproject(x, y, np.full(3, 47.3977), np.full(3, 8.5456))
    lat0, lat1 = np.radians(47.3977), np.radians(lat)
    dlon = np.radians(lon - 8.5456)
    central = np.arccos(np.sin(lat0) * np.sin(lat1) + np.cos(lat0) * np.cos(lat1) * np.cos(dlon))
    np.testing.assert_allclose(central * 6_371_000.0, np.hypot(x, y), atol=1e-6)
