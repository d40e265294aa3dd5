"""ROS writers: the files open with the reference readers (mcap + mcap_ros2, rosbags) and
carry exactly the table values, in REP-103 axes and UTC stamps."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Literal

import numpy as np
import pyarrow as pa
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader

from navreplay.ingest.gpstime import NS_PER_S, gps_from_calendar
from navreplay.ingest.schema import NAV_SOLUTION_FIELDS, from_columns
from navreplay.ingest.writers import ros, rosserial

T0 = gps_from_calendar("2026-11-18T02:30:00")
UTC0 = int(np.datetime64("2026-11-18T02:29:42", "ns").astype(np.int64))  # 18 leap seconds
N_IMU, N_FIX = 40, 4


@pytest.fixture(scope="module")
def tables() -> dict[str, pa.Table]:
    rng = np.random.default_rng(0)
    t_imu = T0 + np.arange(N_IMU, dtype=np.int64) * 10_000_000
    imu: dict[str, np.ndarray] = {"t_ns": t_imu}
    for k in "xyz":
        imu[f"acc_{k}_mps2"] = rng.normal(0.0, 1.0, N_IMU)
        imu[f"gyro_{k}_radps"] = rng.normal(0.0, 0.1, N_IMU)
    imu["acc_z_mps2"] = imu["acc_z_mps2"] - 9.8
    t_fix = T0 + np.arange(N_FIX, dtype=np.int64) * NS_PER_S // 10
    lat = 37.46 + rng.normal(0.0, 1e-5, N_FIX)
    lat[2] = np.nan  # no fix
    gnss = {
        "t_ns": t_fix,
        "lat_deg": lat,
        "lon_deg": 126.95 + rng.normal(0.0, 1e-5, N_FIX),
        "alt_m": 60.0 + rng.normal(0.0, 1.0, N_FIX),
        "vel_n_mps": np.array([1.0, 2.0, 3.0, 4.0]),
        "vel_e_mps": np.array([-1.0, -2.0, -3.0, -4.0]),
        "vel_d_mps": np.array([0.1, 0.2, 0.3, 0.4]),
        "h_acc_m": np.array([1.0, 1.5, np.nan, 2.0]),
        "v_acc_m": np.array([2.0, 2.5, np.nan, 3.0]),
        "speed_acc_mps": np.full(N_FIX, 0.05),
        "fix_type": np.array([3, 3, 1, 3], dtype=np.int8),
        "num_sats": np.array([7, 7, 2, 8], dtype=np.int16),
    }
    truth: dict[str, Any] = {"t_ns": t_imu}
    for name in (*NAV_SOLUTION_FIELDS, "acc_bias_x_mps2", "clock_bias_m"):
        truth[name] = rng.normal(0.0, 1.0, N_IMU)
    return {
        "imu": from_columns("imu", imu),
        "gnss": from_columns("gnss", gnss),
        "truth": from_columns("truth", truth),
    }


OPTS = ros.RosOptions(accel_var_m2ps4=4e-4, gyro_var_rad2ps2=4e-6)


@pytest.fixture(scope="module")
def files(tables: dict[str, pa.Table], tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("ros")
    ros.write_mcap(out / "d.mcap", tables, OPTS)
    ros.write_bag(out / "d.bag", tables, OPTS)
    return out


def _col(table: pa.Table, name: str) -> np.ndarray:
    return np.asarray(table.column(name).to_numpy(zero_copy_only=False), dtype=np.float64)


def test_mcap_decodes_with_the_reference_ros2_decoder(
    files: Path, tables: dict[str, pa.Table]
) -> None:
    with (files / "d.mcap").open("rb") as fh:
        reader = make_reader(fh, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        assert summary is not None
        assert summary.statistics is not None
        assert reader.get_header().profile == "ros2"
        counts = {
            ch.topic: summary.statistics.channel_message_counts[cid]
            for cid, ch in summary.channels.items()
        }
        assert counts == {"/imu/data": N_IMU, "/gps/fix": N_FIX, "/gps/vel": N_FIX, "/truth": N_IMU}
        got: dict[str, list[Any]] = {}
        log_times: dict[str, list[int]] = {}
        for _, channel, message, decoded in reader.iter_decoded_messages():
            got.setdefault(channel.topic, []).append(decoded)
            log_times.setdefault(channel.topic, []).append(message.log_time)
    imu = tables["imu"]
    first = got["/imu/data"][0]
    # UTC stamps: GPS minus 18 leap seconds
    assert first.header.stamp.sec * NS_PER_S + first.header.stamp.nanosec == UTC0
    assert log_times["/imu/data"][1] - log_times["/imu/data"][0] == 10_000_000
    # FLU: x kept, y and z negated
    acc = np.array(
        [
            [m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z]
            for m in got["/imu/data"]
        ]
    )
    frd = np.stack([_col(imu, f"acc_{k}_mps2") for k in "xyz"], axis=-1)
    np.testing.assert_array_equal(acc, frd * [1.0, -1.0, -1.0])
    assert acc[:, 2].mean() > 9.0  # specific force points up at rest in FLU
    gz = np.array([m.angular_velocity.z for m in got["/imu/data"]])
    np.testing.assert_array_equal(gz, -_col(imu, "gyro_z_radps"))
    assert first.orientation_covariance[0] == -1.0
    assert first.linear_acceleration_covariance[0] == pytest.approx(4e-4)
    fixes = got["/gps/fix"]
    assert [f.status.status for f in fixes] == [0, 0, -1, 0]
    assert fixes[0].latitude == _col(tables["gnss"], "lat_deg")[0]
    assert fixes[1].position_covariance[0] == pytest.approx(1.5**2)
    assert fixes[1].position_covariance[8] == pytest.approx(2.5**2)
    assert fixes[1].position_covariance_type == 2
    vel = got["/gps/vel"][3].twist.twist.linear
    assert (vel.x, vel.y, vel.z) == (-4.0, 4.0, -0.4)  # ENU from NED
    truth = got["/truth"]
    assert truth[5].acc_bias_x_mps2 == _col(tables["truth"], "acc_bias_x_mps2")[5]
    assert truth[5].clock_bias_m == _col(tables["truth"], "clock_bias_m")[5]


@pytest.mark.parametrize("name", ["d.mcap", "d.bag"])
def test_rosbags_reads_both_files_from_the_embedded_definitions(
    files: Path, tables: dict[str, pa.Table], name: str
) -> None:
    with AnyReader([files / name]) as reader:  # no default typestore: definitions from file
        conns = {c.topic: c for c in reader.connections}
        assert conns["/truth"].msgtype == ros.TRUTH_MSGTYPE
        assert conns["/imu/data"].msgcount == N_IMU
        truth = [
            reader.deserialize(raw, c.msgtype)
            for c, _, raw in reader.messages(connections=[conns["/truth"]])
        ]
        stamps = [t for _, t, _ in reader.messages(connections=[conns["/gps/fix"]])]
    table = tables["truth"]
    fields = [n for n in table.column_names if n != "t_ns"]
    for name_ in fields:
        np.testing.assert_array_equal([getattr(m, name_) for m in truth], _col(table, name_))
    assert stamps[0] == UTC0
    assert stamps[1] - stamps[0] == NS_PER_S // 10


def test_writing_twice_gives_identical_bytes(
    files: Path, tables: dict[str, pa.Table], tmp_path: Path
) -> None:
    ros.write_mcap(tmp_path / "again.mcap", tables, OPTS)
    ros.write_bag(tmp_path / "again.bag", tables, OPTS)
    assert (tmp_path / "again.mcap").read_bytes() == (files / "d.mcap").read_bytes()
    assert (tmp_path / "again.bag").read_bytes() == (files / "d.bag").read_bytes()


def test_truth_definition_names_the_columns(tables: dict[str, pa.Table]) -> None:
    text = ros.truth_msgdef(tables["truth"])
    assert text.splitlines()[0] == "std_msgs/Header header"
    assert "float64 clock_bias_m" in text.splitlines()


@pytest.mark.parametrize("ros_version", [1, 2])
def test_fast_serialization_equals_rosbags_message_by_message(
    tables: dict[str, pa.Table], ros_version: Literal[1, 2]
) -> None:
    store = ros.typestore(ros_version, tables["truth"])
    serialize = store.serialize_ros1 if ros_version == 1 else store.serialize_cdr
    for stream in ros._streams(tables, store, OPTS):
        if not stream.fixed:
            continue
        fast = rosserial.bulk_serialize(stream, store.types, serialize, ros_version)
        assert fast is not None, stream.topic
        slow = rosserial.encoder(stream._replace(fixed=False), store.types, serialize, ros_version)
        for i in (0, 1, len(stream.stamps_ns) - 1):
            assert fast[i].tobytes() == slow(i), (stream.topic, i)
