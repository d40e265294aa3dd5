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

from navreplay.pipeline.stages.options import add_dir, add_out, add_params


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("dataset", metavar="DATASET", help="dataset id")
    add_dir(
        parser,
        "--tables",
        "the dataset's canonical tables (for the audit and truth)",
        required=True,
    )
    add_dir(
        parser,
        "--runs",
        "directory holding the dataset's run directories (default: TABLES/../runs)",
    )
    add_dir(
        parser,
        "--experiments",
        "directory of the dataset's experiments (default: TABLES/../experiments)",
    )
    add_out(parser, "report directory (index.html, tables/, metrics.json)")
    add_params(parser)


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
