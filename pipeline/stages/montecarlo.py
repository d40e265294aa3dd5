"""Monte Carlo over outage placements and seeds for one filter on one dataset.

Draws window starts (params.yaml `outages`: seeds x windows_per_seed, uniform over the drive)
and replays each as partial outages keeping k satellites (outages.sats, 60 s) and complete
outages of each length (outages.lengths_s), every one from the nominal run's state just
before the window (see pipeline/outages/montecarlo.py), spread over outages.workers
processes (or, with --scheduler, a Dask cluster: `compute` in params.yaml). Writes DIR
atomically: windows.parquet (one row per window start and case: seed, window, start_s,
length_s, sats, the window's drift metrics), plan.json (the draw and the parameters) and
timing.json (wall and replay times; the only file that is not byte-stable). A window start
whose replay raises is listed with its traceback in plan.json "failed", the others are
written, and the exit status is 4. Finished starts are kept in .DIR.tasks beside DIR until
DIR is written, so a rerun of an interrupted Monte Carlo replays only what is missing.
With --skip-unfit, a filter the tables cannot drive (a tightly coupled one on a log without
raw observables) writes DIR/skipped.json with the reason instead, and `navreplay outages`
leaves it, and the pairs that need it, out of the tables.

examples:
  navreplay montecarlo datasets/seoul_campus_cw/tables --filter tc_ukf \\
      --out datasets/seoul_campus_cw/montecarlo/tc_ukf
  navreplay montecarlo datasets/seoul_campus_cw/tables --filter tc_ukf \\
      --scheduler tcp://10.0.0.5:8786 --out datasets/seoul_campus_cw/montecarlo/tc_ukf
"""

from __future__ import annotations

import argparse
import logging
import shutil
import sys
from pathlib import Path
from typing import Any

from navreplay.pipeline.errors import ParamsError
from navreplay.pipeline.stages.options import add_out, add_params, add_scheduler

log = logging.getLogger(__name__)

#: The exit status when some window starts failed (the others are written).
EXIT_TASKS_FAILED = 4


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("tables", type=Path, metavar="TABLES_DIR", help="canonical tables")
    parser.add_argument("--filter", required=True, metavar="NAME", help="INS/GNSS filter")
    add_params(parser, "parameters")
    parser.add_argument(
        "--backend", choices=("numba", "filterpy"), help="override run.backend from the params"
    )
    parser.add_argument("--workers", type=int, help="override outages.workers")
    add_scheduler(parser)
    parser.add_argument(
        "--skip-unfit",
        action="store_true",
        help="if the tables cannot drive this filter (a tightly coupled one without raw "
        "observables), write DIR/skipped.json with the reason and exit 0 instead of failing",
    )
    add_out(parser, "output dir")


