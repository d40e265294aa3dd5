"""MCAP reading: round trips, and damaged files (catalogue cases 1-6, 20, 22)."""

from __future__ import annotations

import os
import struct
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import NonSeekingReader, make_reader
from mcap.writer import CompressionType, IndexType

from navreplay.ingest.api import ingest
from navreplay.ingest.damage import Completeness, DamageLog
from navreplay.ingest.detect import detect
from navreplay.ingest.errors import CorruptLogError
from navreplay.ingest.readers.base import ReadContext
from navreplay.ingest.readers.ros.mcap import McapReader
from navreplay.ingest.schema import TableName

from .roslogs import (
    ImuData,
    Stream,
    assert_definition_mismatch_is_fatal,
    assert_imu_reads_back,
    fix_stream,
    imu_data,
    imu_stream,
    msgdef,
    odom_stream,
    read_imu,
    read_truncated,
    write_mcap,
)


def _nonseeking_count(path: Path) -> int:
    n = 0
    with path.open("rb") as fh:
        try:
            for _ in NonSeekingReader(fh).iter_messages(log_time_order=False):
                n += 1
        except Exception:  # the library's failure on damage is the point
            pass
    return n


@pytest.mark.parametrize("ros1", [False, True], ids=["ros2-cdr", "ros1"])
@pytest.mark.parametrize(
    "compression", [CompressionType.ZSTD, CompressionType.LZ4, CompressionType.NONE]
)
def test_round_trip_reproduces_every_value(
    tmp_path: Path, ros1: bool, compression: CompressionType
) -> None:
    data = imu_data(400)
    path = write_mcap(
        tmp_path / "a.mcap",
        [imu_stream(data, ros1=ros1), fix_stream(10, ros1=ros1)],
        ros1=ros1,
        compression=compression,
    )
    assert_imu_reads_back(path, data)


def test_unchunked_unindexed_file_is_read_in_full(tmp_path: Path) -> None:
    # Case 6.
    data = imu_data(300)
    path = write_mcap(
        tmp_path / "a.mcap", [imu_stream(data)], use_chunking=False, index_types=IndexType.NONE
    )
    cols, damage = read_imu(path)
    np.testing.assert_array_equal(cols["t_ns"], data.t_ns)
    assert damage.completeness == ["complete"]


