"""compile_helper: what the helper compiles is what the replay loads; when it starts.

That the plan is current: ``test_compile_plan.py`` (its own file, so the suite's workers run
the two files' cold compiles side by side).
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
import threading
import types as types_ns
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numba as nb
import numpy as np
import pytest
from numba.core import types
from numba.core.dispatcher import Dispatcher

from pipeline.estimation import compile_helper as ch
from pipeline.estimation.config import FILTER_KINDS, FiltersParams
from pipeline.estimation.replay import RunResult, kernel_for, run_filter

REPO = Path(__file__).resolve().parents[3]


@nb.njit(cache=True)
def _tiny_callee(x: float) -> float:
    return 2.0 * x


@nb.njit(cache=True)
def _tiny_kernel(x: float) -> float:
    return _tiny_callee(x) + 1.0


def _digest(res: RunResult) -> str:
    x, p = np.ascontiguousarray(res.x), np.ascontiguousarray(res.P)
    return hashlib.sha256(x.tobytes() + p.tobytes()).hexdigest()


def _env(cache: Path, **extra: str) -> dict[str, str]:
    return dict(os.environ, NUMBA_CACHE_DIR=str(cache), PYTHONPATH=str(REPO), **extra)


@pytest.mark.parametrize(
    "t",
    [
        types.float64[:, ::1], types.int64[::1], types.Array(types.float64, 2, "A"),
        types.Array(types.float64, 1, "C", readonly=True), types.int64, types.none,
        types.UniTuple(types.float64, 3),  # type: ignore[no-untyped-call]
        types.IntegerLiteral(3), types.BooleanLiteral(False),
    ],
)  # fmt: skip
def test_numba_types_survive_as_text(t: types.Type) -> None:
    text = ch.format_type(t)
    assert ch.parse_type(text) == t


def test_a_type_without_text_is_refused_by_name() -> None:
    t = types.NumberClass(types.float64)
    with pytest.raises(ValueError, match="does not survive as text"):
        ch.format_type(t)


def test_the_plan_covers_every_filter_with_resolvable_entries() -> None:
    filters, kernels = ch.load_plan()
    assert set(filters) == set(FILTER_KINDS)
    for name, key in filters.items():
        plan = kernels[key]
        assert plan.kernel == ch.dispatcher_name(kernel_for(FILTER_KINDS[name], "numba"))
        assert len(plan.callees) >= 10, name
        for callee, args in plan.callees:
            assert isinstance(ch.resolve(callee), Dispatcher), callee
            for text in args:
                ch.parse_type(text)


DIGEST = """
import json, subprocess, sys
from pipeline.params import load_params
from pipeline.estimation.replay import run_filter
from pipeline.estimation import compile_helper as ch
from tests.pipeline.estimation.test_compile_helper import _digest
params = load_params(ch.REPO_PARAMS)
drive = ch.plan_drive()
name = sys.argv[1]
if len(sys.argv) > 2:  # a helper alongside, which reports what it compiles to argv[2]
    popen = subprocess.Popen
    subprocess.Popen = lambda cmd, *a, **k: popen([*cmd, "--report", sys.argv[2]], *a, **k)
    ch.usable_cores = lambda: 2
with ch.compiles_started() as started:
    res = run_filter(dict(drive.tables), drive.sensors, name, params.filters.get(name))
print(json.dumps({"compiled": [n for n, _ in started], "digest": _digest(res)}))
"""


def _replay(cache: Path, name: str, helper_report: Path | None = None) -> tuple[list[str], str]:
    """(what a replay compiled, the digest of its estimates) in a new process; without
    helper, or with one that reports to ``helper_report``."""
    helper = "0" if helper_report is None else "1"
    report = [] if helper_report is None else [str(helper_report)]
    out = subprocess.run(
        [sys.executable, "-c", DIGEST, name, *report],
        env=_env(cache, NAVREPLAY_COMPILE_HELPER=helper),
        cwd=REPO, capture_output=True, text=True, check=True,
    )  # fmt: skip
    result = json.loads(out.stdout.strip().splitlines()[-1])
    return list(result["compiled"]), str(result["digest"])


@pytest.mark.slow
def test_the_replay_loads_what_the_helper_compiled_and_estimates_the_same(
    tmp_path: Path, filters: FiltersParams
) -> None:
    """The helper run to its end, then a cold replay: it compiles its kernel and nothing the
    helper compiled, and its estimates are bitwise those of this process's replay (the
    suite's own cache, no helper)."""
    drive40 = ch.plan_drive()
    name = "lc_ekf"
    report = tmp_path / "report.txt"
    helped = tmp_path / "helped"
    subprocess.run(
        [sys.executable, "-m", "pipeline.estimation.compile_helper", name, "--report", str(report)],
        env=_env(helped), cwd=REPO, check=True, capture_output=True,
    )  # fmt: skip
    by_helper = set(report.read_text().split())
    _, kernels = ch.load_plan()
    plan = kernels[ch.load_plan()[0][name]]
    assert by_helper <= {c for c, _ in plan.callees}
    assert len(by_helper) >= 10
    compiled, digest = _replay(helped, name)
    assert plan.kernel in compiled
    assert not by_helper & set(compiled)
    here = _digest(run_filter(dict(drive40.tables), drive40.sensors, name, filters.get(name)))
    assert digest == here