def run(args: argparse.Namespace) -> int:
    import pyarrow.parquet as pq

    from navreplay.ingest.atomic import atomic_directory, atomic_write_json
    from navreplay.ingest.typed import to_plain
    from navreplay.pipeline.compute import TaskStore, resolve_scheduler, stderr_progress
    from navreplay.pipeline.estimation.core.contract import RunInputs
    from navreplay.pipeline.estimation.ins.run import INPUTS
    from navreplay.pipeline.outages.montecarlo import (
        SKIPPED,
        cases_for,
        draw_starts,
        run_montecarlo,
        windows_table,
    )
    from navreplay.pipeline.params import load_params, params_label
    from navreplay.pipeline.scenarios.apply import log_span

    params = load_params(args.params)
    o = params.outages
    try:
        section = params.filters.get(args.filter)
    except KeyError as err:
        raise ParamsError(
            f"filters.{args.filter}", str(err.args[0]), source=params_label(args.params)
        ) from err
    if args.skip_unfit:
        from navreplay.pipeline.analyze import plan as fit_plan

        _, unfit = fit_plan(args.tables, [args.filter])
        if unfit:
            reason = unfit[0].reason
            with atomic_directory(args.out) as tmp:
                atomic_write_json(
                    tmp / SKIPPED, {"filter": args.filter, "status": "skipped", "reason": reason}
                )
            print(f"{args.filter}: skipped ({reason}) -> {args.out}")
            return 0
    inputs = RunInputs.read(args.tables, INPUTS)
    t0, t_end = log_span(inputs.tables)
    cases = cases_for(o.sats, o.sats_window_s, o.lengths_s)
    longest = max(c.length_s for c in cases)
    try:
        starts = draw_starts(
            o.seeds, o.windows_per_seed, t0, t_end, o.earliest_s, longest, o.tail_s
        )
    except ValueError as err:
        raise ParamsError("outages.earliest_s", str(err), source=params_label(args.params)) from err
    scheduler = resolve_scheduler(args.scheduler, params.compute)
    # finished starts are kept beside DIR until DIR is written: a rerun of an interrupted
    # Monte Carlo replays only the starts that are missing
    store: TaskStore[list[dict[str, Any]]] = TaskStore(
        args.out.parent / f".{args.out.name}.tasks",
        _fingerprint(args, params, section, inputs.dataset),
    )
    rows, timing, failed = run_montecarlo(
        inputs.tables,
        inputs.sensors,
        inputs.lever_b,
        args.filter,
        section,
        starts,
        cases,
        policy=o.policy,
        tail_s=o.tail_s,
        mask_deg=params.scenarios.selection_mask_deg,
        metrics=params.scenarios.metrics,
        backend=args.backend or params.run.backend,
        workers=args.workers or o.workers,
        scheduler=scheduler,
        compute=params.compute,
        store=store,
        progress=stderr_progress,
    )
    plan = {
        "dataset": inputs.dataset,
        "filter": args.filter,
        "t0_ns": t0,
        "starts": [{"seed": s.seed, "window": s.window, "start_t_ns": s.start_ns} for s in starts],
        "cases": [{"length_s": c.length_s, "sats": c.sats} for c in cases],
        "outages": to_plain(o),
        "window_metrics": to_plain(params.scenarios.metrics),
        "diverged": sum(r["status"] != "ok" for r in rows),
        "failed": [f.to_json() for f in failed],
    }
    with atomic_directory(args.out) as tmp:
        pq.write_table(windows_table(rows), tmp / "windows.parquet", compression="zstd")
        atomic_write_json(tmp / "plan.json", plan)
        atomic_write_json(tmp / "timing.json", timing)
    shutil.rmtree(store.directory.parent, ignore_errors=True)  # ours; DIR holds it all now
    rate = timing["replayed_s"] / timing["replay_wall_s"] if timing["replay_wall_s"] else 0.0
    print(
        f"{args.filter} on {inputs.dataset}: {len(starts)} windows x {len(cases)} cases = "
        f"{len(rows)} replays ({timing['replayed_s']:.0f} s of log) in "
        f"{timing['replay_wall_s']:.1f} s ({rate:.0f}x real time), "
        f"{plan['diverged']} diverged -> {args.out}"
    )
    if failed:
        for f in failed:
            print(f"error: window start {f.item} failed: {f.error}", file=sys.stderr)
        print(
            f"error: {len(failed)} of {len(starts)} window starts failed (plan.json 'failed' "
            "has their tracebacks); the tables hold the others",
            file=sys.stderr,
        )
        return EXIT_TASKS_FAILED
    return 0


def _fingerprint(args: argparse.Namespace, params: Any, section: Any, dataset: str) -> str:
    """What a start's result depends on: the tables (sizes and times), the filter's section,
    the outage and metric parameters, the backend."""
    from navreplay.ingest.tables import params_hash
    from navreplay.ingest.typed import to_plain

    tables = sorted(
        (p.name, p.stat().st_size, p.stat().st_mtime_ns) for p in args.tables.glob("*.parquet")
    )
    return str(
        params_hash(
            {
                "dataset": dataset,
                "tables": [list(t) for t in tables],
                "filter": args.filter,
                "section": to_plain(section),
                "outages": to_plain(params.outages),
                "scenarios": to_plain(params.scenarios),
                "backend": args.backend or params.run.backend,
            }
        )
    )
