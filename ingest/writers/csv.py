"""Plain CSV text logs, the format of many vehicle data loggers.

A file is a header line of column names followed by one line per sample, comma separated, each
column printed with its own printf-style format (``%d``, ``%.6f`` ...). Output is byte-for-byte
deterministic. ``quantize`` returns exactly the float64 values a CSV parser reads back from a
column so that a caller can keep in-memory tables identical to the file.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from navreplay.ingest.arrays import F64
from navreplay.ingest.atomic import atomic_write_text
from navreplay.ingest.errors import IngestError


@dataclass(frozen=True)
class CsvColumn:
    """One column of a CSV log.

    Attributes:
        name: header name.
        values: one value per row (integers for ``%d`` formats).
        fmt: printf-style format of one value, e.g. ``%.6f`` or ``%d``; NaN prints as ``NaN``.
    """

    name: str
    values: npt.NDArray[np.generic]
    fmt: str


def _format(values: npt.NDArray[np.generic], fmt: str) -> list[str]:
    if fmt.endswith("d"):
        return [fmt % v for v in values.astype(np.int64).tolist()]
    return ["NaN" if math.isnan(v) else fmt % v for v in values.astype(np.float64).tolist()]


def quantize(values: npt.ArrayLike, fmt: str) -> F64:
    """The float64 values a parser reads back after printing ``values`` with ``fmt``."""
    arr = np.asarray(values, dtype=np.float64)
    return np.array([float(s) for s in _format(arr, fmt)], dtype=np.float64).reshape(arr.shape)


def write_csv(
    path: str | Path, columns: Sequence[CsvColumn], *, comment: str | None = None
) -> None:
    """Write a CSV log atomically.

    Args:
        path: target file.
        columns: the columns, in order; all of the same length.
        comment: optional first line(s), each prefixed with ``# ``.

    Raises:
        IngestError: the columns differ in length or a name contains a comma or newline.
    """
    lengths = {len(c.values) for c in columns}
    if len(lengths) > 1:
        raise IngestError(f"CSV columns of different lengths {sorted(lengths)}", path=path)
    for c in columns:
        if any(ch in c.name for ch in ",\n\r"):
            raise IngestError(f"CSV column name {c.name!r} contains a separator", path=path)
    cells = [_format(c.values, c.fmt) for c in columns]
    lines: list[str] = []
    if comment:
        lines.extend(f"# {line}" for line in comment.splitlines())
    lines.append(",".join(c.name for c in columns))
    lines.extend(",".join(row) for row in zip(*cells, strict=True))
    atomic_write_text(path, "\n".join(lines) + "\n")
