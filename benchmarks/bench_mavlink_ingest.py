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
import struct
import tempfile
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks._table import print_table, timed

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "data"
REAL = {
    "vtol.tlog (real SITL)": DATA / "uavlogviewer_sitl_tlog" / "vtol.tlog",
    "ArduCopter .bin (real)": DATA / "uob_flightlab_ardupilot_bin" / "2023-07-06_10-12-18.bin",
}
TLOG_TYPES = ["HIGHRES_IMU", "RAW_IMU", "SCALED_IMU2", "GPS_RAW_INT", "GLOBAL_POSITION_INT"]
TLOG_TYPES += ["ATTITUDE", "SIMSTATE", "SYSTEM_TIME"]
DF_TYPES = ["IMU", "GPS", "GPA", "XKF1", "ORGN"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--mavlink-seconds",
        type=float,
        default=300.0,
        help="duration of the generated tlog and DataFlash drives (default 300 s)",
    )


def write_tlog(path: Path, seconds: float) -> Path:
    from pymavlink.dialects.v20 import ardupilotmega as apm

    link = apm.MAVLink(None, srcSystem=1, srcComponent=1)
    rng = np.random.default_rng(0)
    utc0, boot0 = 1_700_000_000 * 10**6, 50_000_000
    chunks: list[bytes] = []

    def add(t_us: int, msg: object) -> None:
        packet = msg.pack(link)  # type: ignore[attr-defined]
        link.seq = (link.seq + 1) % 256
        chunks.append(struct.pack(">Q", t_us) + packet)

    n = round(seconds * 200)
    acc = np.array([0.0, 0.0, -9.80665]) + rng.normal(0, 0.02, (n, 3))
    gyro = rng.normal(0, 1e-3, (n, 3))
    for i in range(n):
        boot = boot0 + i * 5_000
        stamp = utc0 + i * 5_000 + 2_000
        a, g = acc[i].tolist(), gyro[i].tolist()
        add(stamp, link.highres_imu_encode(boot, *a, *g, 0, 0, 0, 0, 0, 0, 20.0, 0x3F, 0))
        mg = [round(v * 1000 / 9.80665) for v in a]
        add(stamp, link.raw_imu_encode(boot, *mg, *(round(v * 1000) for v in g), 0, 0, 0))
        if i % 20 == 0:
            ms = boot // 1000
            add(stamp, link.attitude_encode(ms, 0.01, 0.02, 1.0, 0.0, 0.0, 0.0))
            add(
                stamp,
                link.global_position_int_encode(
                    ms, 523_456_789, -41_234_567, 120_000, 5_000, 10, 20, 0, 9000
                ),
            )
        if i % 40 == 0:
            add(
                stamp,
                link.gps_raw_int_encode(
                    boot,
                    3,
                    523_456_789,
                    -41_234_567,
                    120_000,
                    90,
                    150,
                    10,
                    9000,
                    14,
                    alt_ellipsoid=170_000,
                    h_acc=900,
                    v_acc=1500,
                    vel_acc=200,
                ),
            )
        if i % 200 == 0:
            add(stamp, link.system_time_encode(utc0 + boot - boot0, boot // 1000))
    path.write_bytes(b"".join(chunks))
    return path


_DF = {  # name: (type, format, columns), as ArduPilot 4.3 logs them
    "IMU": (162, "QBffffffIIfBBHH", "TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,EG,EA,T,GH,AH,GHz,AHz"),
    "GPS": (
        87,
        "QBBIHBcLLeffffB",
        "TimeUS,I,Status,GMS,GWk,NSats,HDop,Lat,Lng,Alt,Spd,GCrs,VZ,Yaw,U",
    ),
    "GPA": (88, "QBCCCCfBIHf", "TimeUS,I,VDop,HAcc,VAcc,SAcc,YAcc,VV,SMS,Delta,Und"),
    "XKF1": (44, "QBccCfffffffccce", "TimeUS,C,Roll,Pitch,Yaw,VN,VE,VD,dPD,PN,PE,PD,GX,GY,GZ,OH"),
    "ORGN": (69, "QBLLe", "TimeUS,Type,Lat,Lng,Alt"),
}


def _df_length(fmt: str) -> int:
    from pymavlink.DFReader import FORMAT_TO_STRUCT

    return 3 + struct.calcsize("<" + "".join(FORMAT_TO_STRUCT[c][0] for c in fmt))


def _df_block(name: str, n: int, values: dict[str, Any]) -> np.ndarray:
    """``n`` DataFlash records of ``name`` (header + payload) as one structured array."""
    from ingest.readers.dfformat import make_format

    type_, fmt, cols = _DF[name]
    payload = make_format(type_, _df_length(fmt), name, fmt, tuple(cols.split(",")))
    dtype = np.dtype([("h1", "u1"), ("h2", "u1"), ("type", "u1"), ("p", payload.dtype)])
    out = np.zeros(n, dtype)
    out["h1"], out["h2"], out["type"] = 0xA3, 0x95, type_
    for key, v in values.items():
        out["p"][key] = v
    return out


def write_dataflash(path: Path, seconds: float) -> Path:
    """Three IMUs at 400 Hz, GPS+GPA at 5 Hz, three EKF cores at 10 Hz, in time order."""
    rng = np.random.default_rng(1)
    head = b""
    fmt_fmt = {"FMT": (128, "BBnNZ", "Type,Length,Name,Format,Columns")}
    for name, (type_, fmt, cols) in (fmt_fmt | _DF).items():
        length = _df_length(fmt)
        head += b"\xa3\x95\x80" + struct.pack(
            "<BB4s16s64s", type_, length, name.encode(), fmt.encode(), cols.encode()
        )
    t0, n, m, k = 30_000_000, round(seconds * 400), round(seconds * 5), round(seconds * 10)
    t_imu = t0 + np.arange(n, dtype=np.int64) * 2_500
    t_gps = t0 + np.arange(m, dtype=np.int64) * 200_000
    t_ekf = t0 + np.arange(k, dtype=np.int64) * 100_000
    parts: list[tuple[np.ndarray, np.ndarray]] = []
    for inst in range(3):
        imu = {"TimeUS": t_imu + inst, "I": inst, "GyrX": rng.normal(0, 1e-3, n)}
        imu |= {"AccZ": -9.80665 + rng.normal(0, 0.02, n), "GHz": 8000, "AHz": 4000}
        parts.append((t_imu + inst, _df_block("IMU", n, imu)))
    gps: dict[str, Any] = {"TimeUS": t_gps, "Status": 3, "GWk": 2269, "NSats": 20, "HDop": 60}
    gps |= {"GMS": 378_756_400 + np.arange(m) * 200, "Lat": 528_069_428, "Lng": -41_224_417}
    gps |= {"Alt": 1772, "Spd": 0.1, "U": 1}
    parts.append((t_gps, _df_block("GPS", m, gps)))
    gpa = {"TimeUS": t_gps + 10, "HAcc": 30, "VAcc": 40, "SAcc": 8, "VV": 1, "Und": -50.5}
    parts.append((t_gps + 10, _df_block("GPA", m, gpa)))
    for core in range(3):
        ekf = {"TimeUS": t_ekf + 20 + core, "C": core, "Yaw": 9000, "PN": 1.0, "PE": 2.0}
        parts.append((t_ekf + 20 + core, _df_block("XKF1", k, ekf)))
    orgn = {"TimeUS": t0, "Type": 0, "Lat": 528_069_428, "Lng": -41_224_417, "Alt": 1772}
    parts.append((np.array([t0]), _df_block("ORGN", 1, orgn)))
    times = np.concatenate([t for t, _ in parts])
    records = [r[i : i + 1].tobytes() for _, rec in parts for r in (rec,) for i in range(len(r))]
    order = np.argsort(times, kind="stable").tolist()
    path.write_bytes(head + b"".join(records[i] for i in order))
    return path


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
    from ingest.detect import detect
    from ingest.readers import open_reader
    from ingest.readers.base import DamageLog, ReadContext, Selection

    with open_reader(detect(path), ReadContext(DamageLog(path, strict=False))) as reader:
        inv = reader.inventory()
        chosen = [Selection(s.key, s.table) for s in inv.streams if s.table is not None]
        return sum(len(b) for b in reader.read(chosen))


def _count_into(out: list[int], fn: Callable[[], int]) -> None:
    out.append(fn())


def run(options: argparse.Namespace) -> None:
    from ingest.api import ingest
    from ingest.config import parse_dataset_config

    tmp = Path(tempfile.mkdtemp(prefix="navreplay-bench-mav-"))
    try:
        files = {k: v for k, v in REAL.items() if v.exists()}
        if len(files) < len(REAL):
            print(f"   (real logs under {DATA} absent: generated files only)")
        seconds = options.mavlink_seconds
        files[f"generated tlog, {seconds:.0f} s"] = write_tlog(tmp / "gen.tlog", seconds)
        files[f"generated .bin, {seconds:.0f} s"] = write_dataflash(tmp / "gen.bin", seconds)
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
