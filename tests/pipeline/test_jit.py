"""pipeline._jit: an explicit signature is pinned, compiled at first use and never another."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numba as nb
import numpy as np
import pytest

from pipeline._jit import njit, pinned_signature

REPO = Path(__file__).resolve().parents[2]
_F2 = nb.float64[:, :]


def _make_pinned() -> tuple[object, object]:
    @njit(nb.float64(_F2, nb.int64))
    def row_sum(a: np.ndarray, i: int) -> float:
        return float(a[i].sum())

    @njit()
    def caller(a: np.ndarray) -> float:
        return row_sum(a, 1) + row_sum(a[:, :2], 0)  # a literal index, C and A layouts

    return row_sum, caller


def test_a_pinned_function_compiles_nothing_until_used_then_only_its_signature() -> None:
    row_sum, caller = _make_pinned()
    assert row_sum.signatures == []  # type: ignore[attr-defined]
    a = np.arange(6.0).reshape(2, 3)
    assert caller(a) == 12.0 + 1.0  # type: ignore[operator]
    pinned = (nb.float64[:, :], nb.int64)
    assert row_sum.signatures == [pinned]  # type: ignore[attr-defined]
    assert pinned_signature(row_sum) == pinned
    assert pinned_signature(caller) is None


def test_python_calls_convert_to_the_pinned_signature_or_fail_like_numba() -> None:
    row_sum, _ = _make_pinned()
    a = np.arange(6.0).reshape(2, 3)
    assert row_sum(a, 0) == 3.0  # type: ignore[operator]  # first use from Python
    assert row_sum(np.asfortranarray(a), 1) == 12.0  # type: ignore[operator]  # converted
    with pytest.raises(TypeError, match="No matching definition"):
        row_sum(np.arange(3.0), 0)  # type: ignore[operator]
    assert len(row_sum.signatures) == 1  # type: ignore[attr-defined]


def test_compile_accepts_only_the_pinned_signature() -> None:
    row_sum, _ = _make_pinned()
    with pytest.raises(TypeError, match=r"row_sum is pinned to .*not \(float64,\)"):
        row_sum.compile((nb.float64,))  # type: ignore[attr-defined]
    assert row_sum.signatures == []  # type: ignore[attr-defined]  # refused before compiling
    entry = row_sum.compile((_F2, nb.int64))  # type: ignore[attr-defined]
    assert entry is row_sum.overloads[(_F2, nb.int64)].entry_point  # type: ignore[attr-defined]


PROBE = """
import json
from pipeline.estimation.kernels import common
names = ("cholesky", "cho_solve", "_reset_block", "record_event")
print(json.dumps({n: len(getattr(common, n).signatures) for n in names}))
"""


def test_the_kernels_pinned_helpers_do_not_compile_at_import(tmp_path: Path) -> None:
    env = dict(os.environ, PYTHONPATH=str(REPO), NUMBA_CACHE_DIR=str(tmp_path))
    out = subprocess.run(
        [sys.executable, "-c", PROBE], env=env, capture_output=True, text=True, check=True
    )
    compiled = json.loads(out.stdout.strip().splitlines()[-1])
    assert compiled == {"cholesky": 0, "cho_solve": 0, "_reset_block": 0, "record_event": 0}
    assert not any(tmp_path.rglob("*.nbi"))  # and nothing was written to the cache


def test_with_the_jit_disabled_a_pinned_function_is_the_python_function(tmp_path: Path) -> None:
    """NUMBA_DISABLE_JIT=1 (the benchmark's interpreted reference) runs the same source."""
    code = "from pipeline.estimation.kernels import common; print(type(common.cholesky).__name__)"
    env = dict(
        os.environ, PYTHONPATH=str(REPO), NUMBA_CACHE_DIR=str(tmp_path), NUMBA_DISABLE_JIT="1"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
    )
    assert out.stdout.split()[-1] == "function"
