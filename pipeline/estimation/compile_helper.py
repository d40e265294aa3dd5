"""A cold replay compiles on two cores: a helper process compiles the kernel's callees.

numba compiles one function at a time in a process (a global compiler lock). A cold
``navreplay run`` spends most of its 20-30 CPU s compiling the replay kernel and the ~45 model
and bookkeeping functions it calls: typing the kernel compiles each callee when it reaches the
callee's call site, or loads the callee from numba's on-disk cache if it is there. So when the
kernel of a filter is not in the cache and the machine has a second core, ``run_filter`` starts
a helper process (``python -m pipeline.estimation.compile_helper FILTER``, niced) that compiles
the same callees with the same argument types into the same cache, from the *last* the
kernel's compile reaches to the first. The two meet half way: the replay loads what the helper
has finished. The helper is stopped (killed) as soon as the kernel is compiled.

Neither compiles a callee twice: each claims a callee before compiling it (``Claims``, a
directory of marker files the two share), and when the replay's compile reaches a callee the
helper is still compiling, it waits for it and loads it from the cache instead of compiling it
again from the start. ``navreplay run`` starts the helper (``early``) before it reads and
prepares the inputs, so that the helper is ready when the kernel's compile begins.

The compiled code is the same either way (a function compiles to the same machine code in
either process, and a cached callee is what a later warm run would load anyway); only the wall
time of a cold run drops. The CPU time rises a little: the helper's own start, and the numba
internals both processes compile for themselves. ``benchmarks/bench_estimation.py`` measures
both, with the helper and without.

Which callees, with which types: ``compile_plan.json``, one ordered list per kernel signature,
recorded from cold compiles by ``python -m pipeline.estimation.compile_helper --write-plan``.
``tests/pipeline/estimation/test_compile_helper.py`` checks that the plan is current, so a
change to a kernel's callees fails a test until the plan is written again. A stale entry
would only cost the helper's time: the replay never depends on what the helper did.

Not started: with ``NAVREPLAY_COMPILE_HELPER=0``, on one usable core, in a worker of a process
pool (the Monte Carlo's, the scenario runs'), when the kernel is already compiled in this
process or cached on disk, or for a filter the plan does not list.
If the helper is killed while numba writes a cache file, at most a temporary file
(``*.tmp.<hex>``) stays behind; numba replaces its cache files atomically, so no cache entry is
ever half-written.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from pipeline.synth import SynthResult

PLAN_PATH = Path(__file__).with_name("compile_plan.json")
REPO_PARAMS = Path(__file__).resolve().parents[2] / "params.yaml"
ENV_SWITCH = "NAVREPLAY_COMPILE_HELPER"
WRITE_COMMAND = "python -m pipeline.estimation.compile_helper --write-plan"


@dataclass(frozen=True)
class KernelPlan:
    """What a cold compile of one kernel signature compiles, in the order it starts each.

    ``kernel`` and every callee are ``module:qualname`` of a numba dispatcher; ``args`` and the
    callees' argument types are numba type strings (``format_types``).
    """

    kernel: str
    args: tuple[str, ...]
    callees: tuple[tuple[str, tuple[str, ...]], ...]


# -- numba types as text ----------------------------------------------------------------------


def format_type(t: Any) -> str:
    """A numba type as text that ``parse_types`` reads back (``float64[:, ::1]``, ``int64``)."""
    from numba.core import types

    if isinstance(t, types.Array) and t.mutable and t.aligned and t.layout in "CA":
        dims = [":"] * t.ndim
        if t.layout == "C":
            dims[-1] = "::1"
        text = f"{t.dtype}[{', '.join(dims)}]"
    elif isinstance(t, types.IntegerLiteral | types.BooleanLiteral):
        text = f"{type(t).__name__}({t.literal_value!r})"
    else:
        text = repr(t)
    try:
        same = parse_type(text) == t
    except Exception:  # not a type numba's namespace can build from the text
        same = False
    if not same:
        raise ValueError(f"numba type {t!r} does not survive as text {text!r}")
    return text


def parse_type(text: str) -> Any:
    """The numba type ``text`` names (evaluated among ``numba.core.types`` only)."""
    from numba.core import types

    return eval(text, {"__builtins__": {}}, vars(types))  # a closed namespace: types only


def format_types(ts: Sequence[Any]) -> tuple[str, ...]:
    return tuple(format_type(t) for t in ts)


# -- the plan ---------------------------------------------------------------------------------


@cache
def load_plan(path: Path = PLAN_PATH) -> tuple[dict[str, str], dict[str, KernelPlan]]:
    """(filter name -> kernel key, kernel key -> plan) of ``compile_plan.json``; empty if the
    file is absent."""
    if not path.exists():
        return {}, {}
    raw = json.loads(path.read_text())
    kernels = {
        key: KernelPlan(
            k["kernel"], tuple(k["args"]), tuple((c[0], tuple(c[1])) for c in k["callees"])
        )
        for key, k in raw["kernels"].items()
    }
    return dict(raw["filters"]), kernels


def plan_for(filter_name: str, path: Path = PLAN_PATH) -> KernelPlan | None:
    """The plan of ``filter_name``'s kernel, or None if the plan does not list the filter."""
    filters, kernels = load_plan(path)
    return kernels.get(filters.get(filter_name, ""))


