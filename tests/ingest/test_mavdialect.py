"""The compiled MAVLink framing and the dtype decoder agree with pymavlink on every message of
the ardupilotmega dialect: random field values are packed by pymavlink (MAVLink 2, so
trailing zero bytes are trimmed), framed by ``scan_tlog`` and decoded by one dtype view, and
each field is compared with pymavlink's own decoding of the same bytes."""

from __future__ import annotations

import struct
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as apm
from pymavlink.generator.mavcrc import x25crc

from navreplay.ingest.readers.mavlink._mavscan import VALID, x25_crc
from navreplay.ingest.readers.mavlink.dfformat import FormatError, make_format
from navreplay.ingest.readers.mavlink.mavdialect import load_dialect
from navreplay.ingest.readers.mavlink.tlogclock import decode
from navreplay.ingest.readers.mavlink.tlogscan import ScanStats, scan_blocks

_RANGES = {
    "int8_t": (-128, 127),
    "uint8_t": (0, 255),
    "uint8_t_mavlink_version": (0, 255),
    "int16_t": (-32768, 32767),
    "uint16_t": (0, 65535),
    "int32_t": (-(2**31), 2**31 - 1),
    "uint32_t": (0, 2**32 - 1),
    "int64_t": (-(2**63), 2**63 - 1),
    "uint64_t": (0, 2**64 - 1),
}


def _value(rng: np.random.Generator, ctype: str, n: int) -> Any:
    if ctype == "char":
        return bytes(rng.integers(65, 91, max(n, 1), dtype=np.uint8).tolist())
    vals: list[Any]
    if ctype in ("float", "double"):
        normal = rng.normal(0, 1e3, max(n, 1))
        vals = (normal.astype(np.float32) if ctype == "float" else normal).astype(float).tolist()
    else:
        lo, hi = _RANGES[ctype]
        kind = np.uint64 if lo == 0 else np.int64
        vals = [int(rng.integers(lo, hi, endpoint=True, dtype=kind)) for _ in range(max(n, 1))]
    return vals if n else vals[0]


def _random_message(rng: np.random.Generator, cls: Any) -> Any:
    arrays = dict(zip(cls.ordered_fieldnames, cls.array_lengths, strict=True))
    types = dict(zip(cls.fieldnames, cls.fieldtypes, strict=True))
    args = [_value(rng, types[f], int(arrays[f])) for f in cls.fieldnames]
    return cls(*args)


def test_every_message_decodes_like_pymavlink(tmp_path: Path) -> None:
    rng = np.random.default_rng(7)
    link = apm.MAVLink(None, srcSystem=1, srcComponent=1)
    classes = sorted(apm.mavlink_map.items())
    records, messages = [], []
    for _, cls in classes:
        msg = _random_message(rng, cls)
        packet = msg.pack(link)
        link.seq = (link.seq + 1) % 256
        records.append(struct.pack(">Q", 1_700_000_000_000_000) + packet)
        parsed = apm.MAVLink(None).parse_char(packet)
        messages.append(parsed)
    path = tmp_path / "all.tlog"
    path.write_bytes(b"".join(records))
    dialect = load_dialect("ardupilotmega")
    stats = ScanStats()
    (block,) = list(scan_blocks(path, dialect, stats))
    assert len(block) == len(classes)
    assert (block.flag == VALID).all()
    assert stats.garbage_runs == 0
    for i, ref in enumerate(messages):
        mdef = dialect.message(int(block.msgid[i]))
        rec = decode(block, np.array([i]), mdef)[0]
        for name in ref.get_fieldnames():
            want, got = getattr(ref, name), rec[name]
            if isinstance(want, str):
                assert got.decode() == want, (mdef.name, name)
            elif isinstance(want, bytes | bytearray):
                assert bytes(got).rstrip(b"\0") == bytes(want).rstrip(b"\0"), (mdef.name, name)
            else:
                np.testing.assert_array_equal(np.asarray(got), np.asarray(want), (mdef.name, name))


def test_x25_crc_matches_pymavlink() -> None:
    rng = np.random.default_rng(3)
    for n in (0, 1, 9, 255):
        data = rng.integers(0, 256, n, dtype=np.uint8)
        extra = int(rng.integers(0, 256))
        ref = x25crc(data.tobytes())
        ref.accumulate(bytes([extra]))
        assert x25_crc(data, 0, n, extra) == ref.crc


IMU_COLUMNS: tuple[str, ...] = ("TimeUS", "I", "GyrX", "GyrY", "GyrZ", "AccX", "AccY", "AccZ")
IMU_COLUMNS += ("EG", "EA", "T", "GH", "AH", "GHz", "AHz")
GPS_COLUMNS: tuple[str, ...] = ("TimeUS", "I", "Status", "GMS", "GWk", "NSats", "HDop", "Lat")
GPS_COLUMNS += ("Lng", "Alt", "Spd", "GCrs", "VZ", "Yaw", "U")


def test_dataflash_format_sizes_and_unknown_characters() -> None:
    fmt = make_format(162, 54, "IMU", "QBffffffIIfBBHH", IMU_COLUMNS)
    assert fmt.instance_column == "I"
    scaled = make_format(87, 51, "GPS", "QBBIHBcLLeffffB", GPS_COLUMNS)
    assert scaled.per == {"HDop": 100, "Lat": 10**7, "Lng": 10**7, "Alt": 100}
    with pytest.raises(FormatError, match="unsupported format character 'X'"):
        make_format(10, 12, "ODD", "QX", ("TimeUS", "Odd"))
    with pytest.raises(FormatError, match="declares 20"):
        make_format(10, 23, "BAD", "Q", ("TimeUS",))
