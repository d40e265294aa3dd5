"""The installed names: a wheel of the repository puts only ``navreplay`` into site-packages
(the folders ``pipeline/`` and ``ingest/`` install as ``navreplay.pipeline`` and
``navreplay.ingest``), and nothing in the repository imports the folders by their own names."""

from __future__ import annotations

import ast
import configparser
import json
import os
import shutil
import subprocess
import sys
import sysconfig
import tomllib
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
FOLDERS = ("pipeline", "ingest")
# what setuptools reads to build the wheel
BUILD_INPUTS = ("pyproject.toml", "setup.py", "README.md", *FOLDERS)


def _sources(folder: str) -> list[Path]:
    return sorted(p for p in (REPO / folder).rglob("*.py") if "__pycache__" not in p.parts)


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> zipfile.ZipFile:
    """A wheel built, without network, from a copy of the build inputs (setuptools writes
    build/ and *.egg-info beside its input, and a stale build/ would leak into the wheel)."""
    src = tmp_path_factory.mktemp("src")
    for name in BUILD_INPUTS:
        if (REPO / name).is_dir():
            ignore = shutil.ignore_patterns("__pycache__", "*.pyc", "*.nbi", "*.nbc")
            shutil.copytree(REPO / name, src / name, ignore=ignore)
        else:
            shutil.copy2(REPO / name, src / name)
    out = tmp_path_factory.mktemp("wheel")
    done = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "--no-index",
         "--quiet", "--wheel-dir", str(out), str(src)],
        capture_output=True, text=True, check=False,
        env=dict(os.environ, PIP_DISABLE_PIP_VERSION_CHECK="1"),
    )  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    (path,) = out.glob("navreplay-*.whl")
    return zipfile.ZipFile(path)


def test_the_wheel_installs_only_navreplay_at_the_top_level(wheel: zipfile.ZipFile) -> None:
    version = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["version"]
    names = set(wheel.namelist())
    assert {n.split("/")[0] for n in names} == {"navreplay", f"navreplay-{version}.dist-info"}
    assert "navreplay/pipeline/cli.py" in names
    assert "navreplay/ingest/schema.py" in names
    assert "navreplay/__init__.py" not in names  # a namespace package
    for folder in FOLDERS:
        assert f"navreplay/{folder}/py.typed" in names
        # every module of the folder, under its installed name (a subpackage missing from the
        # package list, or a folder without __init__.py, would leave some out)
        missing = {
            f"navreplay/{folder}/{p.relative_to(REPO / folder).as_posix()}"
            for p in _sources(folder)
        } - names
        assert not missing, f"not in the wheel: {sorted(missing)}"
    dist_info = f"navreplay-{version}.dist-info"
    assert wheel.read(f"{dist_info}/top_level.txt").decode().split() == ["navreplay"]
    entry_points = configparser.ConfigParser()
    entry_points.read_string(wheel.read(f"{dist_info}/entry_points.txt").decode())
    assert dict(entry_points["console_scripts"]) == {"navreplay": "navreplay.pipeline.cli:main"}


def test_the_installed_package_has_the_navreplay_names_only(tmp_path: Path) -> None:
    """From outside the repository (no checkout on sys.path): the installed ``navreplay``
    imports, and the folders' own names do not."""
    code = (
        "import importlib.util, json\n"
        "import navreplay.pipeline.cli, navreplay.ingest.schema\n"
        "print(json.dumps([importlib.util.find_spec(n) is None for n in ('pipeline', 'ingest')]))"
    )
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True,
        check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout.strip().splitlines()[-1]) == [True, True]


def test_nothing_imports_the_folders_by_their_own_names() -> None:
    """Under pytest the repository root is on sys.path, so ``import pipeline`` would still
    work here and load a second copy of every module it reaches."""
    found = []
    for folder in (*FOLDERS, "tests", "benchmarks"):
        for path in _sources(folder):
            for node in ast.walk(ast.parse(path.read_bytes(), str(path))):
                if isinstance(node, ast.Import):
                    names = [a.name for a in node.names]
                elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                    names = [node.module]
                else:
                    continue
                found += [
                    f"{path.relative_to(REPO)}:{node.lineno}: {name}"
                    for name in names
                    if name.split(".")[0] in FOLDERS
                ]
    assert not found, "import navreplay.pipeline / navreplay.ingest instead:\n" + "\n".join(found)


