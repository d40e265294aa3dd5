"""ROS log ingest throughput: `navreplay ingest` vs the plain library loops on the same files.

One synthetic drive (IMU 200 Hz, NavSatFix 5 Hz, Odometry 20 Hz) is written with the
libraries' own writers as a ROS 1 bag (uncompressed and lz4), a rosbag2 directory (sqlite3
and MCAP storage) and a ROS 2 MCAP. For each file the full ``ingest()`` (decode, hygiene,
audit, Parquet output, sha256 of the input) is timed against rosbags' ``AnyReader.messages``
+ ``deserialize`` over the same topics, which produces nothing but message objects; for the
MCAP file also against mcap-ros2-support's ``iter_decoded_messages``. Target: ratio >= 1.
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
from collections.abc import Callable
from functools import partial
from pathlib import Path

from benchmarks._options import Option
from benchmarks._table import print_table, timed
from tests.ingest.roslogs import (
    Stream,
    fix_stream,
    imu_data,
    imu_payloads,
    odom_stream,
    write_bag1,
    write_bag2,
    write_mcap,
)

OPTIONS = [
    Option(
        "--ros-imu-messages",
        "IMU messages in the ros_ingest drive (default 200000 = 1000 s at 200 Hz)",
        int,
        200_000,
    ),
]


def _drive(ros1: bool, n: int) -> list[Stream]:
    data = imu_data(n, 200.0)
    rows = imu_payloads(ros1, data)
    imu = Stream(
        "/imu/data",
        "sensor_msgs/msg/Imu",
        [(t, r.tobytes()) for t, r in zip(data.t_ns.tolist(), rows, strict=True)],
    )
    return [imu, fix_stream(n // 40, ros1=ros1), odom_stream(n // 10, 20.0, ros1=ros1)]


def build(tmp: Path, n: int) -> dict[str, Path]:
    ros1, ros2 = _drive(True, n), _drive(False, n)
    mb = 1 << 20
    return {
        "ROS 1 bag, uncompressed": write_bag1(tmp / "a.bag", ros1, chunk_threshold=mb),
        "ROS 1 bag, lz4": write_bag1(tmp / "b.bag", ros1, compression="lz4", chunk_threshold=mb),
        "rosbag2 sqlite3": write_bag2(tmp / "c", ros2, storage="sqlite3"),
        "rosbag2 mcap": write_bag2(tmp / "d", ros2, storage="mcap"),
        "MCAP ros2 (zstd)": write_mcap(tmp / "e.mcap", ros2, chunk_size=mb),
    }


def plain_rosbags(path: Path) -> int:
    """The reference loop: every message read and deserialized by rosbags."""
    from rosbags.highlevel import AnyReader

    n = 0
    with AnyReader([path]) as reader:
        for conn, _t, raw in reader.messages(connections=reader.connections):
            reader.deserialize(raw, conn.msgtype)
            n += 1
    return n


def plain_mcap_ros2(path: Path) -> int:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    n = 0
    with path.open("rb") as fh:
        reader = make_reader(fh, decoder_factories=[DecoderFactory()])
        for _ in reader.iter_decoded_messages(log_time_order=False):
            n += 1
    return n


def _count_into(out: list[int], fn: Callable[[Path], int], path: Path) -> None:
    out.append(fn(path))


def run(options: argparse.Namespace) -> None:
    from navreplay.ingest.api import ingest

    n = options.ros_imu_messages
    tmp = Path(tempfile.mkdtemp(prefix="navreplay-bench-"))
    try:
        files = build(tmp, n)
        # Warm-up: imports and loading each reader's compiled kernels are not throughput.
        for path in files.values():
            ingest([path], tmp / "warm")
        rows: list[list[object]] = []
        for label, path in files.items():
            ours = timed(partial(ingest, [path], tmp / "out"), repeat=2)
            refs: list[tuple[str, Callable[[Path], int]]] = [
                ("rosbags AnyReader+deserialize", plain_rosbags)
            ]
            if "MCAP" in label:
                refs.append(("mcap-ros2 iter_decoded", plain_mcap_ros2))
            for ref_name, fn in refs:
                counts: list[int] = []
                ref = timed(partial(_count_into, counts, fn, path))
                count = counts[0]
                rows.append(
                    [
                        label,
                        ref_name,
                        count,
                        ours.seconds,
                        count / ours.seconds,
                        ref.seconds,
                        count / ref.seconds,
                        ref.seconds / ours.seconds,
                    ]
                )
        print_table(
            [
                "file",
                "reference",
                "messages",
                "ours s",
                "ours msg/s",
                "ref s",
                "ref msg/s",
                "ratio",
            ],
            rows,
        )
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
