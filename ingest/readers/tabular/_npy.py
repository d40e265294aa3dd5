"""NumPy ``.npy`` arrays read defensively: the header is checked before any allocation, and a
file that ends early yields its complete rows with the loss recorded (catalogue case 15's rule
for a trailing partial record, applied to arrays).

comma2k19 stores every stream as ``.npy`` files without an extension; ``np.load`` alone would
raise a bare ``ValueError`` on a truncated file and trust any header shape.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from tokenize import TokenError

import numpy as np

from navreplay.ingest.damage import Completeness, DamageLog, Defect
from navreplay.ingest.errors import CorruptLogError

NPY_MAGIC = b"\x93NUMPY"


@dataclass(frozen=True)
class NpyHeader:
    """What a ``.npy`` header declares, and where the data starts.

    Attributes:
        shape: declared shape (rows first).
        dtype: element type.
        data_offset: byte offset of the first row.
        rows_readable: complete rows actually present in the file.
        fortran: column-major storage (each column's values contiguous).
    """

    shape: tuple[int, ...]
    dtype: np.dtype
    data_offset: int
    rows_readable: int
    fortran: bool = False

    @property
    def rows(self) -> int:
        return self.shape[0] if self.shape else 1

    @property
    def row_bytes(self) -> int:
        return int(np.prod(self.shape[1:], dtype=np.int64)) * self.dtype.itemsize

    @property
    def columns(self) -> int:
        return int(np.prod(self.shape[1:], dtype=np.int64))

    def row_offsets(self, n: int | None = None) -> np.ndarray:
        """Byte offset of each of the first ``n`` rows (default: every readable row); for a
        column-major array, of the row's first value."""
        count = self.rows_readable if n is None else n
        step = self.dtype.itemsize if self.fortran else self.row_bytes
        return self.data_offset + np.arange(count, dtype=np.int64) * step

    def missing_offset(self) -> int:
        """Byte offset where the first value the file lacks would be."""
        present = self.rows_readable * (1 if self.fortran else self.columns)
        if self.fortran:
            present += (self.columns - 1) * self.rows
        return self.data_offset + present * self.dtype.itemsize

    def _readable(self, size: int) -> int:
        values = max(size - self.data_offset, 0) // self.dtype.itemsize
        if not self.shape:
            return 1 if values else 0
        if not self.fortran or self.columns == 1:
            return min(self.rows, values // max(self.columns, 1))
        # Column-major: the last column is the one cut short; earlier columns must be whole.
        whole, rest = divmod(values, self.rows)
        return self.rows if whole >= self.columns else rest if whole == self.columns - 1 else 0


def read_header(path: Path) -> NpyHeader:
    """Parse and check the header of ``path``.

    Raises:
        CorruptLogError: not a ``.npy`` file, an unreadable header, or an object array.
    """
    try:
        size = path.stat().st_size
        with path.open("rb") as fh:
            head = fh.read(len(NPY_MAGIC))
            if head != NPY_MAGIC:
                raise CorruptLogError(
                    f"not a NumPy .npy file (first bytes {head.hex(' ')})", path=path, offset=0
                )
            fh.seek(0)
            version = np.lib.format.read_magic(fh)
            if version == (1, 0):
                shape, fortran, dtype = np.lib.format.read_array_header_1_0(fh)
            else:
                shape, fortran, dtype = np.lib.format.read_array_header_2_0(fh)
            offset = fh.tell()
    except OSError as err:
        raise CorruptLogError(f"cannot read: {err.strerror}", path=path) from err
    except (ValueError, SyntaxError, TokenError, TypeError) as err:
        # numpy parses the header's Python literal: damage there fails in its tokenizer too
        raise CorruptLogError(
            f"unreadable .npy header: {err}",
            path=path,
            offset=0,
            hint="the array's header is damaged; restore the file from its source",
        ) from err
    if dtype.hasobject:
        raise CorruptLogError("an object array, not a stored log stream", path=path, offset=0)
    header = NpyHeader(tuple(int(s) for s in shape), dtype, offset, 0, bool(fortran))
    return NpyHeader(header.shape, dtype, offset, header._readable(size), header.fortran)


def load(path: Path, damage: DamageLog, name: str | None = None) -> tuple[np.ndarray, NpyHeader]:
    """The readable rows of ``path`` as an array, and its header.

    ``name`` is how defects name the file (default: its file name).

    A file shorter than its header declares yields its complete rows; the loss is recorded in
    ``damage`` (``truncated``, raising under ``--strict``) with the offset of the first
    missing row.

    Raises:
        CorruptLogError: see ``read_header``.
    """
    header = read_header(path)
    count = header.rows_readable
    with path.open("rb") as fh:
        fh.seek(header.data_offset)
        if header.fortran and count < header.rows:
            flat = np.fromfile(fh, dtype=header.dtype, count=header.rows * header.columns)
            full = np.zeros(header.rows * header.columns, header.dtype)
            full[: len(flat)] = flat
            data = full.reshape(header.shape, order="F")[:count]
        else:
            flat = np.fromfile(fh, dtype=header.dtype, count=count * max(header.columns, 1))
            shape = (count, *header.shape[1:]) if header.shape else ()
            data = flat.reshape(shape, order="F" if header.fortran else "C")
    if count < header.rows:
        damage.record(
            Defect(
                Completeness.TRUNCATED,
                f"{name or path.name}: {count} of {header.rows} rows complete, the file ends early",
                offset=header.missing_offset(),
                messages_lost=header.rows - count,
                messages_recovered=count,
            )
        )
    end = header.data_offset + header.rows * header.row_bytes if header.shape else None
    size = path.stat().st_size
    if end is not None and size > end:
        damage.record(
            Defect(
                Completeness.CORRUPT_TAIL,
                f"{name or path.name}: {size - end} bytes after the end of the array's data "
                "(the header declares fewer rows: a copy or another array appended?) ignored",
                offset=end,
                bytes_skipped=size - end,
            )
        )
    return np.ascontiguousarray(data, dtype=np.float64), header