def resolve(name: str) -> Any:
    """The object ``module:qualname`` names (an AttributeError or ImportError if none)."""
    module, _, qualname = name.partition(":")
    obj: Any = importlib.import_module(module)
    for part in qualname.split("."):
        obj = getattr(obj, part)
    return obj


def dispatcher_name(dispatcher: Any) -> str:
    fn = dispatcher.py_func
    return f"{fn.__module__}:{fn.__qualname__}"


def is_cached(dispatcher: Any, argtypes: tuple[Any, ...]) -> bool:
    """Whether ``dispatcher`` is compiled for ``argtypes`` in this process or in numba's cache.

    Reads numba's cache index the way ``Dispatcher.compile`` does (numba has no public call for
    it). If that fails (a numba that keeps its cache differently) the answer is True, so the
    helper is not started: a newer numba can cost the speed-up, never a run.
    """
    if argtypes in dispatcher.overloads:
        return True
    try:
        cache_ = dispatcher._cache
        key = cache_._index_key(argtypes, dispatcher.targetctx.codegen())
        return key in cache_._cache_file._load_index()
    except Exception:  # any failure means: do not start the helper
        return True


def usable_cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


# -- the main process's side -------------------------------------------------------------------


@dataclass(frozen=True)
class Claims:
    """Who compiles which plan entry: a directory shared by the replay and its helper.

    Whichever process first creates ``<i>.claim`` (atomically, ``O_EXCL``) compiles entry
    ``i`` of the plan; the helper writes ``<i>.done`` once it has finished one (compiled and
    saved to the cache, or failed). So the two never compile the same entry, and when the
    replay reaches an entry the helper is still compiling it waits for it, instead of
    compiling it again from the start.
    """

    root: Path

    def take(self, i: int) -> bool:
        """Claim entry ``i``; False if the other process has."""
        try:
            os.close(os.open(self.root / f"{i}.claim", os.O_CREAT | os.O_EXCL | os.O_WRONLY))
        except FileExistsError:
            return False
        except OSError:  # the directory is gone: nobody else compiles it
            return True
        return True

    def finish(self, i: int) -> None:
        with contextlib.suppress(OSError):
            (self.root / f"{i}.done").touch()

    def wait(self, i: int, alive: Callable[[], bool], timeout_s: float = 300.0) -> None:
        """Until the helper has finished entry ``i``, or is gone (or ``timeout_s``)."""
        done = self.root / f"{i}.done"
        deadline = time.monotonic() + timeout_s
        while not done.exists() and alive() and time.monotonic() < deadline:
            time.sleep(0.005)


def _wait_for_helper(plan: KernelPlan, claims: Claims, alive: Callable[[], bool]) -> list[Any]:
    """Make this process's cache lookups of the plan's callees claim-aware: a miss on an entry
    the helper has claimed waits for the helper and looks again; a miss on an unclaimed entry
    claims it (this process compiles it). Returns the caches changed (``_unwait``). A process
    forked from this one (a pool's worker) looks up as numba does: the helper is not its."""
    from numba.core import sigutils

    owner = os.getpid()
    entries: dict[Any, dict[tuple[Any, ...], int]] = {}
    for i, (name, args) in enumerate(plan.callees):
        try:
            dispatcher = resolve(name)
            argtypes = tuple(parse_type(t) for t in args)
        except Exception:  # a stale entry: nothing to wait for
            continue
        cache_ = getattr(dispatcher, "_cache", None)
        if cache_ is not None and hasattr(cache_, "load_overload"):
            entries.setdefault(cache_, {})[argtypes] = i

    def waiting(cache_: Any, index: dict[tuple[Any, ...], int]) -> Callable[[Any, Any], Any]:
        load = cache_.load_overload

        def load_overload(sig: Any, target_context: Any) -> Any:
            got = load(sig, target_context)
            if got is not None or os.getpid() != owner:
                return got
            args, _ = sigutils.normalize_signature(sig)  # type: ignore[no-untyped-call]
            i = index.get(tuple(args))
            if i is None or claims.take(i):
                return None  # this process compiles it
            claims.wait(i, alive)
            return load(sig, target_context)

        return load_overload

    for cache_, index in entries.items():
        cache_.load_overload = waiting(cache_, index)
    return list(entries)


