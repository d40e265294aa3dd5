"""Rank filters across datasets, with paired differences and confidence intervals.

Reads REPORT_DIR/tables/runs.json and sat_reduction.csv of each dataset report; writes
DIR/index.html, DIR/tables/{ranking,paired,sat_reduction}.csv and DIR/metrics.json.

examples:
  navreplay summarize reports/seoul_campus_cw reports/tractor_straight --out reports/summary
"""

from __future__ import annotations

import argparse
from pathlib import Path

from navreplay.pipeline.stages.options import add_out


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "reports", nargs="+", type=Path, metavar="REPORT_DIR", help="per-dataset report directories"
    )
    add_out(parser, "summary directory")


def run(args: argparse.Namespace) -> int:
    from navreplay.pipeline.report.summary import render_summary

    index = render_summary(args.reports, args.out)
    print(f"summary: {index}")
    return 0
