"""Format detection from content (catalogue cases 7 and 11), never from the extension."""

from __future__ import annotations

import gzip
import os
import shutil
import sqlite3
import struct
from pathlib import Path

import pytest

from navreplay.ingest.detect import Format, detect
from navreplay.ingest.errors import CorruptLogError, UnsupportedFormatError

from .roslogs import fix_stream, write_bag1, write_bag2, write_mcap

RINEX_OBS = (
    "     3.04           OBSERVATION DATA    M (MIXED)           RINEX VERSION / TYPE\n"
    "navreplay                               20240101 000000 UTC PGM / RUN BY / DATE\n"
)
RINEX2_NAV = (
    "     2              NAVIGATION DATA                         RINEX VERSION / TYPE\n"
    "CCRINEXN V1.6.0 UX  CDDIS               30-JUN-16 23:39     PGM / RUN BY / DATE\n"
)
GNSSLOGGER = (
    "# \n# Header Description:\n# \n# Version: v2.0.4.2 Platform: 10\n# \n"
    "# Raw,utcTimeMillis,TimeNanos,LeapSecond,FullBiasNanos\n# \n"
    "Raw,1,2,18,-1\n"
)


def _tlog_bytes(n: int = 3) -> bytes:
    from pymavlink.dialects.v20 import common

    mav = common.MAVLink(None, srcSystem=1, srcComponent=1)
    out = b""
    for i in range(n):
        packet = mav.heartbeat_encode(2, 3, 0, 0, 4).pack(mav)
        out += struct.pack(">Q", 1_700_000_000_000_000 + i * 1000) + packet
    return out


def _dataflash_bytes() -> bytes:
    fmt = struct.pack("<BB4s16s64s", 128, 89, b"FMT", b"BBnNZ", b"Type,Length,Name,Format,Columns")
    return b"\xa3\x95\x80" + fmt


@pytest.mark.parametrize(
    ("name", "content", "fmt", "variant"),
    [
        ("drive.bin", RINEX_OBS.encode(), Format.RINEX, "obs"),
        ("drive.txt", RINEX2_NAV.encode(), Format.RINEX, "nav"),
        ("drive.obs", GNSSLOGGER.encode(), Format.GNSSLOGGER, ""),
        (
            "drive.mcap",
            b"$GPGGA,021331.00,3725.58,N,12205.61,W,1,15,1.0,6.8,M,-32.6,M,,*55\n" * 3,
            Format.NMEA,
            "",
        ),
        ("drive.log", b"t,ax,ay\n1,2,3\n", Format.CSV, ""),
        (
            "a.csv",
            b"collectionName,phoneName,millisSinceGpsEpoch,constellationType,svid,signalType\n",
            Format.GSDC,
            "derived2021",
        ),
        (
            "b.csv",
            b"collectionName,phoneName,millisSinceGpsEpoch,latDeg,lngDeg,heightAboveWgs84\n",
            Format.GSDC,
            "truth2021",
        ),
        (
            "c.txt",
            b"MessageType,utcTimeMillis,TimeNanos,Svid,SvPositionXEcefMeters\nRaw,1,2,3,4\n",
            Format.GSDC,
            "device_gnss2022",
        ),
        (
            "d.csv",
            b"MessageType,Provider,LatitudeDegrees,LongitudeDegrees,AltitudeMeters\n",
            Format.GSDC,
            "truth2022",
        ),
        ("drive.csv", b"ULog\x01\x12\x35\x01" + bytes(8), Format.ULOG, ""),
        ("drive.tlog", _dataflash_bytes(), Format.DATAFLASH, ""),
        ("drive.bin", _tlog_bytes(), Format.TLOG, ""),
    ],
)
def test_text_and_binary_formats_are_recognised_by_content(
    tmp_path: Path, name: str, content: bytes, fmt: Format, variant: str
) -> None:
    path = tmp_path / name
    path.write_bytes(content)
    found = detect(path)
    assert found.format == fmt
    assert found.variant == variant
    assert found.files == (path,)


def test_gzip_rinex_is_recognised_through_the_compression(tmp_path: Path) -> None:
    path = tmp_path / "x.gz"
    path.write_bytes(gzip.compress(RINEX_OBS.encode()))
    found = detect(path)
    assert (found.format, found.variant, found.version) == (Format.RINEX, "obs+gzip", "3.04")