@pytest.mark.slow
def test_a_cold_replay_and_its_helper_share_the_compile_without_overlap(
    tmp_path: Path, filters: FiltersParams
) -> None:
    """A cold replay with its helper alongside (the claims in action): between them they
    compile the plan's callees, none twice, and the estimates are bitwise this process's."""
    drive40 = ch.plan_drive()
    name = "lc_ekf"
    report = tmp_path / "report.txt"
    compiled, digest = _replay(tmp_path / "cache", name, helper_report=report)
    by_helper = report.read_text().split() if report.exists() else []
    plan = ch.plan_for(name)
    assert plan is not None
    callees = [c for c in compiled if c != plan.kernel]
    assert plan.kernel in compiled
    assert by_helper, "the helper compiled nothing"
    assert len(set(by_helper)) == len(by_helper)
    assert not set(by_helper) & set(callees), "compiled in both processes"
    assert set(by_helper) | set(callees) <= {c for c, _ in plan.callees}
    here = _digest(run_filter(dict(drive40.tables), drive40.sensors, name, filters.get(name)))
    assert digest == here


def _tiny_plan(tmp_path: Path) -> Path:
    path = tmp_path / "plan.json"
    kernel = f"{__name__}:_tiny_kernel"
    path.write_text(json.dumps({
        "filters": {"tiny": "tiny"},
        "kernels": {"tiny": {"kernel": kernel, "args": ["float64"],
                             "callees": [[f"{__name__}:_tiny_callee", ["float64"]]]}},
    }))  # fmt: skip
    return path


