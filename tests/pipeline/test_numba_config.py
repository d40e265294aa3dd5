"""pipeline._numba_cache: the cache directory keyed by the source, and plain numba errors."""

from __future__ import annotations

import gc
import json
import os
import shutil
import subprocess
import sys
import weakref
from pathlib import Path

import pytest

from navreplay.pipeline._numba_cache import compiled_sources, fewer_gc_passes, source_digest

REPO = Path(__file__).resolve().parents[2]

PROBE = """
import json, os
import navreplay.pipeline
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
    digest = source_digest(REPO)
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


def _tree(tmp_path: Path) -> Path:
    """A copy of the repository's ``pipeline`` and ``ingest`` sources."""
    for pkg in ("pipeline", "ingest"):
        shutil.copytree(REPO / pkg, tmp_path / pkg, ignore=shutil.ignore_patterns("__pycache__"))
    return tmp_path


def test_editing_a_report_keeps_the_kernels_and_editing_their_sources_does_not(
    tmp_path: Path,
) -> None:
    base = _tree(tmp_path)
    first = source_digest(base)
    assert source_digest(base) == first

    def edited(rel: str) -> str:
        path = base / rel
        original = path.read_bytes()
        path.write_bytes(original + b"\n# edited\n")
        try:
            return source_digest(base)
        finally:
            path.write_bytes(original)

    # no jitted code reaches these: the compiled kernels stay valid
    for rel in ("pipeline/report/html.py", "pipeline/stages/run.py", "pipeline/cli.py"):
        assert edited(rel) == first, rel
    # a kernel, a callee in another module, a module of constants a kernel imports
    for rel in (
        "pipeline/estimation/ins/kernels/ukf.py",
        "pipeline/estimation/ins/models/ins.py",
        "pipeline/nav/earth.py",
        "pipeline/estimation/ins/kernels/common.py",
    ):
        assert edited(rel) != first, rel
    assert source_digest(base) == first


def test_a_new_import_in_a_jitted_module_extends_the_digest(tmp_path: Path) -> None:
    base = tmp_path
    (base / "pipeline" / "sub").mkdir(parents=True)
    (base / "ingest").mkdir()
    for init in ("pipeline/__init__.py", "pipeline/sub/__init__.py", "ingest/__init__.py"):
        (base / init).write_text("")
    (base / "pipeline" / "consts.py").write_text("G = 9.8\n")
    (base / "pipeline" / "other.py").write_text("x = 1\n")
    kernel = base / "pipeline" / "sub" / "kernel.py"
    kernel.write_text("from navreplay.pipeline._jit import njit\n\n@njit\ndef f():\n    return 1\n")
    assert base / "pipeline" / "consts.py" not in compiled_sources(base)
    kernel.write_text(
        "from navreplay.pipeline._jit import njit\n"
        "from navreplay.pipeline import (\n    consts,  # g\n)\n"
        "@njit\ndef f():\n    return consts.G\n"
    )
    found = compiled_sources(base)
    assert base / "pipeline" / "consts.py" in found
    assert base / "pipeline" / "sub" / "__init__.py" in found
    assert base / "pipeline" / "other.py" not in found
    before = source_digest(base)
    (base / "pipeline" / "consts.py").write_text("G = 9.81\n")
    assert source_digest(base) != before


IMPORTED = """
import importlib, json, sys
for name in sys.argv[1:]:
    importlib.import_module(name)
ours = [m for n, m in sys.modules.items() if n.split(".")[0] == "navreplay"]
print(json.dumps(sorted(m.__file__ for m in ours if getattr(m, "__file__", None))))
"""


def test_the_digest_covers_every_module_python_loads_with_the_jitted_ones() -> None:
    """The static scan against Python's own imports: loading the jitted modules imports
    nothing from the project that the digest leaves out."""
    seeds = [p for p in compiled_sources(REPO) if b"njit" in p.read_bytes()]
    modules = [".".join(p.relative_to(REPO).with_suffix("").parts) for p in seeds]
    modules = ["navreplay." + m.removesuffix(".__init__") for m in modules]
    assert "navreplay.pipeline.estimation.ins.kernels.ukf" in modules
    env = dict(os.environ)
    out = subprocess.run(
        [sys.executable, "-c", IMPORTED, *modules],
        env=env, capture_output=True, text=True, check=True, cwd=REPO,
    )  # fmt: skip
    loaded = {Path(f).resolve() for f in json.loads(out.stdout.strip().splitlines()[-1])}
    missing = loaded - set(compiled_sources(REPO))
    assert not missing, f"imported with the jitted modules but not in the digest: {missing}"


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
    from navreplay.pipeline.cli import EXIT_ERROR, main

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

    from navreplay import pipeline

    found = []
    for info in pkgutil.walk_packages(pipeline.__path__, "navreplay.pipeline."):
        module = importlib.import_module(info.name)
        for name, value in vars(module).items():
            if isinstance(value, Dispatcher) and value.py_func.__module__ == info.name:
                found.append((info.name, name, value.targetoptions.get("no_cfunc_wrapper")))
    assert len(found) > 100
    missing = [f"{m}.{n}" for m, n, flag in found if flag is not True]
    assert not missing, f"compiled without navreplay.pipeline._jit.njit: {missing}"
