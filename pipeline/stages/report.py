"""Render the self-contained HTML report of one dataset from its tables, runs and experiments.

Reads TABLES (meta.json, ingest_report.json, truth and gnss tables), every run directory
under RUNS (any directory with a metrics.json) and every experiment directory under
EXPERIMENTS; writes DIR/index.html, DIR/tables/*.csv|json and DIR/metrics.json atomically.
Missing runs or experiments leave their sections out; a malformed file is an error naming it.

examples:
  navreplay report seoul_campus_cw --tables datasets/seoul_campus_cw/tables \\
      --runs datasets/seoul_campus_cw/runs --out reports/seoul_campus_cw
"""

from __future__ import annotations

import argparse
from pathlib import Path


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("dataset", metavar="DATASET", help="dataset id")
    parser.add_argument(
        "--tables",
        type=Path,
        required=True,
        metavar="DIR",
        help="the dataset's canonical tables (for the audit and truth)",
    )
    parser.add_argument(
        "--runs",
        type=Path,
        metavar="DIR",
        help="directory holding the dataset's run directories (default: TABLES/../runs)",
    )
    parser.add_argument(
        "--experiments",
        type=Path,
        metavar="DIR",
        help="directory of the dataset's experiments (default: TABLES/../experiments)",
    )
    parser.add_argument(
        "--out",
        type=Path,
        required=True,
        metavar="DIR",
        help="report directory (index.html, tables/, metrics.json)",
    )
    parser.add_argument(
        "--params",
        type=Path,
        default=Path("params.yaml"),
        help="parameter file (default: params.yaml)",
    )


def run(args: argparse.Namespace) -> int:
    from navreplay.ingest.tables import params_hash
    from navreplay.ingest.typed import to_plain
    from navreplay.pipeline.params import load_params
    from navreplay.pipeline.report.inputs import load_dataset
    from navreplay.pipeline.report.render import render_dataset

    params = load_params(args.params)
    runs = args.runs or args.tables.parent / "runs"
    experiments = args.experiments or args.tables.parent / "experiments"
    data = load_dataset(args.dataset, args.tables, runs, experiments)
    out = render_dataset(
        data,
        args.out,
        experiments_dir=experiments,
        params_hash=params_hash(to_plain(params)),
    )
    print(f"{args.dataset}: {out.index} ({len(out.runs)} runs, {out.figures} figures)")
    return 0
