"""Atomic writes: a file or directory appears at its final path complete, or not at all.

Everything is written to a hidden temporary sibling (same directory, so the final rename is
atomic on POSIX), flushed and fsynced, then renamed over the target. On an exception the
temporary is removed and any earlier file at the target is untouched. A process killed midway
leaves only a hidden ``.<name>.<pid>.<token>.tmp`` sibling, which the next write to the same
target removes once its process is gone.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import re
import secrets
import shutil
from abc import ABC, abstractmethod
from collections.abc import Iterator
from pathlib import Path
from types import TracebackType
from typing import Any, Self

_TMP_RE = re.compile(r"^\.(?P<name>.+)\.(?P<pid>\d+)\.[0-9a-f]{8}\.tmp$")


def _temp_sibling(target: Path) -> Path:
    return target.with_name(f".{target.name}.{os.getpid()}.{secrets.token_hex(4)}.tmp")


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def remove_stale_temps(target: Path) -> list[Path]:
    """Remove temporaries left for ``target`` by processes that no longer run; returns them."""
    removed: list[Path] = []
    parent = target.parent
    if not parent.is_dir():
        return removed
    for entry in parent.iterdir():
        m = _TMP_RE.match(entry.name)
        if not m or m["name"] != target.name or _pid_alive(int(m["pid"])):
            continue
        if entry.is_dir() and not entry.is_symlink():
            shutil.rmtree(entry, ignore_errors=True)
        else:
            entry.unlink(missing_ok=True)
        removed.append(entry)
    return removed


def _fsync_dir(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


@contextlib.contextmanager
def atomic_path(target: str | Path) -> Iterator[Path]:
    """Yield a temporary path to write; on success it is fsynced and renamed to ``target``.

    The caller writes a complete file at the yielded path. If the block raises, the temporary is
    removed and ``target`` is left as it was.
    """
    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temps(target)
    tmp = _temp_sibling(target)
    try:
        yield tmp
        with tmp.open("rb") as fh:
            os.fsync(fh.fileno())
        tmp.replace(target)
        _fsync_dir(target.parent)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


class AtomicWriter(ABC):
    """A file writer used as a context manager: its file appears at ``path`` only when the
    ``with`` block succeeds (``atomic_path``). ``_start`` opens the temporary file, ``_finish``
    closes it (``ok``: the block succeeded); an error in ``_finish`` also discards the file."""

    path: Path
    _ctx: Any = None

    @abstractmethod
    def _start(self, tmp: Path) -> None: ...

    @abstractmethod
    def _finish(self, ok: bool) -> None: ...

    def __enter__(self) -> Self:
        self._ctx = atomic_path(self.path)
        self._start(self._ctx.__enter__())
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        try:
            self._finish(exc_type is None)
        except BaseException as close_err:
            self._ctx.__exit__(type(close_err), close_err, close_err.__traceback__)
            raise
        self._ctx.__exit__(exc_type, exc, tb)


def atomic_write_bytes(target: str | Path, data: bytes) -> None:
    """Write ``data`` to ``target`` atomically."""
    with atomic_path(target) as tmp:
        tmp.write_bytes(data)


def atomic_write_text(target: str | Path, text: str) -> None:
    """Write UTF-8 ``text`` to ``target`` atomically."""
    atomic_write_bytes(target, text.encode("utf-8"))


def json_ready(obj: Any) -> Any:
    """Turn non-finite floats into None (JSON has no NaN) and tuples into lists, recursively."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {str(k): json_ready(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [json_ready(v) for v in obj]
    if hasattr(obj, "item") and callable(obj.item):  # numpy scalars
        return json_ready(obj.item())
    return obj


def dumps_json(obj: Any) -> str:
    """Deterministic JSON: sorted keys, two-space indent, NaN/inf as null, trailing newline."""
    return json.dumps(json_ready(obj), indent=2, sort_keys=True, allow_nan=False) + "\n"


def atomic_write_json(target: str | Path, obj: Any) -> None:
    """Write ``obj`` as deterministic JSON (see ``dumps_json``) atomically."""
    atomic_write_text(target, dumps_json(obj))