def _unwait(caches: list[Any]) -> None:
    for cache_ in caches:
        with contextlib.suppress(AttributeError):
            del cache_.load_overload  # numba's own method again


class Helper:
    """A running helper process; ``stop()`` kills and reaps it and ends the claims
    (idempotent)."""

    def __init__(self, proc: subprocess.Popen[bytes], claims: Claims, plan: KernelPlan) -> None:
        self._proc: subprocess.Popen[bytes] | None = proc
        self._claims = claims
        self._caches = _wait_for_helper(plan, claims, self.alive)
        self.owner = os.getpid()  # a forked child neither adopts nor stops it

    def alive(self) -> bool:
        return self._proc is not None and self._proc.poll() is None

    def stop(self) -> None:
        proc, self._proc = self._proc, None
        if proc is not None:
            proc.kill()
            proc.wait()
            _unwait(self._caches)
            shutil.rmtree(self._claims.root, ignore_errors=True)


def wanted(filter_name: str, kernel: Any, plan_path: Path = PLAN_PATH) -> KernelPlan | None:
    """The plan for the helper if a helper would help: a cold compile of a planned kernel on a
    free core (see the module docstring for when it would not); else None."""
    import multiprocessing

    if os.environ.get(ENV_SWITCH, "1") == "0" or usable_cores() < 2:
        return None
    if multiprocessing.parent_process() is not None:  # a pool's worker: its siblings use the cores
        return None
    plan = plan_for(filter_name, plan_path)
    if plan is None or not hasattr(kernel, "overloads"):
        return None
    try:
        planned = dispatcher_name(kernel) == plan.kernel
        argtypes = tuple(parse_type(t) for t in plan.args)
    except Exception:  # an unreadable plan entry: no helper
        return None
    return plan if planned and not is_cached(kernel, argtypes) else None


def start(filter_name: str, kernel: Any, plan_path: Path = PLAN_PATH) -> Helper | None:
    """Start the helper for ``filter_name``'s ``kernel`` if it is ``wanted``."""
    plan = wanted(filter_name, kernel, plan_path)
    if plan is None:
        return None
    from numba.core import config

    env = dict(os.environ)
    cache_dir = getattr(config, "CACHE_DIR", "")  # numba's live setting (_numba_cache)
    if cache_dir:
        env["NUMBA_CACHE_DIR"] = str(cache_dir)
    claims = Claims(Path(tempfile.mkdtemp(prefix="navreplay-compile-")))
    cmd = [sys.executable, "-m", "pipeline.estimation.compile_helper", filter_name]
    cmd += ["--claims", str(claims.root)]
    if plan_path != PLAN_PATH:
        cmd += ["--plan", str(plan_path)]
    proc = subprocess.Popen(
        cmd, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )  # fmt: skip
    return Helper(proc, claims, plan)


_started_early: dict[str, Helper] = {}


@contextlib.contextmanager
def early(filter_name: str, backend: str) -> Iterator[None]:
    """Start the helper for ``filter_name`` now, before the inputs are read and prepared, so
    that it is ready when the kernel compile begins; the first ``helping`` of that filter in
    the block adopts it (in this process: the workers of a pool forked meanwhile load what it
    compiled, but neither adopt nor wait for it). It is stopped when the block ends, at the
    latest."""
    from pipeline.estimation.config import FILTER_KINDS

    helper = None
    if backend == "numba" and filter_name in FILTER_KINDS:
        helper = start(filter_name, resolve(FILTER_KINDS[filter_name].numba_kernel))
    if helper is not None:
        _started_early[filter_name] = helper
    try:
        yield
    finally:
        if helper is not None:
            if _started_early.get(filter_name) is helper:
                del _started_early[filter_name]
            helper.stop()


