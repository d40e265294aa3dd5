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
"""

from __future__ import annotations

import hashlib
import os
import sys
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