def test_ros_containers_are_recognised_whatever_their_names(tmp_path: Path) -> None:
    mcap = write_mcap(tmp_path / "log.bag", [fix_stream(3)])
    bag = write_bag1(tmp_path / "log.mcap", [fix_stream(3, ros1=True)])
    rb2 = write_bag2(tmp_path / "rb2", [fix_stream(3)], storage="sqlite3")
    assert detect(mcap).format == Format.MCAP
    assert detect(bag).format == Format.ROS1BAG
    found = detect(rb2)
    assert (found.format, found.variant, found.recovery) == (Format.ROS2BAG, "sqlite3", None)
    assert [f.suffix for f in found.files] == [".db3"]
    # The storage file itself leads to its directory.
    assert detect(found.files[0]).path == rb2


@pytest.mark.parametrize(
    ("content", "reason"),
    [
        (b"", "file is empty"),
        (os.urandom(1000).replace(b"\x89MCAP", b"xxxxx"), "unrecognised content"),
        (b"\x89PNG\r\n\x1a\n" + os.urandom(200), "PNG image"),
        (b"#ROSBAG V1.2\n" + bytes(100), "version 1.2 is not supported"),
    ],
    ids=["empty", "random-bytes", "png-renamed", "old-bag-version"],
)
def test_non_logs_fail_naming_file_offset_and_reason(
    tmp_path: Path, content: bytes, reason: str
) -> None:
    # Catalogue case 7: E-FATAL naming the file, the offset and the reason.
    path = tmp_path / "drive.mcap"
    path.write_bytes(content)
    with pytest.raises(UnsupportedFormatError) as err:
        detect(path)
    assert reason in str(err.value)
    assert str(path) in str(err.value)
    assert err.value.offset == 0 or content == b""
    assert "offset 0" in str(err.value)


def test_missing_path_is_named(tmp_path: Path) -> None:
    with pytest.raises(UnsupportedFormatError, match="no such file"):
        detect(tmp_path / "nope.mcap")


def test_sqlite_that_is_not_a_bag_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "x.db3"
    con = sqlite3.connect(path)
    con.execute("CREATE TABLE t (a INTEGER)")
    con.commit()
    con.close()
    with pytest.raises(UnsupportedFormatError, match="not a rosbag2 storage file"):
        detect(path)


def test_rosbag2_mcap_without_metadata_is_read_directly_and_marked_recovered(
    tmp_path: Path,
) -> None:
    # Catalogue case 11, MCAP storage: E-RECOVER.
    bag = write_bag2(tmp_path / "rb2", [fix_stream(3)], storage="mcap")
    (bag / "metadata.yaml").unlink()
    found = detect(bag)
    assert found.format == Format.ROS2BAG
    assert found.variant == "mcap"
    assert found.recovery is not None
    assert "without metadata.yaml" in found.recovery


def test_rosbag2_db3_without_metadata_names_ros2_bag_reindex(tmp_path: Path) -> None:
    # Catalogue case 11, sqlite3 storage: E-FATAL with the repair command.
    bag = write_bag2(tmp_path / "rb2", [fix_stream(3)], storage="sqlite3")
    (bag / "metadata.yaml").unlink()
    for target in (bag, next(bag.glob("*.db3"))):
        with pytest.raises(CorruptLogError) as err:
            detect(target)
        assert "ros2 bag reindex" in str(err.value)
        assert ".db3" in str(err.value)


def test_directory_that_is_no_bag_is_refused(tmp_path: Path) -> None:
    (tmp_path / "notes.txt").write_text("hello\n")
    with pytest.raises(UnsupportedFormatError, match="not a rosbag2 bag"):
        detect(tmp_path)


def test_rosbag2_metadata_listing_a_missing_file_is_corrupt(tmp_path: Path) -> None:
    bag = write_bag2(tmp_path / "rb2", [fix_stream(3)], storage="sqlite3")
    shutil.move(next(bag.glob("*.db3")), tmp_path / "moved.db3")
    with pytest.raises(CorruptLogError, match="missing"):
        detect(bag)
