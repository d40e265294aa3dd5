"""Compile every filter ahead of its first run (numba's on-disk cache).

The first run of a filter after installing or changing navreplay compiles its replay loop,
10-30 s per filter; later runs load it from the cache in about a second. `navreplay warm`
compiles them all now: it replays each filter over a short synthesized drive of its kind,
one process per compiled kernel, --jobs at a time. `dvc repro` runs it as its first stage and
`make demo` through it. The cache lives in ~/.cache/navreplay/numba-<digest of the compiled
sources> (or NUMBA_CACHE_DIR): editing a filter's code starts a fresh one, editing a report
does not.

examples:
  navreplay warm                      # every filter
  navreplay warm --filter tc_ukf      # one filter
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from navreplay.pipeline.errors import ParamsError, PipelineError
from navreplay.pipeline.stages.options import add_params


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--filter",
        action="append",
        metavar="NAME",
        help="warm only this filter; repeat for several (default: every filter)",
    )
    add_params(parser, "the filters' settings and the warm-up drives' synthesizers")
    parser.add_argument(
        "--jobs",
        type=int,
        default=min(2, os.cpu_count() or 1),
        help="kernels compiled at once, one process each (default: min(2, cores))",
    )
    parser.add_argument(
        "--stamp",
        type=Path,
        metavar="FILE",
        help="after success, write FILE (JSON: the cache's source digest and the filters "
        "warmed); dvc.yaml's later stages depend on it, so they run after the warm-up",
    )
    parser.add_argument("--in-process", action="store_true", help=argparse.SUPPRESS)


def run(args: argparse.Namespace) -> int:
    from navreplay.pipeline.params import load_params, params_label
    from navreplay.pipeline.warm import WarmResult, groups, warm, warm_here

    params = load_params(args.params)
    try:
        todo = groups(args.filter)
    except KeyError as err:
        raise ParamsError("--filter", str(err.args[0]), source=params_label(args.params)) from err
    if args.in_process:
        warm_here([n for g in todo for n in g], params)
        return 0
    print(f"warming {len(todo)} kernels ({sum(map(len, todo))} filters), {args.jobs} at a time")

    def progress(result: WarmResult, k: int, n: int) -> None:
        state = "compiled" if result.error is None else f"FAILED: {result.error}"
        print(f"  [{k}/{n}] {', '.join(result.filters)}: {state} ({result.wall_s:.1f} s)")

    results = warm(args.params, args.filter, jobs=args.jobs, progress=progress)
    failed = [r for r in results if r.error is not None]
    if failed:
        names = ", ".join(n for r in failed for n in r.filters)
        raise PipelineError(f"could not warm {names}; their first run will compile (and fail)")
    if args.stamp is not None:
        from navreplay.ingest.atomic import atomic_write_json
        from navreplay.pipeline._numba_cache import installed_digest

        stamp = {"numba_source_digest": installed_digest(), "filters": [list(g) for g in todo]}
        atomic_write_json(args.stamp, stamp)
    return 0