@contextlib.contextmanager
def helping(filter_name: str, kernel: Any) -> Iterator[Callable[[], None]]:
    """``with helping(name, kernel) as compiled:`` runs the helper (if any) in the block: the
    one ``early`` started, or a new one; calling ``compiled()`` once the kernel is compiled
    stops it early."""
    helper = _started_early.get(filter_name)
    if helper is not None and helper.owner == os.getpid():
        del _started_early[filter_name]
    else:
        helper = start(filter_name, kernel)
    stop = helper.stop if helper is not None else (lambda: None)
    try:
        yield stop
    finally:
        stop()


# -- the helper process -------------------------------------------------------------------------


def run_helper(
    filter_name: str,
    plan_path: Path = PLAN_PATH,
    report: Path | None = None,
    claims: Claims | None = None,
) -> int:
    """Compile the plan's callees for ``filter_name`` from the last to the first, skipping
    those the replay has claimed (``claims``); the number compiled here (not loaded from the
    cache). With ``report``, append one line per callee compiled (``module:qualname``), for
    the tests."""
    from pipeline._numba_cache import fewer_gc_passes

    with contextlib.suppress(OSError):
        os.nice(10)  # the replay's own compile comes first
    plan = plan_for(filter_name, plan_path)
    if plan is None:
        return 0
    parent = os.getppid()
    done = 0
    with fewer_gc_passes():
        for i in reversed(range(len(plan.callees))):
            name, args = plan.callees[i]
            if os.getppid() != parent:  # the replay is gone
                break
            try:
                dispatcher = resolve(name)
                argtypes = tuple(parse_type(t) for t in args)
                if is_cached(dispatcher, argtypes) or (claims is not None and not claims.take(i)):
                    continue
            except Exception:  # a stale entry: the replay compiles what it needs itself
                continue
            try:
                dispatcher.compile(argtypes)
            except Exception:  # the replay finds no cache entry and compiles it itself
                continue
            finally:
                if claims is not None:
                    claims.finish(i)
            done += 1
            if report is not None:
                with report.open("a") as f:
                    f.write(name + "\n")
    return done


# -- writing the plan ----------------------------------------------------------------------------


def plan_drive() -> SynthResult:
    """The drive ``record`` replays: 40 s of seoul_campus (params.yaml), 10 s at rest first."""
    from dataclasses import replace

    from pipeline.params import load_params
    from pipeline.synth.seoul_campus import simulate

    synth = load_params(REPO_PARAMS).synth
    sp = replace(synth.seoul_campus, duration_s=40.0, stationary_s=10.0)
    return simulate(sp, seed=synth.seed, variant="cw")


@contextlib.contextmanager
def compiles_started() -> Iterator[list[tuple[str, tuple[Any, ...]]]]:
    """Inside the block, the list collects ``(module:qualname, argument types)`` of every
    pipeline function numba compiles (not loads from its cache), in the order each starts."""
    from numba.core import event

    started: list[tuple[str, tuple[Any, ...]]] = []

    class Listener(event.Listener):
        def on_start(self, ev: event.Event) -> None:
            data = ev.data
            if data["dispatcher"].py_func.__module__.startswith("pipeline."):
                started.append((dispatcher_name(data["dispatcher"]), tuple(data["args"])))

        def on_end(self, ev: event.Event) -> None:
            pass

    with event.install_listener("numba:compile", Listener()):
        yield started


def record(filter_name: str) -> dict[str, Any]:
    """Run ``filter_name`` on ``plan_drive()`` and record what its kernel compile compiles, in
    order (run in a process with an empty numba cache: ``record_cold``)."""
    from pipeline.estimation.config import FILTER_KINDS
    from pipeline.estimation.replay import kernel_for, run_filter
    from pipeline.params import load_params

    drive = plan_drive()
    section = load_params(REPO_PARAMS).filters.get(filter_name)
    kernel = kernel_for(FILTER_KINDS[filter_name], "numba")
    with compiles_started() as started:
        run_filter(dict(drive.tables), drive.sensors, filter_name, section)
    name = dispatcher_name(kernel)
    kernel_args = [args for n, args in started if n == name]
    if len(kernel_args) != 1:
        raise RuntimeError(f"{filter_name}: the kernel compiled {len(kernel_args)} times, not once")
    callees, skipped = [], []
    for n, args in started:
        if n == name:
            continue
        try:
            callees.append([n, list(format_types(args))])
        except ValueError as e:  # the helper cannot compile it; the replay will
            skipped.append(f"{n}: {e}")
    return {
        "kernel": name,
        "args": list(format_types(kernel_args[0])),
        "callees": callees,
        "not_in_plan": skipped,
    }


