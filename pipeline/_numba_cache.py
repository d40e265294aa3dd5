"""Numba's on-disk cache, keyed by the source numba compiles.

Numba invalidates a cached function only when *its own* file changes; a kernel that calls a
function from another module keeps the callee's old machine code after the callee is edited
(numba documents this limitation), and a constant imported from another module is frozen into
the machine code the same way. For a replay tool that would mean silently running stale
physics. Before any numba function is defined, ``configure()`` points ``NUMBA_CACHE_DIR`` at
``<user cache>/navreplay/numba-<digest>``, where the digest covers exactly the sources numba
can see (``compiled_sources``): every module of ``pipeline`` and ``ingest`` that defines a
jitted function, and every project module those import, transitively. Editing any of them
starts a fresh cache; editing anything else (a report, a stage, the CLI) keeps the compiled
kernels. An explicit ``NUMBA_CACHE_DIR`` in the environment is respected.

``configure()`` also sets ``NUMBA_DISABLE_ERROR_MESSAGE_HIGHLIGHTING`` (unless set): with
colorama installed (dvc brings it), numba otherwise wraps the terminal streams anew for every
error object it builds, and typing builds tens of thousands of them (one per overload it tries
and rejects at each call site: about a second of a cold kernel compile). Numba's own error
messages then come without colour.

``fewer_gc_passes()`` is the collector's setting for a compile, used around every ``navreplay``
command and around a kernel compile; see there.
"""

from __future__ import annotations

import gc
import hashlib
import os
import re
import sys
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

#: the package the project installs (a namespace package)
ROOT = "navreplay"
#: its packages, siblings in one directory: the repository's folders, and the installed
#: ``navreplay/`` (``navreplay.pipeline`` is the folder ``pipeline``)
PACKAGES = ("pipeline", "ingest")


def _module_path(base: Path, module: str) -> Path | None:
    """The file of ``module`` (dotted) under ``base``, or None if it is not a project module."""
    path = base.joinpath(*module.split("."))
    if path.with_suffix(".py").is_file():
        return path.with_suffix(".py")
    if (path / "__init__.py").is_file():
        return path / "__init__.py"
    return None


_FROM = re.compile(rb"^[ \t]*from[ \t]+([\w.]+)[ \t]+import[ \t]+(\([^)]*\)|[^\n]*)", re.M)
_IMPORT = re.compile(rb"^[ \t]*import[ \t]+([^\n]*)", re.M)


def _imported_modules(source: bytes, packages: Sequence[str]) -> Iterator[str]:
    """Every project module an ``import`` statement anywhere in ``source`` names, relative
    to ``ROOT`` (``navreplay.pipeline.x`` is ``pipeline.x``, the file ``pipeline/x.py``);
    ``from M import n`` also yields ``M.n``, a module when ``n`` is a submodule.

    A textual scan (a tenth of the time ``ast`` takes, and this runs at every start): an import
    in a string or comment only adds a file, which costs a needless recompile, never a stale
    one.
    """
    found: list[tuple[str, list[str]]] = []
    for m in _FROM.finditer(source):
        names = m.group(2).split(b"#")[0].strip(b"()").replace(b"\n", b",").split(b",")
        found.append((m.group(1).decode(), [n.split()[0].decode() for n in names if n.split()]))
    for m in _IMPORT.finditer(source):
        for item in m.group(1).split(b"#")[0].split(b","):
            if item.split():
                found.append((item.split()[0].decode(), []))
    prefix = f"{ROOT}."
    for module, names in found:
        for name in (module, *(f"{module}.{n}" for n in names)):
            if name.startswith(prefix) and name[len(prefix) :].split(".")[0] in packages:
                yield name[len(prefix) :]


def compiled_sources(base: Path, packages: Sequence[str] = PACKAGES) -> list[Path]:
    """The project's ``.py`` files under ``base`` whose content can reach compiled code.

    The seeds are the files that mention ``njit`` (they define jitted functions); then every
    project module they import, transitively, with the parent packages' ``__init__.py`` that
    Python runs on the way. Sorted.
    """
    files = [p for pkg in packages for p in sorted((base / pkg).rglob("*.py"))]
    todo = [p for p in files if b"njit" in p.read_bytes()]
    seen: set[Path] = set()
    while todo:
        path = todo.pop()
        if path in seen:
            continue
        seen.add(path)
        parts = path.relative_to(base).parts
        for k in range(1, len(parts)):  # the packages Python imports on the way
            init = base.joinpath(*parts[:k], "__init__.py")
            if init.is_file() and init not in seen:
                todo.append(init)
        for module in _imported_modules(path.read_bytes(), packages):
            found = _module_path(base, module)
            if found is not None and found not in seen:
                todo.append(found)
    return sorted(seen)


def source_digest(base: Path, packages: Sequence[str] = PACKAGES) -> str:
    """sha256 (16 hex) over the relative paths and bytes of ``compiled_sources``."""
    h = hashlib.sha256()
    for path in compiled_sources(base, packages):
        h.update(str(path.relative_to(base)).encode())
        h.update(path.read_bytes())
    return h.hexdigest()[:16]


def installed_digest() -> str:
    """``source_digest`` of the installed ``pipeline`` and ``ingest``: the cache's key."""
    return source_digest(Path(__file__).resolve().parent.parent)


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
    digest = installed_digest()
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
