"""The synthesizers' logs round-trip: ingesting the MCAP or ROS 1 bag that
``ingest.writers.ros`` writes together with the RINEX observation and navigation files of
``ingest.writers.rinex``, and the CSV logs of the vehicle datasets, reproduces the
synthesizers' own tables.

The writer stamps ROS messages in UTC (GPS - 18 s); RINEX epochs are GPS time; ingest puts
both on the GPS time base and records the 18 leap seconds. Every column ROS can carry comes
back bit for bit; ``num_sats`` has no field in ``sensor_msgs/NavSatFix`` and comes back null
(not provided). From RINEX, the measurements come back bit for bit and the satellite states,
recomputed from the broadcast ephemeris at the receiver position solved in ingest, within
2e-4 m (``gnssfiles.assert_obs_match``); the noise sigmas have no RINEX field.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from navreplay.ingest.api import IngestOptions, ingest
from navreplay.ingest.config import input_paths, load_dataset_config
from navreplay.ingest.errors import IngestError
from navreplay.ingest.tables import read_table
from navreplay.ingest.writers import ros
from navreplay.pipeline.synth import car, tractor_log
from navreplay.pipeline.synth.tractor import TractorStraightParams

from .gnssfiles import assert_obs_match, short_drive, write_pair

REPO = Path(__file__).resolve().parents[2]
NOT_IN_ROS = {("gnss", "num_sats")}


@pytest.fixture(scope="module")
def synth() -> Any:
    return short_drive(25.0, seed=11)


@pytest.mark.parametrize("container", ["mcap", "bag"])
def test_ingest_reproduces_the_synthesizer_tables(
    synth: Any, tmp_path: Path, container: str
) -> None:
    tables = {k: synth.tables[k] for k in ("imu", "gnss", "truth")}
    log = tmp_path / f"drive.{container}"
    write = ros.write_mcap if container == "mcap" else ros.write_bag
    write(log, tables, ros.RosOptions(time_base="gps"))
    obs, nav = write_pair(tmp_path, synth)
    result = ingest([log, obs, nav], tmp_path / "tables")  # no descriptor: all automatic
    assert result.tables == {k: t.num_rows for k, t in synth.tables.items()}
    assert result.report["time_base"]["base"] == "gps"
    assert result.report["time_base"]["leap_seconds"] == 18
    assert result.report["time_base"]["gnss_check"]["status"] == "consistent"
    assert result.report["time_base"]["gnss_check"]["lag_s"] == 0.0
    assert not result.report["warnings"]
    assert_obs_match(
        synth.tables["gnss_obs"], pq.read_table(tmp_path / "tables" / "gnss_obs.parquet")
    )
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


def test_a_leap_second_offset_between_bag_and_rinex_is_detected(tmp_path: Path) -> None:
    # Catalogue case 36: the bag's fixes stamped 18 s late (GPS time written as if UTC).
    synth = short_drive(60.0, seed=11)
    gnss = synth.tables["gnss"]
    late = gnss.set_column(0, "t_ns", pa.array(gnss["t_ns"].to_numpy() + 18 * 10**9))
    log = tmp_path / "drive.mcap"
    ros.write_mcap(log, {"imu": synth.tables["imu"], "gnss": late}, ros.RosOptions(time_base="gps"))
    obs, nav = write_pair(tmp_path, synth)
    result = ingest([log, obs, nav], tmp_path / "tables")
    check = result.report["time_base"]["gnss_check"]
    assert check["status"] == "offset"
    assert check["lag_s"] == 18.0
    assert check["median_m_at_lag"] < 5.0
    assert check["median_m_at_zero"] > 50.0
    assert any("offset in time by +18.00 s" in w for w in result.report["warnings"])
    with pytest.raises(IngestError, match=r"leap seconds"):
        ingest([log, obs, nav], tmp_path / "strict", options=IngestOptions(strict=True))
    assert not (tmp_path / "strict").exists()
