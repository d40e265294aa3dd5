"""meta.json round trip."""

from __future__ import annotations

from pathlib import Path

import pytest

from navreplay.ingest.config import ImuNoise
from navreplay.ingest.errors import ConfigError
from navreplay.ingest.meta import DatasetMeta, SensorMeta, SourceRecord, read_meta, write_meta


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
