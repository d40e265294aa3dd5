"""Where sweeps run: in this process, on forked workers, or on a Dask cluster.

A sweep (the outage Monte Carlo, the robustness sweep, a fleet of logs) is a list of tasks,
each a pure function ``fn(shared, item)`` of one job shared by all of them (tables, params,
the nominal run) and its own item (a window start, a cell, a log's path). ``run_tasks`` runs
them on the engine the scheduler names and returns their results in the items' order, so
every engine gives the same results, bit for bit:

- ``processes`` (the default): forked workers of this process (``workers`` of them; one: in
  this process). They share the loaded kernels and tables, so nothing is sent or reloaded.
- ``local``: a Dask ``LocalCluster`` on 127.0.0.1, one single-threaded worker per core (or
  ``compute.workers``). Each worker is a new process that imports navreplay and loads the
  compiled kernels from numba's cache (4-5 s, measured), so it pays off for long sweeps.
- ``tcp://HOST:PORT`` or ``tls://HOST:PORT``: a running Dask scheduler (``dask scheduler``,
  with ``dask worker`` processes from the same navreplay installation). ``tls://`` uses the
  certificate files of ``compute.tls_*`` or, without them, Dask's own TLS settings
  (``distributed.comm.tls`` in Dask's configuration).

The scheduler comes from ``--scheduler``, else ``NAVREPLAY_SCHEDULER``, else
``compute.scheduler`` in params.yaml.

On a cluster the shared job is sent once to every worker (``Client.scatter``), so workers
need no shared file system for it. A task that raises does not stop the sweep: its result is
a ``TaskError`` with the error and traceback, for the caller to record. A worker that dies
mid-sweep loses nothing: the scheduler runs its tasks on the other workers (Dask retries a
task on up to three workers before giving up, recorded as a ``TaskError`` too). With a
``TaskStore`` each result is written as it arrives, so a rerun after an interruption runs
only the tasks that are missing.
"""

from __future__ import annotations

import hashlib
import logging
import multiprocessing
import os
import pickle
import sys
import time
import traceback
import uuid
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Future, ProcessPoolExecutor, as_completed
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Generic, TypeVar, cast

from navreplay.pipeline.errors import PipelineError

log = logging.getLogger(__name__)

SCHEDULER_ENV = "NAVREPLAY_SCHEDULER"
CONNECT_TIMEOUT_S = 20.0  # to reach a running scheduler
ENGINES = ("processes", "local")
_REMOTE = ("tcp://", "tls://")

S = TypeVar("S")
T = TypeVar("T")
R = TypeVar("R")


class ComputeError(PipelineError):
    """The scheduler cannot be used: an unknown name, or a cluster that cannot be reached."""


@dataclass(frozen=True)
class ComputeParams:
    """``compute``: where sweeps run (see the module docstring).

    Attributes:
        scheduler: ``processes``, ``local``, or a Dask scheduler address (``tcp://HOST:PORT``,
            ``tls://HOST:PORT``).
        workers: workers of the ``local`` cluster (0: one per core). The ``processes`` engine
            takes its count from the sweep's own ``workers`` setting.
        tls_ca_file, tls_cert, tls_key: PEM files for a ``tls://`` scheduler: the authority
            that signed the cluster's certificates, and this client's certificate and key.
    """

    scheduler: str = "processes"
    workers: int = 0
    tls_ca_file: str | None = None
    tls_cert: str | None = None
    tls_key: str | None = None

    def __post_init__(self) -> None:
        from navreplay.ingest.typed import FieldError

        if self.workers < 0:
            raise FieldError("workers", "must be >= 0 (0: one per core)")
        try:
            check_scheduler(self.scheduler)
        except ComputeError as err:
            raise FieldError("scheduler", str(err)) from None


def check_scheduler(scheduler: str) -> str:
    """``scheduler`` if it names an engine or a Dask address.

    Raises:
        ComputeError: it does neither.
    """
    if scheduler in ENGINES or (scheduler.startswith(_REMOTE) and len(scheduler) > 6):
        return scheduler
    raise ComputeError(
        f"unknown scheduler {scheduler!r}: use processes (forked workers, the default), local "
        "(a Dask cluster on this machine) or a Dask scheduler's address, tcp://HOST:PORT or "
        "tls://HOST:PORT"
    )


def resolve_scheduler(cli: str | None, params: ComputeParams) -> str:
    """The scheduler: ``--scheduler``, else ``NAVREPLAY_SCHEDULER``, else ``params``."""
    return check_scheduler(cli or os.environ.get(SCHEDULER_ENV) or params.scheduler)


@dataclass(frozen=True)
class TaskError:
    """What a task that raised left: the item it was given (as text), the error, and the
    exception itself where it survives pickling (for a caller that raises it again)."""

    item: str
    error: str
    traceback: str
    exception: Exception | None = None

    def to_json(self) -> dict[str, str]:
        return {"item": self.item, "error": self.error, "traceback": self.traceback}

    def reraise(self) -> None:
        """Raise the task's exception here (a ``PipelineError`` naming it if it was lost)."""
        if self.exception is not None:
            raise self.exception
        raise PipelineError(f"task {self.item} failed: {self.error}")


