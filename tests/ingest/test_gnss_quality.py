"""The receiver's dilutions of precision (``gnss.hdop``/``vdop``) from every autopilot format:
MAVLink GPS_RAW_INT ``eph``/``epv`` (DOP x 100, UINT16_MAX unknown), ArduPilot GPS ``HDop`` and
GPA ``VDop``, PX4 ``vehicle_gps_position`` ``hdop``/``vdop``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from navreplay.ingest.api import ingest
from navreplay.ingest.tables import read_table
from tests.ingest.mavlogs import DriveSpec, tlog_drive

SHARED = Path(__file__).resolve().parents[3] / "shared" / "data"


def test_tlog_dop_is_eph_and_epv_over_100(tmp_path: Path) -> None:
    path = tlog_drive(DriveSpec(seconds=2.0)).write(tmp_path / "f.tlog")  # eph 121, epv 200
    ingest([path], tmp_path / "out")
    gnss = read_table(tmp_path / "out" / "gnss.parquet", "gnss").table
    np.testing.assert_allclose(gnss.column("hdop").to_numpy(), 1.21)
    np.testing.assert_allclose(gnss.column("vdop").to_numpy(), 2.00)


@pytest.mark.parametrize(
    ("rel", "hdop", "vdop"),
    [
        ("uob_flightlab_ardupilot_bin/2023-07-06_10-12-18.bin", (0.58, 0.59), (0.84, 0.85)),
        ("uavlogviewer_sitl_tlog/vtol.tlog", (1.21, 1.21), (2.0, 2.0)),
        ("corpus_2026/px4_v190_fmuv3_flight.ulg", (0.72, 0.81), (1.09, 1.21)),
    ],
)
def test_real_logs_give_their_dop(
    tmp_path: Path, rel: str, hdop: tuple[float, float], vdop: tuple[float, float]
) -> None:
    path = SHARED / rel
    if not path.is_file():
        pytest.skip(f"real data not present: {path} (../shared/data is read in place)")
    ingest([path], tmp_path / "out")
    gnss = read_table(tmp_path / "out" / "gnss.parquet", "gnss").table.to_pandas()
    for name, (lo, hi) in (("hdop", hdop), ("vdop", vdop)):
        v = gnss[name]
        assert v.notna().all(), name
        assert lo - 0.005 <= v.min() <= v.max() <= hi + 0.005, (name, v.min(), v.max())
