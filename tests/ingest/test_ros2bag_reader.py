"""rosbag2 directories: sqlite3 and MCAP storage, versions 8 and 9 (catalogue cases 11, 12)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from navreplay.ingest.api import IngestOptions, ingest
from navreplay.ingest.errors import CorruptLogError, IngestError

from .roslogs import fix_stream, imu_data, imu_stream, odom_stream, write_bag2


@pytest.mark.parametrize("storage", ["sqlite3", "mcap"])
@pytest.mark.parametrize("version", [8, 9])
def test_round_trip_through_ingest(tmp_path: Path, storage: str, version: int) -> None:
    data = imu_data(500)
    bag = write_bag2(
        tmp_path / "bag",
        [imu_stream(data), fix_stream(20), odom_stream(40)],
        version=version,
        storage=storage,
    )
    result = ingest([bag], tmp_path / "out")
    assert result.tables == {"imu": 500, "gnss": 20, "vehicle": 40}
    assert result.report["files"][0]["completeness"] == ["complete"]
    import pyarrow.parquet as pq

    imu = pq.read_table(tmp_path / "out" / "imu.parquet")
    np.testing.assert_array_equal(imu["t_ns"].to_numpy(), data.t_ns)
    # FLU -> FRD, and a level IMU needs no mounting: specific force (0, 0, -g) at rest.
    np.testing.assert_array_equal(imu["acc_z_mps2"].to_numpy(), -data.acc[:, 2])
    np.testing.assert_array_equal(imu["gyro_y_radps"].to_numpy(), -data.gyro[:, 1])


def test_mcap_storage_without_metadata_is_recovered(tmp_path: Path) -> None:
    # Case 11 (MCAP storage): E-RECOVER with the missing metadata in the report.
    bag = write_bag2(tmp_path / "bag", [imu_stream(imu_data(300))], storage="mcap")
    (bag / "metadata.yaml").unlink()
    result = ingest([bag], tmp_path / "out")
    assert result.tables["imu"] == 300
    (f,) = result.report["files"]
    assert f["completeness"] == ["missing_metadata"]
    with pytest.raises(CorruptLogError, match=r"metadata\.yaml"):
        ingest([bag], tmp_path / "strict", options=IngestOptions(strict=True))
    assert not (tmp_path / "strict").exists()


def test_db3_storage_without_metadata_is_fatal_with_the_repair_command(tmp_path: Path) -> None:
    # Case 11 (sqlite3 storage).
    bag = write_bag2(tmp_path / "bag", [imu_stream(imu_data(50))], storage="sqlite3")
    (bag / "metadata.yaml").unlink()
    with pytest.raises(CorruptLogError, match="ros2 bag reindex"):
        ingest([bag], tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_truncated_db3_is_fatal_naming_the_bag(tmp_path: Path) -> None:
    # Case 12: recovery of a damaged SQLite file is outside the pipeline.
    bag = write_bag2(tmp_path / "bag", [imu_stream(imu_data(3000))], storage="sqlite3")
    db = next(bag.glob("*.db3"))
    os.truncate(db, db.stat().st_size // 2)
    with pytest.raises(IngestError) as err:
        ingest([bag], tmp_path / "out")
    assert str(bag) in str(err.value) or str(db) in str(err.value)
    assert not (tmp_path / "out").exists()