def guarded(fn: Callable[[S, T], R], shared: S, item: T) -> R | TaskError:
    """``fn(shared, item)``, or the ``TaskError`` it raised (run on the worker): any failure
    of one task is recorded, never fatal to the sweep."""
    try:
        return fn(shared, item)
    except Exception as err:
        kept: Exception | None = err
        try:
            pickle.loads(pickle.dumps(err))
        except Exception:  # an exception that cannot travel between processes stays as text
            kept = None
        return TaskError(repr(item), f"{type(err).__name__}: {err}", traceback.format_exc(), kept)


class TaskStore(Generic[R]):
    """Finished results of one sweep on disk, one file per task key, written atomically as
    they arrive, so a rerun runs only what is missing. ``fingerprint`` (e.g. a hash of the
    params and inputs) names the folder: results of another configuration are never taken."""

    def __init__(self, directory: Path, fingerprint: str) -> None:
        self.directory = Path(directory) / fingerprint

    def _path(self, key: str) -> Path:
        return self.directory / f"{hashlib.sha256(key.encode()).hexdigest()[:32]}.pickle"

    def get(self, key: str) -> R | None:
        path = self._path(key)
        if not path.is_file():
            return None
        try:
            with path.open("rb") as fh:
                stored_key, value = pickle.load(fh)
        except Exception:  # a file cut short, or of another version: run the task again
            return None
        return value if stored_key == key else None

    def put(self, key: str, value: R) -> None:
        from navreplay.ingest.atomic import atomic_write_bytes

        self.directory.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(self._path(key), pickle.dumps((key, value), protocol=5))


class Progress:
    """Counts and an ETA for a sweep, to ``say`` (stderr by default) at most every
    ``every_s`` seconds and once at the end."""

    def __init__(
        self, label: str, total: int, say: Callable[[str], None] | None, every_s: float = 5.0
    ) -> None:
        self.label, self.total, self.every_s = label, total, every_s
        self.say = say
        self.done = self.failed = self.reused = 0
        self.t0 = self.t_last = time.perf_counter()

    def add(self, *, failed: bool = False, reused: bool = False) -> None:
        self.done += 1
        self.failed += failed
        self.reused += reused
        now = time.perf_counter()
        if self.say is not None and (self.done == self.total or now - self.t_last >= self.every_s):
            self.t_last = now
            self.say(self.line(now))

    def line(self, now: float) -> str:
        elapsed = now - self.t0
        ran = self.done - self.reused
        left = self.total - self.done
        eta = f", about {_duration(elapsed / ran * left)} left" if ran and left else ""
        extra = f", {self.failed} failed" if self.failed else ""
        extra += f", {self.reused} from an earlier run" if self.reused else ""
        return f"[{self.label}] {self.done}/{self.total} done{extra}, {_duration(elapsed)}{eta}"


def _duration(s: float) -> str:
    return f"{s:.0f} s" if s < 120 else f"{s / 60:.1f} min"


