"""Ingest peak memory on a large log of small IMU messages (catalogue case 39).

An uncompressed ROS 2 MCAP of 400 Hz IMU messages (about 330 bytes each) is written with
``mcap.writer.Writer`` to the requested size; ``ingest()`` then runs in a fresh process and
its peak RSS (``ru_maxrss``) is reported next to that of a process that only imports the
package and ingests a tiny log (the fixed cost), and next to the plain rosbags loop on the same
file. Target: under 500 MB for a 2 GB log (``--memory-log-mb 2048``; the default is smaller so
``make bench`` stays quick).
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

from benchmarks._options import Option
from benchmarks._table import print_table
from tests.ingest.roslogs import imu_data, imu_payloads, msgdef

PAYLOAD_BYTES = 9 + 22 + 324  # MCAP message record around a 324-byte CDR Imu


OPTIONS = [
    Option(
        "--memory-log-mb",
        "size of the ingest_memory log in MB (2048 for the 2 GB target; default 256)",
        int,
        256,
    ),
    Option(
        "--memory-no-reference",
        "skip the rosbags loop's memory on the same file (slow for multi-GB logs)",
    ),
]


def write_log(path: Path, target_bytes: int, batch: int = 500_000) -> int:
    """Write the IMU MCAP in batches of ``batch`` messages; returns the message count."""
    from mcap.writer import CompressionType, Writer

    n_total = target_bytes // PAYLOAD_BYTES
    with path.open("wb") as fh:
        w = Writer(fh, chunk_size=1 << 20, compression=CompressionType.NONE)
        w.start(profile="ros2", library="navreplay-bench")
        schema = w.register_schema(
            "sensor_msgs/msg/Imu", "ros2msg", msgdef(False, "sensor_msgs/msg/Imu").encode()
        )
        ch = w.register_channel("/imu/data", "cdr", schema)
        done = 0
        while done < n_total:
            n = min(batch, n_total - done)
            data = imu_data(n, 400.0, seed=done, t0_ns=1_700_000_000 * 10**9 + done * 2_500_000)
            for t, row in zip(data.t_ns.tolist(), imu_payloads(False, data), strict=True):
                w.add_message(ch, log_time=t, data=row.tobytes(), publish_time=t)
            done += n
        w.finish()  # type: ignore[no-untyped-call]
    return n_total


# Peak RSS of the child's own address space. ru_maxrss is not used: Linux carries the parent's
# high-water mark into a forked-and-exec'd child, so a big parent would inflate the figure.
PEAK_RSS = (
    "\nimport re\n"
    "print(re.search(r'VmHWM:\\s+(\\d+)', open('/proc/self/status').read()).group(1))\n"
)


#: the measured process: ingest of one log, printing the IMU rows it wrote
INGEST_CODE = textwrap.dedent(
    """
    from pathlib import Path
    from navreplay.ingest.api import ingest
    print(ingest([Path({log!r})], Path({out!r})).tables["imu"])
    """
)


def _child(code: str) -> tuple[str, float, float]:
    """Run ``code`` in a fresh interpreter: (its stdout, peak RSS MB, wall s)."""
    script = code + PEAK_RSS
    start = time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, check=True
    )
    lines = done.stdout.split()
    return " ".join(lines[:-1]), int(lines[-1]) / 1024, time.perf_counter() - start


def run(options: argparse.Namespace) -> None:
    tmp = Path(tempfile.mkdtemp(prefix="navreplay-bench-mem-"))
    try:
        big = tmp / "imu.mcap"
        start = time.perf_counter()
        n = write_log(big, options.memory_log_mb * (1 << 20))
        size_mb = big.stat().st_size / (1 << 20)
        print(
            f"  wrote {size_mb:,.0f} MB, {n:,} IMU messages in {time.perf_counter() - start:.0f} s"
        )
        small = tmp / "small.mcap"
        write_log(small, 1 << 20)
        rows: list[list[object]] = []
        for label, log in (("ingest, 1 MB log (fixed cost)", small), ("ingest", big)):
            out, rss, wall = _child(INGEST_CODE.format(log=str(log), out=str(tmp / "out")))
            rows.append([label, f"{log.stat().st_size / (1 << 20):,.0f} MB", int(out), rss, wall])
        if not options.memory_no_reference:
            ref = textwrap.dedent(
                f"""
                from pathlib import Path
                from rosbags.highlevel import AnyReader
                n = 0
                with AnyReader([Path({str(big)!r})]) as r:
                    for c, t, raw in r.messages(connections=r.connections):
                        r.deserialize(raw, c.msgtype)
                        n += 1
                print(n)
                """
            )
            out, rss, wall = _child(ref)
            rows.append(
                ["rosbags AnyReader+deserialize", f"{size_mb:,.0f} MB", int(out), rss, wall]
            )
        print_table(["process", "log", "messages", "peak RSS MB", "wall s"], rows)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
