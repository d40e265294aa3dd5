"""Canonical Parquet tables: atomic, checksummed writes with provenance, and checked reads.

Every file carries, under the schema metadata key ``navreplay``, a JSON provenance record: the
table name, schema version, package version, git commit (when the package runs from a git
checkout), the sha256 of each source file, and a hash of the parameters that produced it.
Pages carry CRC checksums, verified on read.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import subprocess
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from functools import lru_cache
from importlib import metadata
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from navreplay.ingest.atomic import AtomicWriter, dumps_json
from navreplay.ingest.errors import (
    CorruptLogError,
    IngestError,
    ProvenanceError,
    TableValidationError,
)
from navreplay.ingest.schema import (
    SCHEMA_VERSION,
    ContextName,
    TableName,
    last_key,
    spec,
    table_name,
    validate,
)

PROVENANCE_KEY = b"navreplay"
_ROW_GROUP_ROWS = 262_144


@lru_cache(maxsize=1)
def package_version() -> str:
    """The installed navreplay version, or ``0+unknown`` when running from an uninstalled tree."""
    try:
        return metadata.version("navreplay")
    except metadata.PackageNotFoundError:
        return "0+unknown"


@lru_cache(maxsize=1)
def git_commit() -> str | None:
    """The commit of the navreplay checkout (``+dirty`` if tracked files changed), or None."""
    here = Path(__file__).resolve().parent
    try:
        head = subprocess.run(
            ["git", "-C", str(here), "rev-parse", "HEAD"],
            capture_output=True,
            text=True,
            check=True,
            timeout=10,
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "-C", str(here), "status", "--porcelain", "--untracked-files=no"],
            capture_output=True,
            text=True,
            check=True,
            timeout=10,
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None
    return f"{head}+dirty" if dirty else head


def sha256_file(path: str | Path, *, chunk_bytes: int = 1 << 20) -> str:
    """Hex sha256 of a file's bytes, streamed; for a directory, of its files in sorted order."""
    path = Path(path)
    h = hashlib.sha256()
    files = sorted(p for p in path.rglob("*") if p.is_file()) if path.is_dir() else [path]
    for f in files:
        if path.is_dir():
            h.update(str(f.relative_to(path)).encode())
        with f.open("rb") as fh:
            while chunk := fh.read(chunk_bytes):
                h.update(chunk)
    return h.hexdigest()


def params_hash(params: Mapping[str, Any] | None) -> str | None:
    """A stable short hash of a parameter mapping (sorted-key JSON), or None."""
    if params is None:
        return None
    return hashlib.sha256(dumps_json(params).encode()).hexdigest()[:16]


@dataclass(frozen=True)
class SourceFile:
    """A file a table was derived from: its name (not its machine-specific path) and sha256."""

    name: str
    sha256: str


@dataclass(frozen=True)
class Provenance:
    """Where a table came from. Stored in every Parquet file navreplay writes."""

    table: str
    package_version: str
    git_commit: str | None
    sources: tuple[SourceFile, ...]
    params_hash: str | None
    schema_version: int = SCHEMA_VERSION
    extra: Mapping[str, str] = field(default_factory=dict)

    @classmethod
    def create(
        cls,
        table: TableName | ContextName | str,
        *,
        sources: Iterable[str | Path | SourceFile] = (),
        params: Mapping[str, Any] | None = None,
        extra: Mapping[str, str] | None = None,
    ) -> Provenance:
        """Provenance for a table made now, hashing each source file (or taking its hash)."""
        files = tuple(
            s if isinstance(s, SourceFile) else SourceFile(Path(s).name, sha256_file(s))
            for s in sources
        )
        return cls(
            table=table_name(table).value,
            package_version=package_version(),
            git_commit=git_commit(),
            sources=files,
            params_hash=params_hash(params),
            extra=dict(extra or {}),
        )

    def to_json(self) -> str:
        return dumps_json(
            {
                "table": self.table,
                "schema_version": self.schema_version,
                "package_version": self.package_version,
                "git_commit": self.git_commit,
                "sources": [{"name": s.name, "sha256": s.sha256} for s in self.sources],
                "params_hash": self.params_hash,
                "extra": dict(self.extra),
            }
        )

    @classmethod
    def from_json(cls, text: str | bytes, *, path: Path | None = None) -> Provenance:
        try:
            raw = json.loads(text)
            return cls(
                table=str(raw["table"]),
                schema_version=int(raw["schema_version"]),
                package_version=str(raw["package_version"]),
                git_commit=None if raw["git_commit"] is None else str(raw["git_commit"]),
                sources=tuple(SourceFile(str(s["name"]), str(s["sha256"])) for s in raw["sources"]),
                params_hash=None if raw["params_hash"] is None else str(raw["params_hash"]),
                extra={str(k): str(v) for k, v in raw.get("extra", {}).items()},
            )
        except (ValueError, KeyError, TypeError) as err:
            raise ProvenanceError(f"provenance record is malformed: {err}", path=path) from err


