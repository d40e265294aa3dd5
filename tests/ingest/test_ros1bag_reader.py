"""ROS 1 bags: round trips and damage (catalogue cases 8, 9, 20)."""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag1 import Writer as Bag1Writer

from navreplay.ingest.api import ingest, inspect
from navreplay.ingest.damage import Completeness, DamageLog
from navreplay.ingest.detect import detect
from navreplay.ingest.errors import CorruptLogError
from navreplay.ingest.readers.base import ReadContext
from navreplay.ingest.readers.ros.ros1bag import Ros1BagReader
from navreplay.ingest.schema import TableName

from .roslogs import (
    ROS1,
    assert_definition_mismatch_is_fatal,
    assert_imu_reads_back,
    fix_stream,
    imu_data,
    imu_stream,
    msgdef,
    read_imu,
    read_truncated,
    serialize,
    vec3,
    write_bag1,
)


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.mark.parametrize("compression", [None, "bz2", "lz4"])
def test_round_trip_reproduces_every_value(tmp_path: Path, compression: str | None) -> None:
    data = imu_data(600)
    path = write_bag1(
        tmp_path / "a.bag",
        [imu_stream(data, ros1=True), fix_stream(20, ros1=True)],
        compression=compression,
    )
    assert_imu_reads_back(path, data)
    inv = Ros1BagReader(detect(path), ReadContext(DamageLog(path, strict=False))).inventory()
    assert {s.key: s.count for s in inv.streams} == {"/imu/data": 600, "/fix": 20}


def _unindex(path: Path) -> None:
    raw = bytearray(path.read_bytes())
    at = raw.index(b"index_pos=") + len(b"index_pos=")
    raw[at : at + 8] = bytes(8)
    path.write_bytes(bytes(raw))


def test_unindexed_bag_is_read_by_a_linear_chunk_scan(tmp_path: Path) -> None:
    # Case 8: E-RECOVER; the input is never modified.
    data = imu_data(800)
    path = write_bag1(tmp_path / "a.bag", [imu_stream(data, ros1=True)], compression="bz2")
    _unindex(path)
    before = _sha(path)
    cols, damage = read_imu(path)
    np.testing.assert_array_equal(cols["t_ns"], data.t_ns)
    assert [d.kind for d in damage.defects] == [Completeness.UNINDEXED]
    assert "rosbag reindex" in damage.defects[0].reason
    inv = Ros1BagReader(detect(path), ReadContext(DamageLog(path, strict=False))).inventory()
    assert inv.streams[0].count == 800
    assert _sha(path) == before


def test_unindexed_bag_under_strict_names_rosbag_reindex(tmp_path: Path) -> None:
    path = write_bag1(tmp_path / "a.bag", [imu_stream(imu_data(100), ros1=True)])
    _unindex(path)
    with pytest.raises(CorruptLogError) as err:
        read_imu(path, strict=True)
    assert "rosbag reindex" in str(err.value)
    assert str(path) in str(err.value)


def test_bag_cut_before_its_index_section_loses_no_chunk(tmp_path: Path) -> None:
    data = imu_data(500)
    path = write_bag1(tmp_path / "a.bag", [imu_stream(data, ros1=True)])
    raw = path.read_bytes()
    at = raw.index(b"index_pos=") + len(b"index_pos=")
    index_pos = int.from_bytes(raw[at : at + 8], "little")
    os.truncate(path, index_pos)
    cols, damage = read_imu(path)
    np.testing.assert_array_equal(cols["t_ns"], data.t_ns)
    assert [d.kind for d in damage.defects] == [Completeness.UNINDEXED]


def test_truncated_uncompressed_bag_keeps_exactly_the_complete_messages(tmp_path: Path) -> None:
    # Case 9 with an exact oracle: a message is recoverable iff its bytes precede the cut.
    data = imu_data(1500)
    stream = imu_stream(data, ros1=True)
    path = write_bag1(tmp_path / "a.bag", [stream])
    original = path.read_bytes()
    os.truncate(path, len(original) // 2)
    read_truncated(path, original, data, stream)


def test_truncated_bz2_bag_recovers_a_prefix(tmp_path: Path) -> None:
    data = imu_data(1500)
    path = write_bag1(tmp_path / "a.bag", [imu_stream(data, ros1=True)], compression="bz2")
    os.truncate(path, path.stat().st_size // 2)
    cols, damage = read_imu(path)
    n = len(cols["t_ns"])
    assert 0 < n < 1500
    np.testing.assert_array_equal(cols["t_ns"], data.t_ns[:n])
    assert [d.kind for d in damage.defects] == [Completeness.TRUNCATED]
    # Through the whole pipeline: a valid dataset flagged as truncated, or nothing (--strict).
    result = ingest([path], tmp_path / "out")
    assert result.tables["imu"] == n
    assert result.report["files"][0]["completeness"] == ["truncated"]
    from navreplay.ingest.api import IngestOptions

    with pytest.raises(CorruptLogError):
        ingest([path], tmp_path / "strict", options=IngestOptions(strict=True))
    assert not (tmp_path / "strict").exists()


def test_connection_type_that_does_not_match_the_payload_is_fatal(tmp_path: Path) -> None:
    # Case 20 (ROS 1): the connection says sensor_msgs/Imu, the payloads are Vector3.
    path = tmp_path / "a.bag"
    with Bag1Writer(path) as w:
        conn = w.add_connection("/imu/data", "sensor_msgs/msg/Imu", typestore=ROS1)
        for i in range(30):
            w.write(conn, 10**18 + i * 10**7, serialize(True, vec3(True, (1.0, 2.0, 3.0))))
    assert_definition_mismatch_is_fatal(path, tmp_path / "out")


def test_definition_whose_md5_disagrees_is_not_decoded(tmp_path: Path) -> None:
    # Case 20: the definition text and the md5 the connection declares disagree.
    path = tmp_path / "a.bag"
    text = msgdef(True, "sensor_msgs/msg/Imu").replace("float64[9] orientation_covariance", "")
    md5 = ROS1.generate_msgdef("sensor_msgs/msg/Imu")[1]
    with Bag1Writer(path) as w:
        conn = w.add_connection(
            "/imu/data", "sensor_msgs/msg/Imu", msgdef=text, md5sum=md5, typestore=ROS1
        )
        w.write(conn, 10**18, b"\x00" * 8)
    inventories, plans = inspect([path])
    (stream,) = inventories[0].streams
    assert stream.table is None
    assert "md5" in stream.detail
    assert TableName.IMU not in plans


@pytest.mark.parametrize("back", [200, 120, 60])
def test_damaged_index_does_not_stop_the_linear_read(tmp_path: Path, back: int) -> None:
    # Case 10: a byte flipped near the end, inside the index section. The read never uses
    # the index, so every message still comes out; no raw decode error escapes.
    data = imu_data(800)
    path = write_bag1(tmp_path / "a.bag", [imu_stream(data, ros1=True)], compression="lz4")
    raw = bytearray(path.read_bytes())
    raw[-back] ^= 0xFF
    path.write_bytes(bytes(raw))
    result = ingest([path], tmp_path / "out")
    assert result.tables["imu"] == 800
