"""Content and time faults injected into real MCAP files, checked in the ingest report
(catalogue cases 21, 23, 24, 27, 29-33): the counts reported equal the counts injected."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from navreplay.ingest.api import IngestOptions, ingest
from navreplay.ingest.config import parse_dataset_config
from navreplay.ingest.errors import CorruptLogError, PlausibilityError
from navreplay.ingest.tables import read_provenance

from .roslogs import (
    G,
    Stream,
    fix_stream,
    imu_data,
    imu_msg,
    imu_stream,
    navsatfix_msg,
    serialize,
    write_mcap,
)


def _imu_with_stamps(t_ns: np.ndarray, acc: np.ndarray, gyro: np.ndarray) -> Stream:
    """Messages written in log order 0..n-1 carrying the given (possibly faulty) stamps."""
    s = Stream("/imu/data", "sensor_msgs/msg/Imu")
    log0 = int(t_ns.min())
    for i, (t, a, g) in enumerate(zip(t_ns.tolist(), acc, gyro, strict=True)):
        s.messages.append((log0 + i * 10_000_000, serialize(False, imu_msg(False, t, a, g))))
    return s


def test_time_faults_are_counted_exactly_through_the_pipeline(tmp_path: Path) -> None:
    data = imu_data(3000)
    t, acc, gyro = data.t_ns.copy(), data.acc.copy(), data.gyro.copy()
    swaps = list(range(100, 1100, 100))  # case 29: 10 swapped neighbours
    for i in swaps:
        t[[i, i + 1]] = t[[i + 1, i]]
    dups = list(range(1205, 1255, 10))  # case 30: 5 stamps repeated with other values
    for i in dups:
        t[i] = t[i - 1]
    keep = np.ones(len(t), bool)
    keep[2000:2200] = False  # case 33: a 2 s hole
    stream = _imu_with_stamps(t[keep], acc[keep], gyro[keep])
    result = ingest([write_mcap(tmp_path / "a.mcap", [stream])], tmp_path / "out")
    imu = result.report["tables"]["imu"]
    assert imu["hygiene"]["reordered"] == len(swaps)
    assert imu["hygiene"]["duplicates_conflicting_dropped"] == len(dups)
    assert imu["hygiene"]["dropped_late"] == 0
    assert imu["stats"]["gaps"]["count"] == 1
    assert imu["stats"]["gaps"]["longest_s"] == pytest.approx(2.01)
    assert result.tables["imu"] == 3000 - 200 - len(dups)
    t_out = pq.read_table(tmp_path / "out" / "imu.parquet")["t_ns"].to_numpy()
    assert (np.diff(t_out) > 0).all()
    with pytest.raises(CorruptLogError, match="re-sorted"):
        ingest([tmp_path / "a.mcap"], tmp_path / "strict", options=IngestOptions(strict=True))


def test_clock_step_backwards_is_split_and_reported(tmp_path: Path) -> None:
    # Case 31 through the pipeline, and its strict failure.
    data = imu_data(2000)
    t = data.t_ns.copy()
    t[1500:] -= 5 * 10**9
    log = write_mcap(tmp_path / "a.mcap", [_imu_with_stamps(t, data.acc, data.gyro)])
    result = ingest([log], tmp_path / "out")
    (step,) = result.report["tables"]["imu"]["hygiene"]["clock_steps_backward"]
    assert step["step_s"] == pytest.approx(-4.99)
    assert result.tables["imu"] == 2000
    with pytest.raises(CorruptLogError, match="backwards"):
        ingest([log], tmp_path / "strict", options=IngestOptions(strict=True))
    assert not (tmp_path / "strict").exists()


def test_nan_and_inf_values_are_kept_as_nan_and_counted(tmp_path: Path) -> None:
    # Case 21: AccX = NaN (3 rows), gyro z = inf (2 rows), a NaN latitude.
    data = imu_data(500)
    acc, gyro = data.acc.copy(), data.gyro.copy()
    acc[[10, 20, 30], 0] = np.nan
    gyro[[40, 50], 2] = np.inf
    fixes = fix_stream(20)
    t7 = fixes.messages[7][0]
    fixes.messages[7] = (t7, serialize(False, navsatfix_msg(False, t7, np.nan, 127.0, 50.0)))
    log = write_mcap(tmp_path / "a.mcap", [_imu_with_stamps(data.t_ns, acc, gyro), fixes])
    result = ingest([log], tmp_path / "out")
    assert result.tables == {"imu": 500, "gnss": 20}
    nonfinite = result.report["tables"]["imu"]["stats"]["nonfinite"]
    assert nonfinite == {"acc_x_mps2": {"nan": 3, "inf": 0}, "gyro_z_radps": {"nan": 0, "inf": 2}}
    imu = pq.read_table(tmp_path / "out" / "imu.parquet")
    assert imu["acc_x_mps2"].null_count == 0
    assert np.isnan(imu["acc_x_mps2"].to_numpy()[[10, 20, 30]]).all()
    assert np.isnan(imu["gyro_z_radps"].to_numpy()[[40, 50]]).all()
    gnss = result.report["tables"]["gnss"]["stats"]["nonfinite"]
    assert gnss == {"lat_deg": {"nan": 1, "inf": 0}}


def test_no_fix_with_stale_position_is_flagged(tmp_path: Path) -> None:
    # Case 27: status NO_FIX while lat/lon repeat the last fix.
    fixes = fix_stream(30)
    for i in range(10, 15):
        t = fixes.messages[i][0]
        msg = navsatfix_msg(False, t, 37.5 + 9e-6, 127.0 + 18e-6, 50.09, status=-1)
        fixes.messages[i] = (t, serialize(False, msg))
    result = ingest([write_mcap(tmp_path / "a.mcap", [fixes])], tmp_path / "out")
    assert result.report["tables"]["gnss"]["counters"]["no_fix"] == 5
    fix_type = pq.read_table(tmp_path / "out" / "gnss.parquet")["fix_type"].to_numpy()
    assert (fix_type[10:15] == 1).all()  # NO_FIX: the filter must not fuse these
    assert (fix_type[:10] == 3).all()


def test_accel_in_g_fails_ingest_unless_the_descriptor_says_so(tmp_path: Path) -> None:
    # Case 23 through the pipeline: E-FATAL, or scaled with the override in provenance.
    data = imu_data(500)
    log = write_mcap(tmp_path / "a.mcap", [_imu_with_stamps(data.t_ns, data.acc / G, data.gyro)])
    with pytest.raises(PlausibilityError, match="probable g units"):
        ingest([log], tmp_path / "out")
    assert not (tmp_path / "out").exists()
    cfg = parse_dataset_config({"id": "x", "imu": {"accel_units": "g"}})
    ingest([log], tmp_path / "out", config=cfg)
    acc_z = pq.read_table(tmp_path / "out" / "imu.parquet")["acc_z_mps2"].to_numpy()
    assert acc_z.mean() == pytest.approx(-G, abs=0.01)
    prov = read_provenance(tmp_path / "out" / "imu.parquet")
    assert "g (scaled by 9.80665" in prov.extra["imu_accel_units"]


def test_ned_frame_id_is_not_converted(tmp_path: Path) -> None:
    # REP-103: a frame id ending in _ned carries FRD/NED data already.
    data = imu_data(300)
    acc = data.acc * np.array([1.0, 1.0, -1.0])  # FRD: gravity reaction on -z
    stream = imu_stream(type(data)(data.t_ns, acc, data.gyro), frame_id="imu_ned")
    result = ingest([write_mcap(tmp_path / "a.mcap", [stream])], tmp_path / "out")
    assert result.report["tables"]["imu"]["frame_conversions"] == []
    acc_z = pq.read_table(tmp_path / "out" / "imu.parquet")["acc_z_mps2"].to_numpy()
    assert acc_z.mean() == pytest.approx(-G, abs=0.01)


def test_descriptor_frame_overrides_the_ros_convention(tmp_path: Path) -> None:
    # A driver that publishes FRD without the _ned suffix: imu.frame: frd in dataset.yaml.
    data = imu_data(300)
    acc = data.acc * np.array([1.0, 1.0, -1.0])
    stream = imu_stream(type(data)(data.t_ns, acc, data.gyro))
    cfg = parse_dataset_config({"id": "x", "imu": {"frame": "frd"}})
    result = ingest([write_mcap(tmp_path / "a.mcap", [stream])], tmp_path / "out", config=cfg)
    assert result.report["tables"]["imu"]["frame_conversions"] == []
    acc_z = pq.read_table(tmp_path / "out" / "imu.parquet")["acc_z_mps2"].to_numpy()
    assert acc_z.mean() == pytest.approx(-G, abs=0.01)