class TableWriter(AtomicWriter):
    """Stream a canonical table to Parquet, chunk by chunk, appearing atomically on success.

    Use as a context manager; each ``write`` validates its chunk (schema, and key order also
    across chunks) and appends it as row groups. If the block raises, or the process dies,
    nothing appears at ``path`` and an earlier file there is untouched. With no chunk written,
    an empty file with the full canonical schema is produced.

    Args:
        path: final path of the Parquet file.
        name: canonical table name.
        provenance: stored in the file metadata; its ``table`` must equal ``name``.
    """

    def __init__(
        self, path: str | Path, name: TableName | ContextName | str, provenance: Provenance
    ) -> None:
        self.path = Path(path)
        self.name = table_name(name)
        if provenance.table != self.name.value:
            raise ProvenanceError(
                f"provenance is for table {provenance.table!r}, writing {self.name.value!r}",
                path=self.path,
            )
        self.provenance = provenance
        self.rows = 0
        self._schema: pa.Schema | None = None
        self._writer: pq.ParquetWriter | None = None
        self._last: tuple[Any, ...] | None = None
        self._tmp: Path | None = None

    def _start(self, tmp: Path) -> None:
        self._tmp = tmp

    def write(self, table: pa.Table) -> None:
        """Append a chunk; it must share the columns of the first chunk and follow its keys."""
        if self._tmp is None:
            raise RuntimeError("TableWriter.write outside its `with` block")
        try:
            validate(self.name, table, previous_key=self._last)
        except TableValidationError as err:
            raise TableValidationError(
                err.reason,
                table=err.table,
                column=err.column,
                row=None if err.row is None else self.rows + err.row,
                path=self.path,
            ) from err
        if self._writer is None:
            self._open(table.schema)
        assert self._schema is not None
        assert self._writer is not None
        if table.schema.remove_metadata() != self._schema.remove_metadata():
            raise TableValidationError(
                f"chunk columns {table.column_names} differ from the first chunk's "
                f"{self._schema.names}",
                table=self.name.value,
                path=self.path,
            )
        if table.num_rows:
            self._writer.write_table(
                table.replace_schema_metadata(self._schema.metadata), row_group_size=_ROW_GROUP_ROWS
            )
            self._last = last_key(self.name, table)
            self.rows += table.num_rows

    def _open(self, schema: pa.Schema) -> None:
        assert self._tmp is not None
        self._schema = schema.with_metadata({PROVENANCE_KEY: self.provenance.to_json().encode()})
        # Dictionary encoding only where values repeat (satellite ids, fix types): on float
        # sensor columns it never pays and its hash tables cost ~10x the block in memory.
        dictionary = [
            f.name
            for f in schema
            if pa.types.is_string(f.type)
            or (pa.types.is_integer(f.type) and f.type.bit_width <= 16)
        ]
        self._writer = pq.ParquetWriter(
            self._tmp,
            self._schema,
            compression="zstd",
            write_page_checksum=True,
            write_statistics=True,
            use_dictionary=dictionary,
        )

    def _finish(self, ok: bool) -> None:
        try:
            if ok:
                if self._writer is None:
                    self._open(spec(self.name).arrow_schema())
                assert self._writer is not None
                self._writer.close()
            elif self._writer is not None:
                with contextlib.suppress(Exception):
                    self._writer.close()
        finally:
            self._tmp = None


def write_table(
    path: str | Path,
    name: TableName | ContextName | str,
    table: pa.Table,
    provenance: Provenance,
) -> None:
    """Validate ``table`` and write it atomically to ``path`` with ``provenance``."""
    with TableWriter(path, name, provenance) as writer:
        writer.write(table)


@dataclass(frozen=True)
class TableFile:
    """A canonical table read back, with its provenance."""

    table: pa.Table
    provenance: Provenance


def read_provenance(path: str | Path) -> Provenance:
    """Read only the provenance record of a navreplay Parquet file."""
    path = Path(path)
    schema = _read_schema(path)
    meta = schema.metadata or {}
    if PROVENANCE_KEY not in meta:
        raise ProvenanceError(
            "no navreplay provenance in the Parquet metadata",
            path=path,
            hint="the file was not written by navreplay; ingest the original log instead",
        )
    return Provenance.from_json(meta[PROVENANCE_KEY], path=path)


def _read_schema(path: Path) -> pa.Schema:
    if not path.is_file():
        raise IngestError(
            "no such table file", path=path, hint="run `navreplay ingest` (or `dvc repro`) first"
        )
    try:
        return pq.read_schema(path)
    except (pa.ArrowInvalid, OSError) as err:
        raise CorruptLogError(f"not a readable Parquet file: {err}", path=path) from err


def read_table(
    path: str | Path,
    name: TableName | ContextName | str,
    *,
    columns: list[str] | None = None,
) -> TableFile:
    """Read a canonical table, verifying page checksums, provenance and the schema.

    Raises:
        IngestError: the file does not exist.
        CorruptLogError: the file is not valid Parquet or a page checksum fails.
        ProvenanceError: provenance is missing, malformed, for another table or schema version.
        TableValidationError: the content breaks the canonical schema.
    """
    path = Path(path)
    tname = table_name(name).value
    prov = read_provenance(path)
    if prov.table != tname:
        raise ProvenanceError(f"file holds table {prov.table!r}, expected {tname!r}", path=path)
    if prov.schema_version != SCHEMA_VERSION:
        raise ProvenanceError(
            f"schema version {prov.schema_version}, this navreplay reads {SCHEMA_VERSION}",
            path=path,
            hint="re-run ingest with this version",
        )
    try:
        table = pq.read_table(path, columns=columns, page_checksum_verification=True)
    except (pa.ArrowInvalid, OSError) as err:
        raise CorruptLogError(f"cannot read Parquet data: {err}", path=path) from err
    table = table.replace_schema_metadata(None)
    if columns is None:
        try:
            validate(tname, table)
        except TableValidationError as err:
            raise TableValidationError(
                err.reason, table=err.table, column=err.column, row=err.row, path=path
            ) from err
    return TableFile(table, prov)