def test_the_built_in_params_are_in_the_wheel(wheel: zipfile.ZipFile) -> None:
    assert wheel.read("navreplay/pipeline/params.yaml") == (REPO / "params.yaml").read_bytes()


@pytest.mark.slow
def test_analyze_runs_from_any_directory_with_the_wheel_installed(
    wheel: zipfile.ZipFile, tmp_path: Path
) -> None:
    """A new user's first steps: the wheel installed into a fresh environment (its
    dependencies taken from this one, without the checkout), a log in an empty directory,
    `navreplay analyze` on it with no parameter file anywhere."""
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    python = venv / "bin" / "python"
    purelib = subprocess.run(
        [str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
        capture_output=True, text=True, check=True,
    ).stdout.strip()  # fmt: skip
    # the dependencies: this environment's site-packages as a plain path (its .pth files,
    # among them the editable install of the checkout, are not processed)
    deps = sysconfig.get_paths()["purelib"]
    Path(purelib, "navreplay_test_deps.pth").write_text(deps + "\n")
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "NUMBA_CACHE_DIR")}
    env["PIP_DISABLE_PIP_VERSION_CHECK"] = "1"
    # The installed copy runs its kernels as Python (36 s) rather than compiling them from
    # nothing (another path is another cache entry: 2 minutes of the suite's two cores): what
    # this tests is the install (resources, parameters, entry point, any working directory);
    # the kernels it would compile are the checkout's, which the rest of the suite runs
    # compiled and compares against the interpreted filterpy references.
    installed_env = dict(env, NUMBA_DISABLE_JIT="1")
    done = subprocess.run(
        [sys.executable, "-m", "pip", "--python", str(python), "install", "--no-deps",
         "--no-index", "--quiet", str(wheel.filename)],
        capture_output=True, text=True, check=False, env=env,
    )  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    navreplay = venv / "bin" / "navreplay"
    work = tmp_path / "work"
    work.mkdir()

    def cli(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [str(navreplay), *args], cwd=work, env=installed_env, capture_output=True, text=True,
            timeout=600, check=False,
        )  # fmt: skip

    where = cli("params", "--section", "run.filters")
    assert where.returncode == 0, where.stderr
    assert f"built-in defaults ({Path(purelib) / 'navreplay' / 'pipeline'}" in where.stdout
    # the log is made by the checkout's navreplay, whose kernels are compiled already
    made = subprocess.run(
        [sys.executable, "-m", "navreplay.pipeline.cli", "-q", "synth", "fwekf_reference",
         "--out", str(work / "raw")],
        cwd=REPO, capture_output=True, text=True, timeout=600, check=False,
    )  # fmt: skip
    assert made.returncode == 0, made.stderr
    done = cli("analyze", "raw/fwekf_reference.tlog", "--filters", "lc_ekf",
               "--scenarios", "nominal,outage_60s", "--out", "analysis")  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    assert "Traceback" not in done.stderr
    runs = {(r["filter"], r["scenario"]): r for r in
            json.loads((work / "analysis/report/tables/runs.json").read_text())}  # fmt: skip
    assert runs[("lc_ekf", "nominal")]["status"] == "ok"
    # the 80 s drive is too short for five 60 s windows after 120 s: one shorter one is placed
    assert runs[("lc_ekf", "outage_60s")]["status"] == "ok"
    assert "note: outage_60s: 5 window(s) of 60 s need 120 s of settling" in done.stdout
    windows = json.loads((work / "analysis/runs/lc_ekf/outage_60s/metrics.json").read_text())[
        "windows"
    ]
    assert len(windows) == 1