#: kinds of file navreplay writes into an output folder (tables, runs, reports); a folder
#: holding anything else is not replaced (``atomic_directory``)
OUTPUT_SUFFIXES = frozenset({".parquet", ".json", ".html", ".csv", ".svg", ".png", ".tum"})


def _foreign_files(target: Path, owned: frozenset[str]) -> list[Path]:
    """Files under the existing folder ``target`` that navreplay would not have written
    (links count as foreign: replacing the folder would lose them)."""
    found = []
    for path in sorted(target.rglob("*")):
        if path.is_symlink() or (not path.is_dir() and path.suffix.lower() not in owned):
            found.append(path)
    return found


def check_output_dir(target: str | Path, extra_suffixes: tuple[str, ...] = ()) -> None:
    """Refuse an output folder whose replacement would delete something navreplay did not write.

    ``target`` may be absent, an empty folder, or a previous navreplay output: a folder whose
    files are all of the kinds navreplay writes (``OUTPUT_SUFFIXES`` plus ``extra_suffixes``).

    Raises:
        OutputPathError: ``target`` is a file (or a link, or something else that is not a
            folder), or a folder holding files navreplay did not write; nothing is touched.
    """
    from navreplay.ingest.errors import OutputPathError

    target = Path(target)
    for above in target.parents:
        if above.exists() and not above.is_dir():
            raise OutputPathError(
                f"the output folder would be inside {above}, which is a file, not a folder",
                path=target,
                hint="give --out a path whose parent folders are folders; nothing was written",
            )
    if target.is_symlink() or (target.exists() and not target.is_dir()):
        kind = "a symbolic link" if target.is_symlink() else "a file, not a folder"
        raise OutputPathError(
            f"the output path is {kind}; navreplay writes a folder there and would replace it",
            path=target,
            hint="give --out a new folder (or a previous navreplay output folder); nothing "
            "was written",
        )
    if not target.is_dir():
        return
    owned = OUTPUT_SUFFIXES | {s.lower() for s in extra_suffixes}
    foreign = _foreign_files(target, frozenset(owned))
    if foreign:
        shown = ", ".join(str(p.relative_to(target)) for p in foreign[:3])
        more = f" and {len(foreign) - 3} more" if len(foreign) > 3 else ""
        raise OutputPathError(
            f"the output folder is not empty and holds files navreplay did not write "
            f"({shown}{more}); it would be replaced as a whole",
            path=target,
            hint="give --out a new or empty folder (e.g. a subfolder), or move those files "
            "away; nothing was written",
        )


@contextlib.contextmanager
def atomic_directory(target: str | Path, *, extra_suffixes: tuple[str, ...] = ()) -> Iterator[Path]:
    """Yield a temporary directory to fill; on success it replaces ``target`` as a whole.

    ``target`` must be absent, empty or a previous navreplay output (``check_output_dir``,
    checked before anything is created; ``extra_suffixes``: further kinds of file the caller
    itself writes there). An existing ``target`` directory is moved aside and deleted only
    after the new one is in place, so a failure at any point leaves either the old or the new
    directory, never a mix. Folders created for ``target`` are removed again on failure.

    Raises:
        OutputPathError: see ``check_output_dir``.
    """
    target = Path(target)
    check_output_dir(target, extra_suffixes)
    created = [p for p in (target.parent, *target.parent.parents) if not p.exists()]
    target.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temps(target)
    tmp = _temp_sibling(target)
    tmp.mkdir()
    try:
        yield tmp
        for path in sorted(tmp.rglob("*"), reverse=True):
            if path.is_file():
                with path.open("rb") as fh:
                    os.fsync(fh.fileno())
        check_output_dir(target, extra_suffixes)  # the folder may have changed meanwhile
        old: Path | None = None
        if target.exists():
            old = _temp_sibling(target)
            target.replace(old)
        tmp.replace(target)
        _fsync_dir(target.parent)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        for folder in created:  # innermost first
            with contextlib.suppress(OSError):
                folder.rmdir()
        raise
