"""meta.json round trip."""

from __future__ import annotations

from pathlib import Path

import pytest

from navreplay.ingest.config import ImuNoise
from navreplay.ingest.errors import ConfigError
from navreplay.ingest.meta import DatasetMeta, SensorMeta, SourceRecord, read_meta, write_meta
from navreplay.ingest.platform import Platform


def test_meta_round_trips(tmp_path: Path) -> None:
    noise = ImuNoise(0.002, 0.0002, 0.05, 0.001, 1e-4, 1e-5)
    meta = DatasetMeta(
        dataset="drive",
        time_base="gps",
        sources=(SourceRecord("a.mcap", "0" * 64, "mcap"),),
        tables={"imu": 100, "gnss": 2},
        sensors=SensorMeta(imu_noise=noise, lever_arm_m=(0.5, 0.0, -1.0)),
        frame_conversions=("imu: FLU->FRD",),
        audit={"imu": {"rate_hz": 100.0}},
    )
    write_meta(tmp_path, meta)
    assert read_meta(tmp_path) == meta


def test_missing_or_malformed_meta(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="ingest the dataset first"):
        read_meta(tmp_path)
    (tmp_path / "meta.json").write_text('{"dataset": "x", "time_base": "gps", "tables": {}}')
    with pytest.raises(ConfigError, match="sources: missing"):
        read_meta(tmp_path)


def test_platform_round_trips_and_a_wrong_kind_names_its_key(tmp_path: Path) -> None:
    meta = DatasetMeta(
        dataset="hover",
        time_base="gps",
        sources=(SourceRecord("a.tlog", "0" * 64, "tlog"),),
        tables={"imu": 100},
        sensors=SensorMeta(platform=Platform("multirotor", "HEARTBEAT type 2")),
    )
    write_meta(tmp_path, meta)
    assert read_meta(tmp_path) == meta
    path = tmp_path / "meta.json"
    path.write_text(path.read_text().replace('"multirotor"', '"blimp"'))
    with pytest.raises(ConfigError, match=r"sensors\.platform\.kind"):
        read_meta(tmp_path)