def test_the_helper_starts_only_for_a_cold_planned_kernel(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    plan = _tiny_plan(tmp_path)
    monkeypatch.setenv(ch.ENV_SWITCH, "1")
    monkeypatch.setattr(ch, "usable_cores", lambda: 2)
    monkeypatch.setattr(ch, "is_cached", lambda d, a: False)
    helper = ch.start("tiny", _tiny_kernel, plan)
    assert helper is not None
    helper.stop()
    helper.stop()  # idempotent
    assert ch.start("other", _tiny_kernel, plan) is None  # not in the plan
    assert ch.start("tiny", _tiny_callee, plan) is None  # not the planned kernel
    monkeypatch.setattr(ch, "usable_cores", lambda: 1)
    assert ch.start("tiny", _tiny_kernel, plan) is None
    monkeypatch.setattr(ch, "usable_cores", lambda: 2)
    monkeypatch.setenv(ch.ENV_SWITCH, "0")
    assert ch.start("tiny", _tiny_kernel, plan) is None
    monkeypatch.setenv(ch.ENV_SWITCH, "1")
    monkeypatch.setattr(ch, "is_cached", lambda d, a: True)
    assert ch.start("tiny", _tiny_kernel, plan) is None


class _FakeHelper:
    """Counts how often it was actually stopped (``Helper.stop`` is idempotent)."""

    def __init__(self) -> None:
        self.stops = 0
        self.running = True
        self.owner = os.getpid()

    def stop(self) -> None:
        self.stops += self.running
        self.running = False


def test_a_helper_started_early_is_adopted_by_the_replay_and_stopped_at_the_end(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    started: list[tuple[str, object]] = []

    def fake_start(name: str, kernel: object, plan_path: Path = ch.PLAN_PATH) -> _FakeHelper:
        started.append((name, kernel))
        return _FakeHelper()

    monkeypatch.setattr(ch, "start", fake_start)
    kernel = kernel_for(FILTER_KINDS["tc_ukf"], "numba")
    with ch.early("tc_ukf", "numba"):
        assert started == [("tc_ukf", kernel)]  # started before any replay
        early_helper = ch._started_early["tc_ukf"]
        with ch.helping("tc_ukf", kernel) as compiled:
            assert len(started) == 1  # adopted, not a second helper
            compiled()
        assert early_helper.stops == 1  # type: ignore[attr-defined]
        with ch.helping("tc_ukf", kernel):  # a later replay (another scenario) starts anew
            assert len(started) == 2
    assert early_helper.stops == 1  # type: ignore[attr-defined]
    assert ch._started_early == {}
    with ch.early("tc_ukf", "filterpy"), ch.early("vehicle_kinematic", "numba"):
        assert len(started) == 2  # no numba kernel to compile: no helper


def test_claims_are_exclusive_and_waits_end_when_done_or_helper_gone(tmp_path: Path) -> None:
    claims = ch.Claims(tmp_path)
    assert claims.take(3)
    assert not claims.take(3)  # the other process's now
    assert claims.take(4)
    asked: list[int] = []

    def alive(answer: bool) -> Callable[[], bool]:
        def ask() -> bool:
            asked.append(1)
            return answer

        return ask

    claims.wait(3, alive(False))  # the helper is gone: asked once, no wait
    assert len(asked) == 1
    claims.finish(4)
    claims.wait(4, alive(True))  # finished: not even asked
    assert len(asked) == 1
    threading.Timer(0.2, claims.finish, (3,)).start()
    claims.wait(3, alive(True))  # polls until the helper has finished
    assert (tmp_path / "3.done").exists()
    assert len(asked) > 2


class _FakeCache:
    """A cache entry that appears once the helper has finished entry 0."""

    def __init__(self, claims: ch.Claims) -> None:
        self.claims = claims
        self.looks = 0

    def load_overload(self, sig: Any, target_context: Any) -> Any:
        self.looks += 1
        done = (self.claims.root / "0.done").exists()
        return "compiled" if sig == (types.float64,) and done else None


def test_a_miss_waits_for_the_helper_s_claim_and_claims_the_rest(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    claims = ch.Claims(tmp_path)
    cache = _FakeCache(claims)
    fake = types_ns.SimpleNamespace(_cache=cache)
    monkeypatch.setattr(ch, "resolve", lambda name: fake)
    plan = ch.KernelPlan("k", (), (("a", ("float64",)), ("b", ("int64",))))
    caches = ch._wait_for_helper(plan, claims, alive=lambda: True)
    assert caches == [cache]
    assert claims.take(0)  # the helper compiles entry 0 ...
    threading.Timer(0.2, claims.finish, (0,)).start()
    assert fake._cache.load_overload((types.float64,), None) == "compiled"  # ... waited for
    assert cache.looks == 2  # looked again once the helper was done
    assert fake._cache.load_overload((types.int64,), None) is None  # a miss: compile here
    assert not claims.take(1)  # ... and the helper will not
    assert fake._cache.load_overload((types.float32,), None) is None  # not in the plan
    ch._unwait(caches)
    assert "load_overload" not in vars(cache)  # the cache's own method again


CACHED = f"""
import json, sys
from numba.core import types
from pipeline.estimation import compile_helper as ch
sys.path.insert(0, {str(REPO)!r})
from tests.pipeline.estimation.test_compile_helper import _tiny_callee
before = ch.is_cached(_tiny_callee, (types.float64,))
n = ch.run_helper("tiny", ch.Path(sys.argv[1]))
print(json.dumps([before, n, ch.is_cached(_tiny_callee, (types.float64,))]))
"""


def test_is_cached_reads_numba_s_cache_index(tmp_path: Path) -> None:
    """Cold, then the helper compiles the callee; a new process finds it in the cache."""
    plan = _tiny_plan(tmp_path)
    cache = tmp_path / "cache"

    def probe() -> list[object]:
        out = subprocess.run(
            [sys.executable, "-c", CACHED, str(plan)], env=_env(cache), cwd=REPO,
            capture_output=True, text=True, check=True,
        )  # fmt: skip
        result: list[object] = json.loads(out.stdout.strip().splitlines()[-1])
        return result

    assert probe() == [False, 1, True]
    assert probe() == [True, 0, True]
