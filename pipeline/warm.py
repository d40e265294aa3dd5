"""Compile every filter's kernel into numba's on-disk cache before the first real run.

A cold first run of a filter spends 10-30 s compiling its replay loop; later runs load it from
numba's cache (``pipeline._numba_cache``) in about a second. ``warm`` pays that cost once, up
front: it replays every filter over a short synthesized drive of its family, through the same
path a real run takes (tables written and read back, ``estimation.families.run_tables``), so the
argument types it compiles for are exactly those of a real run. Nothing but numba's public
API is involved: each kernel is compiled by calling it. The INS filters are warmed smoothed,
so that the backward pass (``kernels.smoother``) is compiled as well.

Filters that share one compiled kernel (the EKFs, loose or tight, with or without NHC; the
UKFs; the vehicle-model filters; the cascaded filters) are one *group* and are warmed one
after the other in one process: the later ones load what the first compiled. Groups compile
independently, one process each, ``jobs`` at a time.
"""

from __future__ import annotations

import logging
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import dataclass, replace
from pathlib import Path

from navreplay.ingest.meta import DatasetMeta, write_meta
from navreplay.ingest.tables import Provenance, write_table
from navreplay.pipeline.errors import PipelineError
from navreplay.pipeline.params import Params

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class WarmResult:
    """One group's outcome: its filters, wall time, and the error if it failed."""

    filters: tuple[str, ...]
    wall_s: float
    error: str | None = None


def groups(names: Sequence[str] | None = None) -> list[tuple[str, ...]]:
    """The filters in compile groups (one compiled kernel each), in family order.

    ``names`` restricts them to those filters (unknown names raise ``KeyError``)."""
    from navreplay.pipeline.estimation.families import FAMILIES, filter_names
    from navreplay.pipeline.estimation.ins.config import FILTER_KINDS

    known = filter_names()
    wanted = known if names is None else tuple(names)
    for name in wanted:
        if name not in known:
            raise KeyError(f"unknown filter {name!r} (known: {', '.join(known)})")
    keyed: dict[tuple[str, ...], list[str]] = {}
    for family in FAMILIES:
        for name in family.filters:
            if name not in wanted:
                continue
            key: tuple[str, ...] = (family.name,)
            if family.name == "ins":
                kind = FILTER_KINDS[name]
                key = (family.name, kind.numba_kernel)  # loose and tight share it
            keyed.setdefault(key, []).append(name)
    return [tuple(v) for v in keyed.values()]


def _family(name: str) -> str:
    from navreplay.pipeline.estimation.families import family_of

    return family_of(name).name


def _drive(family: str, params: Params, out: Path) -> Path:
    """A short synthesized drive of ``family``'s kind, written as canonical tables to ``out``."""
    synth = params.synth
    if family == "ins":
        from navreplay.pipeline.synth.seoul_campus import simulate

        sp = replace(synth.seoul_campus, duration_s=40.0, stationary_s=10.0)
        result = simulate(sp, seed=synth.seed, variant="cw")
    elif family == "vehicle":
        from navreplay.pipeline.synth.car import synthesize as car

        result = car(replace(synth.car_speed_ramp, ramp_s=20.0, hold_s=10.0), synth.seed)
    else:
        from navreplay.pipeline.synth.tractor_log import synthesize as tractor

        result = tractor(replace(synth.tractor_straight, duration_s=20.0), synth.seed)
    for name, table in result.tables.items():
        prov = Provenance.create(name, sources=[], params=None, extra={"synthesizer": "warm"})
        write_table(out / f"{name}.parquet", name, table, prov)
    tables = {name: t.num_rows for name, t in sorted(result.tables.items())}
    write_meta(out, DatasetMeta(f"warm-{family}", result.time_base, (), tables, result.sensors))
    return out


def warm_here(names: Sequence[str], params: Params) -> None:
    """Compile (or load) the kernels of ``names`` in this process by running each filter once.

    Raises:
        PipelineError: a filter could not run on its warm-up drive (the message names it).
    """
    from navreplay.pipeline.errors import DivergenceError
    from navreplay.pipeline.estimation.families import run_tables
    from navreplay.pipeline.estimation.ins.config import InsFilterParams

    with tempfile.TemporaryDirectory(prefix="navreplay-warm-") as tmp:
        drives: dict[str, Path] = {}
        for name in names:
            family = _family(name)
            if family not in drives:
                drives[family] = _drive(family, params, Path(tmp) / family)
            try:
                section = params.filters.section(name)
                if isinstance(section, InsFilterParams):  # the backward pass too
                    section = replace(section, smooth=True)
                run_tables(drives[family], name, section, "numba")
            except DivergenceError:
                pass  # the kernel compiled and ran; a short drive may end off its limits
            except PipelineError as err:
                raise PipelineError(f"warm {name}: {err}") from err


def warm(
    params_path: Path | None,
    names: Sequence[str] | None = None,
    *,
    jobs: int = 2,
    progress: Callable[[WarmResult, int, int], None] | None = None,
) -> list[WarmResult]:
    """Warm every compile group of ``names`` (default: every filter) in its own process,
    ``jobs`` at a time; returns one result per group, in group order.

    The groups of one family share most of their callees (the INS model, alignment, gating),
    so a family's first group runs before its others, which then load those callees from the
    cache instead of compiling them in two processes at once; the other worker meanwhile
    compiles another family, which shares nothing with it.
    """
    todo = groups(names)
    families = [_family(g[0]) for g in todo]

    def one(group: tuple[str, ...]) -> WarmResult:
        cmd = [sys.executable, "-m", "navreplay.pipeline.cli", "-q", "warm", "--in-process"]
        if params_path is not None:
            cmd += ["--params", str(params_path)]
        for name in group:
            cmd += ["--filter", name]
        t0 = time.perf_counter()
        done = subprocess.run(cmd, capture_output=True, text=True, check=False)
        wall = time.perf_counter() - t0
        if done.returncode != 0:
            lines = (done.stderr or done.stdout).strip().splitlines()
            return WarmResult(group, wall, lines[-1] if lines else f"exit {done.returncode}")
        return WarmResult(group, wall)

    leaders = {f: families.index(f) for f in families}  # each family's first group
    results: dict[int, WarmResult] = {}
    with ThreadPoolExecutor(max_workers=max(1, jobs)) as pool:
        running = {pool.submit(one, todo[i]): i for i in leaders.values()}
        while running:
            done = next(as_completed(running))
            i = running.pop(done)
            results[i] = done.result()
            if i == leaders[families[i]]:  # the family's shared callees are in the cache
                for j, f in enumerate(families):
                    if f == families[i] and j != i:
                        running[pool.submit(one, todo[j])] = j
            if progress is not None:
                progress(results[i], len(results), len(todo))
    return [results[i] for i in range(len(todo))]
