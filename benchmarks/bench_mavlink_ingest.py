"""MAVLink tlog and DataFlash ingest throughput vs the plain pymavlink loop on the same files.

Files: the real logs of ../shared/data when present (the SITL ``vtol.tlog``, the Bristol
ArduCopter ``.bin``), and larger generated ones: a tlog of a drive with HIGHRES_IMU and
RAW_IMU at 200 Hz, GPS_RAW_INT at 5 Hz, ATTITUDE + GLOBAL_POSITION_INT at 10 Hz and
SYSTEM_TIME (packets packed by pymavlink), and a DataFlash log with three IMUs at 400 Hz,
GPS+GPA at 5 Hz and three EKF cores at 10 Hz (records packed with numpy in the DataFlash
layout). For each file the full ``ingest()`` (framing, CRC, decoding, hygiene, audit,
Parquet output, sha256 of the input) is timed against
``mavutil.mavlink_connection(path).recv_match(type=[...])`` over the message types ingest
converts, which produces nothing but message objects, and against the same loop over every
message. Target: ratio >= 5 against the type-filtered loop.
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
from tests.ingest.mavlogs import write_dataflash_drive, write_tlog_drive

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "data"
REAL = {
    "vtol.tlog (real SITL)": DATA / "uavlogviewer_sitl_tlog" / "vtol.tlog",
    "ArduCopter .bin (real)": DATA / "uob_flightlab_ardupilot_bin" / "2023-07-06_10-12-18.bin",
}
TLOG_TYPES = ["HIGHRES_IMU", "RAW_IMU", "SCALED_IMU2", "GPS_RAW_INT", "GLOBAL_POSITION_INT"]
TLOG_TYPES += ["ATTITUDE", "SIMSTATE", "SYSTEM_TIME"]
DF_TYPES = ["IMU", "GPS", "GPA", "XKF1", "ORGN"]


OPTIONS = [
    Option(
        "--mavlink-seconds",
        "duration of the generated tlog and DataFlash drives (default 300 s)",
        float,
        300.0,
    ),
]


def plain_pymavlink(path: Path, types: list[str] | None) -> int:
    """The reference loop: every (selected) message decoded by pymavlink."""
    from pymavlink import mavutil

    conn = mavutil.mavlink_connection(str(path), dialect="ardupilotmega")
    n = 0
    while conn.recv_match(type=types) is not None:
        n += 1
    conn.close()
    return n


def reader_only(path: Path) -> int:
    """Inventory and read every stream ingest could convert: decoding without output."""
    from navreplay.ingest.damage import DamageLog
    from navreplay.ingest.detect import detect
    from navreplay.ingest.readers import open_reader
    from navreplay.ingest.readers.base import ReadContext, Selection

    with open_reader(detect(path), ReadContext(DamageLog(path, strict=False))) as reader:
        inv = reader.inventory()
        chosen = [Selection(s.key, s.table) for s in inv.streams if s.table is not None]
        return sum(len(b) for b in reader.read(chosen))


def _count_into(out: list[int], fn: Callable[[], int]) -> None:
    out.append(fn())


def run(options: argparse.Namespace) -> None:
    from navreplay.ingest.api import ingest
    from navreplay.ingest.config import parse_dataset_config

    tmp = Path(tempfile.mkdtemp(prefix="navreplay-bench-mav-"))
    try:
        files = {k: v for k, v in REAL.items() if v.exists()}
        if len(files) < len(REAL):
            print(f"   (real logs under {DATA} absent: generated files only)")
        seconds = options.mavlink_seconds
        files[f"generated tlog, {seconds:.0f} s"] = write_tlog_drive(tmp / "gen.tlog", seconds)
        files[f"generated .bin, {seconds:.0f} s"] = write_dataflash_drive(tmp / "gen.bin", seconds)
        # In flight from the start: the gyro unit check is told the units, as in the tests.
        cfg = parse_dataset_config({"id": "bench", "imu": {"gyro_units": "radps"}})
        for path in files.values():  # warm-up: imports and compiled kernels are not throughput
            ingest([path], tmp / "warm", config=cfg)
        rows: list[list[object]] = []
        for label, path in files.items():
            mb = path.stat().st_size / 1e6
            ours = timed(partial(ingest, [path], tmp / "out", config=cfg), repeat=2)
            decode = timed(partial(reader_only, path), repeat=2)
            types = DF_TYPES if path.suffix == ".bin" else TLOG_TYPES
            for ref_name, selected in (("type=converted", types), ("all messages", None)):
                counts: list[int] = []
                ref = timed(partial(_count_into, counts, partial(plain_pymavlink, path, selected)))
                rows.append(
                    [
                        label,
                        ref_name,
                        mb,
                        counts[0],
                        ours.seconds,
                        decode.seconds,
                        ref.seconds,
                        ref.seconds / ours.seconds,
                        ref.seconds / decode.seconds,
                    ]
                )
        print_table(
            [
                "file",
                "recv_match",
                "MB",
                "ref msgs",
                "ingest s",
                "reader s",
                "ref s",
                "ratio ingest",
                "ratio reader",
            ],
            rows,
        )
        print(
            "   ingest: the whole `navreplay ingest` (incl. ~0.1 s of fixed cost: atomic, "
            "fsynced Parquet and JSON output);\n   reader: inventory + read of every "
            "convertible stream (decoding only)"
        )
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
