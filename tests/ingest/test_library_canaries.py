"""Library-behaviour canaries (bad-inputs.md): what mcap, rosbags and pyarrow do by themselves
on damaged input, which is why navreplay frames, checks and salvages on its own. If a library
upgrade changes one of these, the test fails and the workaround can be revisited."""

from __future__ import annotations

import io
import os
from pathlib import Path

import pyarrow.csv as pacsv
import pytest
from mcap.exceptions import EndOfFile
from mcap.reader import NonSeekingReader, make_reader
from mcap.stream_reader import CRCValidationError, StreamReader
from mcap.writer import CompressionType
from rosbags.rosbag1 import Reader as Bag1Reader
from rosbags.rosbag1 import ReaderError as Bag1ReaderError
from rosbags.rosbag2 import Reader as Bag2Reader

from .roslogs import fix_stream, imu_data, imu_stream, write_bag1, write_bag2, write_mcap


def test_mcap_nonseeking_reader_stops_with_end_of_file_on_truncation(tmp_path: Path) -> None:
    path = write_mcap(tmp_path / "a.mcap", [imu_stream(imu_data(2000))])
    os.truncate(path, path.stat().st_size // 2)
    got: list[object] = []
    with path.open("rb") as fh, pytest.raises(EndOfFile):
        got.extend(NonSeekingReader(fh).iter_messages(log_time_order=False))
    with path.open("rb") as fh:
        messages = NonSeekingReader(fh).iter_messages(log_time_order=False)
        first = next(iter(messages))
    assert first is not None


def test_mcap_seeking_reader_gets_nothing_from_a_truncated_file(tmp_path: Path) -> None:
    path = write_mcap(tmp_path / "a.mcap", [imu_stream(imu_data(2000))])
    os.truncate(path, path.stat().st_size // 2)
    with path.open("rb") as fh, pytest.raises(Exception):  # noqa: B017, PT011
        list(make_reader(fh).iter_messages())


def test_mcap_crc_validation_aborts_the_whole_read(tmp_path: Path) -> None:
    data = imu_data(1500)
    path = write_mcap(tmp_path / "a.mcap", [imu_stream(data)], compression=CompressionType.NONE)
    with path.open("rb") as fh:
        summary = make_reader(fh).get_summary()
    assert summary is not None
    chunk = summary.chunk_indexes[1]
    raw = bytearray(path.read_bytes())
    raw[chunk.chunk_start_offset + chunk.chunk_length // 2] ^= 0x01
    n = 0
    with pytest.raises(CRCValidationError):  # noqa: PT012
        for _ in StreamReader(io.BytesIO(bytes(raw)), validate_crcs=True).records:
            n += 1
    # ... and with CRCs off the damaged message is returned silently.
    silent = list(StreamReader(io.BytesIO(bytes(raw)), validate_crcs=False).records)
    assert len(silent) > n


def test_rosbags_refuses_an_unindexed_bag(tmp_path: Path) -> None:
    path = write_bag1(tmp_path / "a.bag", [fix_stream(10, ros1=True)])
    raw = bytearray(path.read_bytes())
    at = raw.index(b"index_pos=") + len(b"index_pos=")
    raw[at : at + 8] = bytes(8)
    path.write_bytes(bytes(raw))
    with pytest.raises(Bag1ReaderError, match="not indexed"), Bag1Reader(path):
        pass


def test_rosbags_reads_nothing_from_a_truncated_bag(tmp_path: Path) -> None:
    path = write_bag1(tmp_path / "a.bag", [imu_stream(imu_data(1500), ros1=True)])
    os.truncate(path, path.stat().st_size // 2)
    with pytest.raises(Bag1ReaderError), Bag1Reader(path):
        pass


def test_rosbags_rosbag2_without_metadata_is_file_not_found(tmp_path: Path) -> None:
    bag = write_bag2(tmp_path / "b", [fix_stream(5)], storage="mcap")
    (bag / "metadata.yaml").unlink()
    with pytest.raises(FileNotFoundError):
        Bag2Reader(bag).open()


def test_pyarrow_csv_turns_nan_literals_into_null() -> None:
    table = pacsv.read_csv(io.BytesIO(b"t,v\n1,NaN\n2,1.5\n"))
    assert table["v"].null_count == 1