def record_cold(filter_name: str) -> dict[str, Any]:
    """``record`` in a fresh process with an empty numba cache and no helper."""
    with tempfile.TemporaryDirectory(prefix="navreplay-plan-") as tmp:
        env = dict(os.environ, NUMBA_CACHE_DIR=tmp, **{ENV_SWITCH: "0"})
        done = subprocess.run(
            [sys.executable, "-m", "pipeline.estimation.compile_helper", "--record", filter_name],
            env=env, capture_output=True, text=True, check=False,
        )  # fmt: skip
    if done.returncode != 0:
        raise RuntimeError(f"recording {filter_name} failed:\n{done.stderr}")
    recorded: dict[str, Any] = json.loads(done.stdout.strip().splitlines()[-1])
    return recorded


def build_plan(filter_names: Sequence[str], progress: Callable[[str], None]) -> dict[str, Any]:
    """The plan of ``filter_names``; filters whose kernels compile alike share an entry."""
    import numba

    filters: dict[str, str] = {}
    kernels: dict[str, dict[str, Any]] = {}
    for name in filter_names:
        progress(f"recording {name} (a cold compile)")
        rec = record_cold(name)
        key = next((k for k, v in kernels.items() if v == rec), name)
        kernels.setdefault(key, rec)
        filters[name] = key
    return {
        "about": f"what cold kernel compiles compile, in order; written by {WRITE_COMMAND}",
        "numba": numba.__version__,
        "filters": filters,
        "kernels": kernels,
    }


def write_plan(path: Path, plan: dict[str, Any]) -> None:
    """Write ``plan`` to ``path`` atomically."""
    text = json.dumps(plan, indent=1) + "\n"
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    tmp.replace(path)


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m pipeline.estimation.compile_helper",
        description="The cold-compile helper of navreplay run (see the module docstring). "
        "Given a filter name: compile its kernel's callees into numba's cache, from the last "
        "to the first (what navreplay run starts by itself). --write-plan: record the plan "
        "from cold compiles of every filter (a few minutes).",
    )
    ap.add_argument("filter", nargs="?", help="compile this filter's callees (the helper)")
    ap.add_argument("--plan", type=Path, default=PLAN_PATH, help="the plan file")
    ap.add_argument("--report", type=Path, help="append the names compiled here to this file")
    ap.add_argument("--claims", type=Path, help="the directory of claims shared with the replay")
    ap.add_argument("--record", metavar="FILTER", help="print one filter's plan entry as JSON")
    ap.add_argument("--write-plan", action="store_true", help="record and write the plan")
    ap.add_argument(
        "--only", action="append", metavar="FILTER",
        help="with --write-plan: record only this filter (repeat for more), keep the others",
    )  # fmt: skip
    a = ap.parse_args(argv)
    if a.filter is not None and not (a.record or a.write_plan):
        run_helper(a.filter, a.plan, a.report, Claims(a.claims) if a.claims else None)
        return 0  # the helper: no more imports than its compiles need
    from pipeline.estimation.config import FILTER_KINDS

    unknown = sorted(set(a.only or ()) - set(FILTER_KINDS))
    if unknown:
        ap.error(f"--only {', '.join(unknown)}: not a filter (known: {', '.join(FILTER_KINDS)})")
    if a.record:
        print(json.dumps(record(a.record)))
        return 0
    if not a.write_plan:
        ap.error("give a filter name, --record FILTER or --write-plan")
    names = a.only or list(FILTER_KINDS)
    plan = build_plan(names, lambda s: print(s, file=sys.stderr, flush=True))
    if a.only and a.plan.exists():  # update those filters' entries, keep the others
        old = json.loads(a.plan.read_text())
        kernels = {k: v for k, v in old["kernels"].items() if k not in plan["filters"].values()}
        filters = {f: k for f, k in old["filters"].items() if f not in plan["filters"]}
        merged = {**filters, **plan["filters"]}
        plan["filters"] = {f: merged[f] for f in FILTER_KINDS if f in merged}
        both = {**kernels, **plan["kernels"]}
        plan["kernels"] = {k: both[k] for k in dict.fromkeys(plan["filters"].values())}
    write_plan(a.plan, plan)
    print(f"wrote {a.plan}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
