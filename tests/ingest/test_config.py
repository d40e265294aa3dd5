"""Dataset descriptors (dataset.yaml)."""

from __future__ import annotations

from pathlib import Path

import pytest

from navreplay.ingest.config import load_dataset_config, log_paths, parse_dataset_config
from navreplay.ingest.errors import ConfigError


def test_minimal_descriptor_has_defaults() -> None:
    cfg = parse_dataset_config({"id": "my_drive"})
    assert cfg.imu.frame == "auto"
    assert cfg.gnss.lever_arm_m == (0.0, 0.0, 0.0)
    assert cfg.logs == ()


def test_full_descriptor_round_trips(tmp_path: Path) -> None:
    path = tmp_path / "dataset.yaml"
    path.write_text(
        """
id: drive_1
logs: [raw/a.mcap, /abs/b.obs]
required: [imu, gnss]
imu:
  topic: /imu/data
  frame: flu
  mounting_rpy_deg: [0, 90, 0]
  noise:
    accel_noise_mps2_rthz: 0.002
    gyro_noise_radps_rthz: 0.0002
    accel_bias_sigma_mps2: 0.05
    gyro_bias_sigma_radps: 0.001
    accel_bias_rw_mps3_rthz: 0.0001
    gyro_bias_rw_radps2_rthz: 0.00001
gnss: {lever_arm_m: [0.5, 0, -1.2]}
csv:
  - path: wheel.csv
    table: vehicle
    time_column: t
    time_unit: s
    columns: {speed_mps: v}
"""
    )
    cfg = load_dataset_config(path)
    assert cfg.imu.mounting_rpy_deg == (0.0, 90.0, 0.0)
    assert cfg.imu.noise is not None
    assert cfg.imu.noise.gyro_noise_radps_rthz == 0.0002
    assert cfg.csv[0].columns["speed_mps"] == "v"
    assert log_paths(cfg, path) == [tmp_path / "raw/a.mcap", Path("/abs/b.obs")]


@pytest.mark.parametrize(
    ("data", "key"),
    [
        ({"id": "x", "imu": {"topc": "/imu"}}, "imu.topc"),
        ({"id": "x", "imu": {"frame": "enu"}}, "imu.frame"),
        ({"id": "x", "gnss": {"lever_arm_m": [1, 2]}}, "gnss.lever_arm_m"),
        ({"id": "x", "required": ["imu", "gps"]}, "required[1]"),
        ({"id": "Bad-Id"}, "id"),
        ({"description": "no id"}, "id"),
    ],
)
def test_errors_name_file_and_key(tmp_path: Path, data: dict[str, object], key: str) -> None:
    with pytest.raises(ConfigError) as err:
        parse_dataset_config(data, source=tmp_path / "dataset.yaml")
    assert f"{key}:" in str(err.value)
    assert "dataset.yaml" in str(err.value)


def test_missing_file_is_a_config_error(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="cannot read dataset descriptor"):
        load_dataset_config(tmp_path / "absent.yaml")
