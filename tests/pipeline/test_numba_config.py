"""pipeline._numba_cache: the cache directory keyed by the source, and plain numba errors."""

from __future__ import annotations

import gc
import json
import os
import subprocess
import sys
import weakref
from pathlib import Path

import pytest

from pipeline._numba_cache import fewer_gc_passes, source_digest

REPO = Path(__file__).resolve().parents[2]

PROBE = """
import json, os
import pipeline
import numba
from numba.core import errors
print(json.dumps({
    "cache_dir": numba.core.config.CACHE_DIR,
    "env_cache_dir": os.environ.get("NUMBA_CACHE_DIR"),
    "scheme": type(errors.termcolor()).__name__,
}))
"""


def _probe(env_extra: dict[str, str], drop: tuple[str, ...] = ()) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in drop}
    env.update(env_extra)
    env["PYTHONPATH"] = str(REPO)
    out = subprocess.run(
        [sys.executable, "-c", PROBE], env=env, capture_output=True, text=True, check=True
    )
    result: dict[str, str] = json.loads(out.stdout.strip().splitlines()[-1])
    return result


def test_cache_dir_is_keyed_by_the_package_source(tmp_path: Path) -> None:
    got = _probe(
        {"XDG_CACHE_HOME": str(tmp_path)},
        drop=("NUMBA_CACHE_DIR", "NUMBA_DISABLE_ERROR_MESSAGE_HIGHLIGHTING"),
    )
    digest = source_digest(REPO / "pipeline")
    expected = str(tmp_path / "navreplay" / f"numba-{digest}")
    assert got["cache_dir"] == expected
    assert got["env_cache_dir"] == expected
    # typing builds an error object per rejected overload: no colour scheme (no colorama
    # stream wrapping) for each of them
    assert got["scheme"] == "NOPColorScheme"


def test_explicit_cache_dir_and_highlighting_are_respected(tmp_path: Path) -> None:
    got = _probe(
        {"NUMBA_CACHE_DIR": str(tmp_path / "mine"), "NUMBA_DISABLE_ERROR_MESSAGE_HIGHLIGHTING": ""}
    )
    assert got["cache_dir"] == str(tmp_path / "mine")
    assert got["scheme"] != "NOPColorScheme"  # the user's (empty) setting kept highlighting on


def test_source_digest_changes_with_any_file(tmp_path: Path) -> None:
    pkg = tmp_path / "pkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "a.py").write_text("x = 1\n")
    (pkg / "sub" / "b.py").write_text("y = 2\n")
    first = source_digest(pkg)
    assert source_digest(pkg) == first
    (pkg / "sub" / "b.py").write_text("y = 3\n")
    assert source_digest(pkg) != first
    (pkg / "sub" / "b.py").write_text("y = 2\n")
    assert source_digest(pkg) == first
    (pkg / "sub" / "b.py").rename(pkg / "b.py")  # same bytes, another path
    assert source_digest(pkg) != first


class _Node:
    def __init__(self) -> None:
        self.other: _Node | None = None


def test_fewer_gc_passes_restores_the_collector_and_frees_the_garbage() -> None:
    before = gc.get_threshold()
    assert gc.get_freeze_count() == 0
    with fewer_gc_passes(young=123_456):
        assert gc.get_threshold()[0] == max(before[0], 123_456)
        assert gc.get_freeze_count() > 0  # what was alive at entry is not scanned
        a, b = _Node(), _Node()
        a.other, b.other = b, a  # a reference cycle: only the cyclic collector frees it
        dead = weakref.ref(a)
        del a, b
    assert gc.get_threshold() == before
    assert gc.get_freeze_count() == 0
    gc.collect()
    assert dead() is None


def test_fewer_gc_passes_restores_on_error_and_leaves_a_disabled_collector_alone() -> None:
    before = gc.get_threshold()
    with pytest.raises(RuntimeError), fewer_gc_passes():
        raise RuntimeError("compile failed")
    assert gc.get_threshold() == before
    assert gc.get_freeze_count() == 0
    gc.disable()
    try:
        with fewer_gc_passes():
            assert gc.get_threshold() == before
            assert gc.get_freeze_count() == 0
    finally:
        gc.enable()


def test_a_failing_command_leaves_the_collector_as_it_was(tmp_path: Path) -> None:
    from pipeline.cli import EXIT_ERROR, main

    before = gc.get_threshold()
    code = main(["run", str(tmp_path / "missing"), "--filter", "lc_ekf", "--out", str(tmp_path)])
    assert code == EXIT_ERROR
    assert gc.get_threshold() == before
    assert gc.get_freeze_count() == 0


def test_every_compiled_pipeline_function_skips_the_c_callback_wrapper() -> None:
    """None is a C callback or a first-class function value, so none needs numba's cfunc
    wrapper (``pipeline._jit``); building it costs every compiled function time in a cold
    compile."""
    import importlib
    import pkgutil

    from numba.core.dispatcher import Dispatcher

    import pipeline

    found = []
    for info in pkgutil.walk_packages(pipeline.__path__, "pipeline."):
        module = importlib.import_module(info.name)
        for name, value in vars(module).items():
            if isinstance(value, Dispatcher) and value.py_func.__module__ == info.name:
                found.append((info.name, name, value.targetoptions.get("no_cfunc_wrapper")))
    assert len(found) > 100
    missing = [f"{m}.{n}" for m, n, flag in found if flag is not True]
    assert not missing, f"compiled without pipeline._jit.njit: {missing}"
