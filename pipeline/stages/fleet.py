"""Analyze a fleet of logs: a report per log and a summary across them.

Each LOG is a log file or a folder of logs (a rosbag2 bag folder is one log; in a folder, files
sharing a stem, such as drive.obs and drive.nav, are one log, and files whose format is not
recognized, such as a README, are listed and left out). Every log is
analyzed as `navreplay analyze` would (ingest, the filters that fit, the scenarios, a report)
into DIR/logs/<name>/, one task per log: on forked workers of this process (--workers,
default run.workers) or on a Dask cluster (--scheduler local: one started on this machine;
--scheduler tcp://HOST:PORT: a running one, whose workers must reach the logs' paths). Then
DIR/index.html lists every log with the status of its runs and any GNSS trouble, the logs
that could not be analyzed and why, and the reduction per satellite count pooled over all
logs; DIR/summary/ ranks the filters across the logs. A progress line with counts and an
ETA goes to stderr. A rerun after an interruption analyzes only the logs that are missing.

Exit status: 0 when every log was analyzed, 4 when some could not be (DIR says why), 2 for
bad input or parameters.

examples:
  navreplay fleet flights/*.bin --out fleet/
  navreplay fleet flights/ --filters lc_ekf --scenarios nominal,outage_60s --out fleet/
  navreplay fleet flights/ --scheduler tcp://10.0.0.5:8786 --out fleet/
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from navreplay.pipeline.stages.options import (
    add_analysis_options,
    add_out,
    add_params,
    add_scheduler,
    split_names,
)

#: The exit status when some logs could not be analyzed.
EXIT_LOGS_FAILED = 4


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "logs", nargs="+", type=Path, metavar="LOG", help="log files or folders of logs"
    )
    add_out(parser, "output directory (a folder per log, the fleet summary)")
    add_analysis_options(parser, what=" on every log")
    parser.add_argument(
        "--workers", type=int, metavar="N", help="processes of the default engine (run.workers)"
    )
    add_scheduler(parser)
    add_params(parser)


def run(args: argparse.Namespace) -> int:
    from navreplay.pipeline.compute import resolve_scheduler, stderr_progress
    from navreplay.pipeline.fleet import fleet
    from navreplay.pipeline.params import load_params

    params = load_params(args.params)
    scheduler = resolve_scheduler(args.scheduler, params.compute)
    try:
        res = fleet(
            args.logs,
            args.out,
            params,
            filters=split_names(args.filters),
            scenarios=split_names(args.scenarios),
            outages=args.outage,
            smooth=args.smooth,
            scheduler=scheduler,
            workers=args.workers or params.run.workers,
            progress=stderr_progress,
        )
    except FileNotFoundError as err:
        print(f"navreplay fleet: error: {err}", file=sys.stderr)
        return 2
    print(f"navreplay fleet: {len(res.rows)} logs analyzed in {res.seconds:.0f} s -> {res.index}")
    for r in res.rows:
        trouble = f"; GNSS trouble: {r['gnss_trouble']}" if r["gnss_trouble"] else ""
        print(f"  {r['name']}: {r['statuses']}{trouble}")
    if res.not_logs:
        print(f"  {len(res.not_logs)} files of the folders are not logs (listed in the index)")
    for f in res.failed:
        print(f"  {f['name']}: FAILED: {f['error']}", file=sys.stderr)
    return EXIT_LOGS_FAILED if res.failed else 0
