"""``navreplay warm``: the kernels it compiles are the ones a later run loads from the cache."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from navreplay.pipeline._numba_cache import installed_digest
from navreplay.pipeline.estimation.families import filter_names
from navreplay.pipeline.warm import groups

REPO = Path(__file__).resolve().parents[3]

# A fresh process runs vehicle_kinematic on a short drive with the given cache and prints numba's
# cache statistics (Dispatcher.stats) of the loop it ran: hits are loads, misses are compiles.
# (The vehicle-model kernel is the cheapest group to compile cold: the test's cost is that
# compile, and the mechanism is the same for every group.)
PROBE = """
import json, sys, tempfile
from dataclasses import replace
from pathlib import Path
from navreplay.pipeline.params import load_params
from navreplay.pipeline.warm import _drive
from navreplay.pipeline.estimation.families import run_tables
from navreplay.pipeline.estimation.vehicle.kernel import run_vehicle
params = load_params(Path(sys.argv[1]))
with tempfile.TemporaryDirectory() as tmp:
    tables = _drive("vehicle", params, Path(tmp) / "t")
    run_tables(tables, "vehicle_kinematic", params.filters.section("vehicle_kinematic"), "numba")
st = run_vehicle.stats
print(json.dumps({"hits": sum(st.cache_hits.values()), "misses": sum(st.cache_misses.values())}))
"""


def _stats(cache: Path) -> dict[str, int]:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    out = subprocess.run(
        [sys.executable, "-c", PROBE, str(REPO / "params.yaml")],
        env=env, capture_output=True, text=True, check=True, cwd=REPO,
    )  # fmt: skip
    stats: dict[str, int] = json.loads(out.stdout.strip().splitlines()[-1])
    return stats


def test_groups_put_filters_that_share_a_kernel_together() -> None:
    every = groups()
    assert ("lc_ekf", "tc_ekf", "lc_ekf_nhc", "tc_ekf_nhc") in every  # one kernel
    assert ("tc_ukf", "tc_ukf_nhc") in every
    assert ("fwekf", "iae_ekf") in every  # one adaptive kernel
    assert sorted(n for g in every for n in g) == sorted(filter_names())  # each once
    assert groups(["tc_ukf", "lc_ekf"]) == [("lc_ekf",), ("tc_ukf",)]
    with pytest.raises(KeyError, match="unknown filter 'nope'"):
        groups(["nope"])


@pytest.mark.slow
def test_after_warm_the_first_run_loads_the_kernel_and_compiles_nothing(tmp_path: Path) -> None:
    # No cold control run (it costs a whole compile): a hit can only be a load from the cache
    # warm wrote, and no miss means nothing compiled.
    cache = tmp_path / "cache"
    stamp = tmp_path / "warm.json"
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    done = subprocess.run(
        [sys.executable, "-m", "navreplay.pipeline.cli", "warm", "--filter", "vehicle_imm",
         "--filter", "vehicle_kinematic", "--stamp", str(stamp)],
        env=env, capture_output=True, text=True, check=False, cwd=REPO,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "[1/1] vehicle_kinematic, vehicle_imm: compiled" in done.stdout
    assert json.loads(stamp.read_text()) == {
        "numba_source_digest": installed_digest(),
        "filters": [["vehicle_kinematic", "vehicle_imm"]],
    }
    assert _stats(cache) == {"hits": 1, "misses": 0}


def test_an_unknown_filter_is_a_parameter_error(tmp_path: Path) -> None:
    from navreplay.pipeline.cli import EXIT_ERROR, main

    assert main(["warm", "--filter", "nope", "--params", str(REPO / "params.yaml")]) == EXIT_ERROR
