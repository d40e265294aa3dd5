"""ArduPilot DataFlash message formats (FMT records) as numpy structured dtypes.

A DataFlash log describes its own messages: each ``FMT`` record gives a type byte, the record
length (3 header bytes included), a 4-character name, one format character per column and
the column names. The format characters and their multipliers are pymavlink's
(``pymavlink.DFReader.FORMAT_TO_STRUCT``: ``c`` int16 x 0.01, ``L`` int32 x 1e-7, ``e`` int32
x 0.01, ...); ``DfFormat`` maps them to a packed little-endian numpy dtype so a block of
records of one type decodes with one ``view``, and ``scaled`` applies the multipliers
(as divisions by the decimal unit, so 1e-7 deg values are exact to the last bit).

Raises ``CorruptLogError`` from ``parse_fmt`` for an FMT record whose format uses a character
pymavlink does not know (catalogue case 17) or whose length disagrees with its format; the
reader decides whether the type matters.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from pymavlink.DFReader import FORMAT_TO_STRUCT

FMT_TYPE = 128
FMT_LENGTH = 89
HEADER = 3

_STRUCT_TO_NUMPY = {
    "b": "i1",
    "B": "u1",
    "M": "u1",
    "h": "<i2",
    "H": "<u2",
    "i": "<i4",
    "I": "<u4",
    "q": "<i8",
    "Q": "<u8",
    "f": "<f4",
    "d": "<f8",
    "e": "<f2",
}


class FormatError(ValueError):
    """An FMT record that cannot be turned into a dtype (reason in the message)."""


@dataclass(frozen=True)
class DfFormat:
    """One DataFlash message type.

    Attributes:
        type: the type byte.
        name: message name (``IMU``).
        length: record length including the 3-byte header.
        format: the format characters.
        columns: column names.
        dtype: packed structured dtype of the payload (record minus header).
        per: column -> decimal unit to divide by (100 for ``c``, 1e7 for ``L``), if any.
    """

    type: int
    name: str
    length: int
    format: str
    columns: tuple[str, ...]
    dtype: np.dtype[Any]
    per: dict[str, float]

    @property
    def instance_column(self) -> str | None:
        """``I`` (sensor instance) or ``C`` (EKF core) when the type has one."""
        for name in ("I", "C"):
            if name in self.columns:
                return name
        return None

    @property
    def boot_clock(self) -> tuple[str, int] | None:
        """(column, microseconds per unit) of the record's time since boot, if it has one.

        ``TimeUS`` (2015 on); ``TimeMS`` before, except in GPS records, where ``TimeMS`` is
        the GPS millisecond of the week and ``T`` the boot time in ms; ``StartTime`` of a
        legacy PX4 (sdlog2) ``TIME`` record, which times the records after it."""
        cols = self.columns
        if "TimeUS" in cols:
            return "TimeUS", 1
        if self.name == "TIME" and "StartTime" in cols:
            return "StartTime", 1
        if self.is_gps:
            return ("T", 1000) if "T" in cols else None
        if "TimeMS" in cols:
            return "TimeMS", 1000
        return None

    @property
    def is_gps(self) -> bool:
        return self.name in ("GPS", "GPS2")

    @property
    def gps_time(self) -> tuple[str, ...] | None:
        """Columns of the fix's own GPS time: (week, ms of week) (``GWk``/``GMS``, before 2015
        ``Week``/``TimeMS``), or (UTC us,) (legacy PX4 ``GPSTime``); None if absent."""
        cols = self.columns
        if not self.is_gps:
            return None
        for week, ms in (("GWk", "GMS"), ("Week", "TimeMS")):
            if week in cols and ms in cols:
                return week, ms
        if "GPSTime" in cols:
            return ("GPSTime",)
        return None

    def scaled(self, rec: np.ndarray, column: str) -> np.ndarray:
        """Column ``column`` of decoded records as float64 in the logged units."""
        values = np.asarray(rec[column], dtype=np.float64)
        per = self.per.get(column)
        return values / per if per else values


def _numpy_code(char: str, name: str) -> tuple[str | tuple[str, tuple[int]], Any]:
    if char not in FORMAT_TO_STRUCT:
        raise FormatError(f"message {name}: unsupported format character {char!r}")
    code, mult, _ = FORMAT_TO_STRUCT[char]
    if char == "a":  # int16[32], which pymavlink reads as 64 raw bytes
        return ("<i2", (32,)), None
    if code.endswith("s"):
        return f"S{int(code[:-1])}", None
    return _STRUCT_TO_NUMPY[code], mult


def make_format(type_: int, length: int, name: str, fmt: str, columns: tuple[str, ...]) -> DfFormat:
    """A ``DfFormat`` from FMT fields; raises ``FormatError`` when it is unusable."""
    if len(columns) != len(fmt):
        raise FormatError(
            f"message {name}: {len(fmt)} format characters for {len(columns)} columns"
        )
    fields: list[Any] = []
    per: dict[str, float] = {}
    seen: set[str] = set()
    for char, col in zip(fmt, columns, strict=True):
        code, mult = _numpy_code(char, name)
        key = col if col not in seen else f"{col}_{len(seen)}"
        seen.add(key)
        fields.append((key, *code) if isinstance(code, tuple) else (key, code))
        if mult is not None:
            per[key] = round(1.0 / mult)
    dtype = np.dtype(fields)
    if dtype.itemsize != length - HEADER:
        raise FormatError(
            f"message {name}: format {fmt!r} packs {dtype.itemsize} bytes, the FMT record "
            f"declares {length - HEADER}"
        )
    return DfFormat(type_, name, length, fmt, tuple(columns), dtype, per)


def _text(raw: bytes) -> str:
    return raw.split(b"\0", 1)[0].decode("ascii", "replace").strip()


def parse_fmt(payload: bytes) -> tuple[int, int, str, str, tuple[str, ...]]:
    """(type, length, name, format, columns) of an FMT record's 86-byte payload."""
    type_, length = payload[0], payload[1]
    name = _text(payload[2:6])
    fmt = _text(payload[6:22])
    columns = tuple(c for c in _text(payload[22:86]).split(",") if c) if fmt else ()
    return type_, length, name, fmt, columns


FMT_FORMAT = make_format(
    FMT_TYPE, FMT_LENGTH, "FMT", "BBnNZ", ("Type", "Length", "Name", "Format", "Columns")
)