def stderr_progress(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


# ---- the engines ----------------------------------------------------------------------------

_SHARED: Any = None


def _init(shared: Any) -> None:
    global _SHARED  # noqa: PLW0603 -- one job per worker process, set once by the pool
    _SHARED = shared


def _forked(fn: Callable[[Any, T], R], item: T) -> R | TaskError:
    return guarded(fn, _SHARED, item)


def _security(params: ComputeParams, scheduler: str) -> Any:
    from distributed.security import Security

    if not scheduler.startswith("tls://"):
        return None
    if params.tls_ca_file or params.tls_cert or params.tls_key:
        return Security(
            tls_ca_file=params.tls_ca_file,
            tls_client_cert=params.tls_cert,
            tls_client_key=params.tls_key,
            require_encryption=True,
        )
    sec = Security()  # Dask's configuration: distributed.comm.tls.*
    if not getattr(sec, "tls_ca_file", None):
        raise ComputeError(
            f"{scheduler}: a tls:// scheduler needs the cluster's certificates: set "
            "compute.tls_ca_file, compute.tls_cert and compute.tls_key in the params, or "
            "Dask's distributed.comm.tls settings (e.g. DASK_DISTRIBUTED__COMM__TLS__CA_FILE)"
        )
    return sec


@contextmanager
def dask_client(scheduler: str, params: ComputeParams) -> Iterator[Any]:
    """A Dask client of ``scheduler`` (``local``: a cluster started here and stopped after).

    Raises:
        ComputeError: the scheduler cannot be reached.
    """
    from distributed import Client, LocalCluster

    # Dask logs every start and stop of its scheduler and workers at INFO: not news to a user
    logging.getLogger("distributed").setLevel(max(logging.WARNING, log.getEffectiveLevel()))
    if scheduler == "local":
        n = params.workers or os.cpu_count() or 1
        with (
            LocalCluster(
                n_workers=n,
                threads_per_worker=1,
                processes=True,
                host="127.0.0.1",
                dashboard_address=None,
                silence_logs=logging.WARNING,
            ) as cluster,
            Client(cluster) as client,
        ):
            yield client
        return
    try:
        client = Client(
            scheduler, security=_security(params, scheduler), timeout=f"{CONNECT_TIMEOUT_S}s"
        )
    except (OSError, TimeoutError, ValueError) as err:
        raise ComputeError(
            f"cannot reach the Dask scheduler at {scheduler}: {err}. Start one (`dask "
            f"scheduler`, then `dask worker {scheduler}` on each machine), or use "
            "--scheduler processes"
        ) from err
    with client:
        yield client


def run_tasks(
    fn: Callable[[S, T], R],
    shared: S,
    items: Sequence[T],
    *,
    scheduler: str = "processes",
    workers: int = 1,
    params: ComputeParams | None = None,
    label: str = "tasks",
    keys: Sequence[str] | None = None,
    store: TaskStore[R] | None = None,
    progress: Callable[[str], None] | None = None,
    progress_every_s: float = 5.0,
) -> list[R | TaskError]:
    """``fn(shared, item)`` for every item, on ``scheduler``; the results in ``items``' order.

    ``workers``: processes of the ``processes`` engine (1: in this process). ``keys`` name
    the tasks for ``store`` (one per item; default: the items' reprs): a stored result is
    taken instead of running its task, and each new result is stored as it arrives (errors
    are not, so a rerun tries them again). ``progress`` is given a line of counts and an ETA
    at most every ``progress_every_s`` seconds and at the end. ``fn`` must be importable by
    name on the workers (a module-level function), and ``shared`` and the items picklable.
    """
    params = params or ComputeParams()
    keys = list(keys) if keys is not None else [repr(i) for i in items]
    if len(keys) != len(items):
        raise ValueError(f"{len(keys)} keys for {len(items)} items")
    out: list[R | TaskError | None] = [None] * len(items)
    bar = Progress(label, len(items), progress, progress_every_s)
    todo = []
    for i, key in enumerate(keys):
        found = store.get(key) if store is not None else None
        if found is None:
            todo.append(i)
        else:
            out[i] = found
            bar.add(reused=True)

    def finish(i: int, result: R | TaskError) -> None:
        out[i] = result
        if store is not None and not isinstance(result, TaskError):
            store.put(keys[i], result)
        if isinstance(result, TaskError):
            log.warning("%s: task %s failed: %s", label, keys[i], result.error)
        bar.add(failed=isinstance(result, TaskError))

    if todo and scheduler == "processes":
        _run_processes(fn, shared, items, todo, workers, finish)
    elif todo:
        with dask_client(check_scheduler(scheduler), params) as client:
            _run_dask(client, fn, shared, items, todo, label, finish)
    missing = [keys[i] for i, r in enumerate(out) if r is None]
    if missing:  # the engines' contract: every task ends with a result or an error
        raise RuntimeError(f"{label}: no result for {', '.join(missing[:3])}")
    return cast("list[R | TaskError]", out)


def _run_processes(
    fn: Callable[[S, T], R],
    shared: S,
    items: Sequence[T],
    todo: list[int],
    workers: int,
    finish: Callable[[int, R | TaskError], None],
) -> None:
    if workers <= 1 or len(todo) < 2:
        for i in todo:
            finish(i, guarded(fn, shared, items[i]))
        return
    # fork shares the compiled kernels and the tables with the workers (copy on write);
    # a spawned worker re-imports and re-loads every numba kernel, 4-8 s each
    methods = multiprocessing.get_all_start_methods()
    ctx = multiprocessing.get_context("fork" if "fork" in methods else "spawn")
    n = min(workers, len(todo))
    with ProcessPoolExecutor(n, mp_context=ctx, initializer=_init, initargs=(shared,)) as pool:
        futures: dict[Future[R | TaskError], int] = {
            pool.submit(_forked, fn, items[i]): i for i in todo
        }
        for fut in as_completed(futures):
            finish(futures[fut], fut.result())


def _run_dask(
    client: Any,
    fn: Callable[[S, T], R],
    shared: S,
    items: Sequence[T],
    todo: list[int],
    label: str,
    finish: Callable[[int, R | TaskError], None],
) -> None:
    from distributed import as_completed as dask_completed

    shared_f = client.scatter(shared, broadcast=True, hash=False)
    token = uuid.uuid4().hex[:8]
    keys = [f"{label.replace(' ', '_')}-{token}-{i}" for i in todo]
    n = len(todo)
    submitted = client.map(
        guarded, [fn] * n, [shared_f] * n, [items[i] for i in todo], key=keys, pure=False
    )  # one message for all of them
    index = {f.key: i for f, i in zip(submitted, todo, strict=True)}
    # results are fetched as tasks finish, concurrently, not one round trip each
    for fut, value in dask_completed(submitted, with_results=True, raise_errors=False):
        i = index[fut.key]
        if fut.status == "finished":
            finish(i, value)
        else:  # e.g. KilledWorker: the task killed three workers
            err = value[1] if isinstance(value, tuple) and len(value) > 1 else value
            finish(i, TaskError(repr(items[i]), f"{type(err).__name__}: {err}", ""))
        fut.release()
