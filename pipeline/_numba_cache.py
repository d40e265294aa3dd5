"""Numba's on-disk cache, keyed by the source of the whole ``pipeline`` package.

Numba invalidates a cached function only when *its own* file changes; a kernel that calls a
function from another module keeps the callee's old machine code after the callee is edited
(numba documents this limitation). For a replay tool that would mean silently running stale
physics. Before any numba function is defined, ``configure()`` points ``NUMBA_CACHE_DIR`` at
``<user cache>/navreplay/numba-<sha256 of every pipeline/*.py>``, so any source change starts
a fresh cache while unchanged code keeps loading its compiled functions. An explicit
``NUMBA_CACHE_DIR`` in the environment is respected.

``configure()`` also sets ``NUMBA_DISABLE_ERROR_MESSAGE_HIGHLIGHTING`` (unless set): with
colorama installed (dvc brings it), numba otherwise wraps the terminal streams anew for every
error object it builds, and typing builds tens of thousands of them (one per overload it tries
and rejects at each call site: about a second of a cold kernel compile). Numba's own error
messages then come without colour.

``fewer_gc_passes()`` is the collector's setting for a compile, used around every ``navreplay``
command (the stage's imports compile the kernels' explicitly typed helpers) and around a
kernel compile; see there.
"""

from __future__ import annotations

import gc
import hashlib
import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path


def source_digest(package: Path) -> str:
    """sha256 (16 hex) over the relative paths and bytes of the package's ``.py`` files."""
    h = hashlib.sha256()
    for path in sorted(package.rglob("*.py")):
        h.update(str(path.relative_to(package)).encode())
        h.update(path.read_bytes())
    return h.hexdigest()[:16]


def configure() -> None:
    """Set ``NUMBA_CACHE_DIR`` for this source tree unless the user set it (and plain error
    messages, see the module docstring).

    Numba reads the variable when it is imported; if it already was (by other code imported
    before ``pipeline``), its live configuration is updated too. Either way this runs before
    any ``pipeline`` module defines a cached function.
    """
    os.environ.setdefault("NUMBA_DISABLE_ERROR_MESSAGE_HIGHLIGHTING", "1")
    if "NUMBA_CACHE_DIR" in os.environ:
        return
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    digest = source_digest(Path(__file__).resolve().parent)
    path = str(Path(base) / "navreplay" / f"numba-{digest}")
    os.environ["NUMBA_CACHE_DIR"] = path
    numba = sys.modules.get("numba")
    if numba is not None:
        numba.core.config.CACHE_DIR = path


@contextmanager
def fewer_gc_passes(young: int = 50_000) -> Iterator[None]:
    """Let CPython's cyclic collector run less often inside the block (a numba compile).

    A cold kernel compile allocates millions of small, short-lived IR objects. With the
    default threshold (a young-generation pass every 700 allocations) the collector runs some
    two thousand times, and each of its full passes re-scans every object already alive: the
    imported modules and the loaded tables, some 400,000. That is about a tenth of the
    compile. Inside the block the objects alive at entry are frozen (never scanned) and the
    young generation is collected every ``young`` allocations; on exit both are restored, so
    the garbage of the block is collected as usual afterwards. Nothing changes when the
    collector is disabled, or when objects are already frozen (by an embedding application).
    """
    old = gc.get_threshold()
    if old[0] == 0 or not gc.isenabled() or gc.get_freeze_count() > 0:
        yield
        return
    gc.freeze()
    gc.set_threshold(max(old[0], young), old[1], old[2])
    try:
        yield
    finally:
        gc.set_threshold(*old)
        gc.unfreeze()
