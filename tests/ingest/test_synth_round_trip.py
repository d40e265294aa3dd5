"""The synthesizers' logs round-trip: ingesting the MCAP and ROS 1 bag that
``ingest.writers.ros`` writes, and the CSV logs of the vehicle datasets, reproduces the
synthesizers' own tables.

The writer stamps ROS messages in UTC (GPS - 18 s); ingest converts back to the GPS time base
the dataset declares. Every column ROS can carry comes back bit for bit; ``num_sats`` has no
field in ``sensor_msgs/NavSatFix`` and comes back null (not provided).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.parquet as pq
import pytest

from ingest.api import ingest
from ingest.config import input_paths, load_dataset_config, parse_dataset_config
from ingest.tables import read_table
from ingest.writers import ros
from pipeline.params import load_params
from pipeline.synth import car, tractor_log
from pipeline.synth.seoul_campus import simulate
from pipeline.synth.tractor import TractorStraightParams

REPO = Path(__file__).resolve().parents[2]
NOT_IN_ROS = {("gnss", "num_sats")}


@pytest.fixture(scope="module")
def synth() -> Any:
    params = load_params(REPO / "params.yaml").synth.seoul_campus
    short = dataclasses.replace(params, duration_s=25.0, stationary_s=10.0)
    return simulate(short, seed=11, variant="cw")


@pytest.mark.parametrize("container", ["mcap", "bag"])
def test_ingest_reproduces_the_synthesizer_tables(
    synth: Any, tmp_path: Path, container: str
) -> None:
    tables = {k: synth.tables[k] for k in ("imu", "gnss", "truth")}
    log = tmp_path / f"drive.{container}"
    write = ros.write_mcap if container == "mcap" else ros.write_bag
    write(log, tables, ros.RosOptions(time_base="gps"))
    cfg = parse_dataset_config({"id": "seoul_short", "time_base": "gps"})
    result = ingest([log], tmp_path / "tables", config=cfg)
    assert result.tables == {k: t.num_rows for k, t in tables.items()}
    assert result.report["time_base"]["leap_seconds"] == 18
    assert result.report["tables"]["gnss"]["companion"]["joined"] == tables["gnss"].num_rows
    for name, ref in tables.items():
        got = pq.read_table(tmp_path / "tables" / f"{name}.parquet")
        for col in ref.column_names:
            a = ref[col].to_numpy(zero_copy_only=False)
            b = got[col].to_numpy(zero_copy_only=False)
            if (name, col) in NOT_IN_ROS:
                assert got[col].null_count == got.num_rows
            elif a.dtype.kind == "f":
                np.testing.assert_array_equal(a, b, err_msg=f"{name}.{col}")
                assert got[col].null_count == ref[col].null_count
            else:
                np.testing.assert_array_equal(a, b, err_msg=f"{name}.{col}")
    # A level, well-mounted IMU: no mounting correction, units plausible.
    assert result.report["tables"]["imu"]["plausibility"]["mounting"]["source"] == "none"


CSV_CASES = {
    "tractor_straight": lambda out: tractor_log.write(
        TractorStraightParams(duration_s=10.0), 5, out
    ),
    "car_speed_ramp": lambda out: car.write(
        dataclasses.replace(car.CarSpeedRampParams(), ramp_s=20.0, hold_s=2.0), 5, out
    ),
}


@pytest.mark.parametrize("dataset", sorted(CSV_CASES))
def test_csv_datasets_ingest_through_their_descriptors(dataset: str, tmp_path: Path) -> None:
    # The repository's own descriptors: logs come from their csv: entries, time base utc.
    descriptor = tmp_path / "dataset.yaml"
    descriptor.write_text((REPO / "datasets" / dataset / "dataset.yaml").read_text())
    CSV_CASES[dataset](tmp_path / "raw")
    cfg = load_dataset_config(descriptor)
    logs = input_paths(cfg, descriptor)
    assert [p.suffix for p in logs] == [".csv"] * 3
    result = ingest(logs, tmp_path / "tables", config=cfg, config_dir=tmp_path)
    assert result.report["time_base"]["base"] == "utc"
    for name in ("vehicle", "gnss", "truth"):
        ref = read_table(tmp_path / "raw" / "reference" / f"{name}.parquet", name).table
        got = read_table(tmp_path / "tables" / f"{name}.parquet", name).table
        assert got.num_rows == ref.num_rows
        for col in ref.column_names:
            want = ref[col].to_numpy(zero_copy_only=False)
            have = got[col].to_numpy(zero_copy_only=False)
            if ref[col].null_count == ref.num_rows:
                assert got[col].null_count == got.num_rows, f"{name}.{col}"
            elif name == "truth":  # exact in the reference, printed to 1e-10 in the file
                np.testing.assert_allclose(have, want, rtol=0, atol=1e-9, err_msg=col)
            else:  # measurements are exactly what the file holds
                np.testing.assert_array_equal(have, want, err_msg=f"{name}.{col}")