def _truncated(tmp_path: Path, compression: CompressionType) -> tuple[Path, ImuData, bytes]:
    data = imu_data(2000)
    path = write_mcap(tmp_path / "a.mcap", [imu_stream(data)], compression=compression)
    original = path.read_bytes()
    os.truncate(path, len(original) // 2)
    return path, data, original


def test_truncated_uncompressed_mcap_keeps_exactly_the_complete_messages(tmp_path: Path) -> None:
    # Case 1 with an exact oracle: a message is recoverable iff its bytes precede the cut.
    path, data, original = _truncated(tmp_path, CompressionType.NONE)
    complete, defect = read_truncated(path, original, data, imu_stream(data))
    # Every message of complete chunks, plus the readable prefix of the cut chunk.
    assert complete == _nonseeking_count(path) + (defect.messages_recovered or 0)


def test_truncated_compressed_mcap_recovers_a_prefix_and_says_how(tmp_path: Path) -> None:
    path, data, _ = _truncated(tmp_path, CompressionType.ZSTD)
    cols, damage = read_imu(path)
    n = len(cols["t_ns"])
    baseline = _nonseeking_count(path)
    assert baseline <= n < len(data.t_ns)
    np.testing.assert_array_equal(cols["t_ns"], data.t_ns[:n])
    (defect,) = damage.defects
    assert defect.kind == Completeness.TRUNCATED
    assert n == baseline + (defect.messages_recovered or 0)
    assert f"offset {defect.offset}" in defect.reason


def test_truncated_mcap_under_strict_is_an_error_naming_file_and_offset(tmp_path: Path) -> None:
    path, _, _ = _truncated(tmp_path, CompressionType.ZSTD)
    with pytest.raises(CorruptLogError) as err:
        read_imu(path, strict=True)
    assert str(path) in str(err.value)
    assert err.value.offset is not None


@pytest.mark.parametrize("how", ["cut-30-bytes", "never-finished"])
def test_missing_footer_or_summary_loses_nothing_that_was_written(tmp_path: Path, how: str) -> None:
    # Case 2.
    data = imu_data(1000)
    path = write_mcap(tmp_path / "a.mcap", [imu_stream(data)], finish=how != "never-finished")
    if how == "cut-30-bytes":
        os.truncate(path, path.stat().st_size - 30)
        expected = len(data.t_ns)
    else:
        expected = _nonseeking_count(path)  # the unfinished last chunk never reached the file
    cols, damage = read_imu(path)
    assert len(cols["t_ns"]) == expected
    assert [d.kind for d in damage.defects] == [Completeness.NO_SUMMARY]
    inv = McapReader(detect(path), ReadContext(DamageLog(path, strict=False))).inventory()
    assert inv.streams[0].count == expected  # counted by a scan when the summary is gone


@pytest.mark.parametrize("compression", [CompressionType.ZSTD, CompressionType.NONE])
def test_corrupt_chunk_is_skipped_and_reported_from_the_index(
    tmp_path: Path, compression: CompressionType
) -> None:
    # Cases 3 and 4: CRC checks are on by default; one bit flipped in one chunk.
    data = imu_data(1500)
    path = write_mcap(tmp_path / "a.mcap", [imu_stream(data)], compression=compression)
    with path.open("rb") as fh:
        summary = make_reader(fh).get_summary()
    assert summary is not None
    chunk = summary.chunk_indexes[2]
    raw = bytearray(path.read_bytes())
    middle = chunk.chunk_start_offset + chunk.chunk_length // 2
    raw[middle] ^= 0x10
    path.write_bytes(bytes(raw))
    in_chunk = int(
        ((data.t_ns >= chunk.message_start_time) & (data.t_ns <= chunk.message_end_time)).sum()
    )
    cols, damage = read_imu(path)
    assert len(cols["t_ns"]) == len(data.t_ns) - in_chunk
    (defect,) = damage.defects
    assert defect.kind == Completeness.CORRUPT_CHUNKS_SKIPPED
    assert defect.offset == chunk.chunk_start_offset
    assert defect.time_range_ns == (chunk.message_start_time, chunk.message_end_time)
    assert defect.messages_lost == in_chunk
    assert "CRC" in defect.reason or "decompress" in defect.reason


@pytest.mark.parametrize("length", [2**40, 3 * 2**30], ids=["2^40", "3GB"])
def test_corrupt_record_length_is_reported_without_allocating_it(
    tmp_path: Path, length: int
) -> None:
    # Case 5: the length is bounded by the file size before anything is read.
    data = imu_data(1500)
    path = write_mcap(tmp_path / "a.mcap", [imu_stream(data)])
    with path.open("rb") as fh:
        summary = make_reader(fh).get_summary()
    assert summary is not None
    chunk = summary.chunk_indexes[1]
    raw = bytearray(path.read_bytes())
    raw[chunk.chunk_start_offset + 1 : chunk.chunk_start_offset + 9] = struct.pack("<Q", length)
    path.write_bytes(bytes(raw))
    first = summary.chunk_indexes[0]
    before = int((data.t_ns <= first.message_end_time).sum())
    cols, damage = read_imu(path)
    assert len(cols["t_ns"]) == before
    (defect,) = damage.defects
    assert defect.kind == Completeness.CORRUPT_TAIL
    assert defect.offset == chunk.chunk_start_offset
    assert str(length) in defect.reason
    with pytest.raises(CorruptLogError, match=f"offset {chunk.chunk_start_offset}"):
        read_imu(path, strict=True)


def test_empty_payload_is_dropped_and_counted(tmp_path: Path) -> None:
    # Case 22: E-FLAG per record, never a crash.
    data = imu_data(200)
    stream = imu_stream(data)
    stream.messages[50] = (stream.messages[50][0], b"")
    stream.messages[120] = (stream.messages[120][0], stream.messages[120][1][:40])
    path = write_mcap(tmp_path / "a.mcap", [stream])
    result = ingest([path], tmp_path / "out")
    assert result.tables["imu"] == 198
    imu = result.report["tables"]["imu"]
    assert imu["counters"]["payloads_malformed_dropped"] == 2
    assert "offset" in imu["info"]["first_malformed_payload"]


def test_ros2_definition_with_a_field_removed_is_fatal_for_the_topic(tmp_path: Path) -> None:
    # Case 20 (ROS 2): the embedded definition does not describe the payloads.
    text = msgdef(False, "sensor_msgs/msg/Imu").replace(
        "float64[9] linear_acceleration_covariance\n", "", 1
    )
    assert text != msgdef(False, "sensor_msgs/msg/Imu")
    stream = imu_stream(imu_data(40))
    broken = Stream(stream.topic, stream.msgtype, stream.messages, text)
    path = write_mcap(tmp_path / "a.mcap", [broken, fix_stream(5)])
    assert_definition_mismatch_is_fatal(path, tmp_path / "out")


def test_inventory_lists_counts_rates_and_tables_from_the_summary(tmp_path: Path) -> None:
    path = write_mcap(
        tmp_path / "a.mcap",
        [imu_stream(imu_data(500, 100.0)), fix_stream(25, 5.0), odom_stream(50, 10.0)],
    )
    inv = McapReader(detect(path), ReadContext(DamageLog(path, strict=False))).inventory()
    by_key = {s.key: s for s in inv.streams}
    assert by_key["/imu/data"].count == 500
    assert by_key["/imu/data"].table == TableName.IMU
    assert by_key["/fix"].table == TableName.GNSS
    assert by_key["/odom"].table == TableName.VEHICLE
    assert by_key["/imu/data"].frame == "flu"
    rate = by_key["/imu/data"].rate_hz
    assert rate is not None
    assert 90 < rate < 110
