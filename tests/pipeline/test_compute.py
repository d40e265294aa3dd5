"""pipeline.compute on this machine: order, failures, the task store, progress, schedulers.

The Dask cluster itself (a scheduler and workers started from the venv, a killed worker,
TLS) is tests/pipeline/test_dask_cluster.py.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest

from navreplay.ingest.typed import FieldError
from navreplay.pipeline.compute import (
    SCHEDULER_ENV,
    ComputeError,
    ComputeParams,
    TaskError,
    TaskStore,
    resolve_scheduler,
    run_tasks,
)


def scaled(shared: int, item: int) -> int:
    """A task: fails on 3 (a bad input), else ``shared * item``."""
    if item == 3:
        raise ValueError(f"item {item} is bad")
    return shared * item


def pid_of(shared: int, item: int) -> int:
    """A task long enough that both workers get some."""
    time.sleep(0.3)
    return os.getpid()


@pytest.mark.parametrize("workers", [1, 2])
def test_results_keep_the_items_order_and_a_failure_is_recorded(workers: int) -> None:
    out = run_tasks(scaled, 10, [1, 2, 3, 4, 5], workers=workers)
    assert out[:2] == [10, 20]
    assert out[3:] == [40, 50]
    err = out[2]
    assert isinstance(err, TaskError)
    assert err.item == "3"
    assert err.error == "ValueError: item 3 is bad"
    assert "raise ValueError" in err.traceback


def test_forked_workers_run_the_tasks_in_other_processes() -> None:
    pids = run_tasks(pid_of, 0, list(range(6)), workers=2)
    assert os.getpid() not in pids
    assert len(set(pids)) == 2


def test_a_rerun_with_the_store_runs_only_what_is_missing(tmp_path: Path) -> None:
    store: TaskStore[int] = TaskStore(tmp_path / "tasks", "fp1")
    first = run_tasks(scaled, 10, [1, 2, 3], keys=["a", "b", "c"], store=store)
    assert first[:2] == [10, 20]
    assert isinstance(first[2], TaskError)
    # the stored results are taken as they are (shared 99 would change them); the failed
    # task runs again
    lines: list[str] = []
    again = run_tasks(scaled, 99, [1, 2, 3], keys=["a", "b", "c"], store=store,
                      progress=lines.append)  # fmt: skip
    assert again[:2] == [10, 20]
    assert isinstance(again[2], TaskError)
    assert lines[-1].startswith("[tasks] 3/3 done, 1 failed, 2 from an earlier run")
    # another fingerprint (other params) takes nothing from it
    other: TaskStore[int] = TaskStore(tmp_path / "tasks", "fp2")
    assert run_tasks(scaled, 99, [1, 2], keys=["a", "b"], store=other) == [99, 198]


def test_a_store_file_cut_short_is_run_again(tmp_path: Path) -> None:
    store: TaskStore[int] = TaskStore(tmp_path, "fp")
    store.put("a", 1)
    (path,) = store.directory.iterdir()
    path.write_bytes(path.read_bytes()[:5])
    assert store.get("a") is None


def test_progress_counts_and_estimates_what_is_left() -> None:
    lines: list[str] = []
    run_tasks(scaled, 1, [1, 2, 4], label="sweep", progress=lines.append, progress_every_s=0.0)
    assert [line.split(",")[0] for line in lines] == [
        "[sweep] 1/3 done",
        "[sweep] 2/3 done",
        "[sweep] 3/3 done",
    ]
    assert "left" in lines[0]
    assert "left" not in lines[-1]


def test_the_scheduler_comes_from_the_option_then_the_environment_then_the_params(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    params = ComputeParams(scheduler="local")
    monkeypatch.delenv(SCHEDULER_ENV, raising=False)
    assert resolve_scheduler(None, params) == "local"
    monkeypatch.setenv(SCHEDULER_ENV, "tcp://10.0.0.5:8786")
    assert resolve_scheduler(None, params) == "tcp://10.0.0.5:8786"
    assert resolve_scheduler("processes", params) == "processes"
    with pytest.raises(ComputeError, match="unknown scheduler 'dask'"):
        resolve_scheduler("dask", params)


def test_a_bad_scheduler_in_the_params_names_the_key() -> None:
    with pytest.raises(FieldError, match="scheduler") as info:
        ComputeParams(scheduler="http://host:8786")
    assert "tcp://HOST:PORT" in str(info.value)
    with pytest.raises(FieldError, match="workers"):
        ComputeParams(workers=-1)


def test_an_unreachable_scheduler_is_a_clear_error(monkeypatch: pytest.MonkeyPatch) -> None:
    from navreplay.pipeline import compute

    monkeypatch.setattr(compute, "CONNECT_TIMEOUT_S", 2.0)
    with pytest.raises(
        ComputeError, match=r"cannot reach the Dask scheduler at tcp://127\.0\.0\.1:9"
    ):
        run_tasks(scaled, 1, [1], scheduler="tcp://127.0.0.1:9")
