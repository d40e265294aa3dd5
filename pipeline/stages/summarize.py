"""Rank filters across datasets, with paired differences and confidence intervals.

examples:
  navreplay summarize reports/seoul_campus_cw reports/tractor_straight --out reports/summary
"""

from __future__ import annotations

import argparse
from pathlib import Path

from pipeline.errors import NotBuiltError


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "reports", nargs="+", type=Path, metavar="REPORT_DIR", help="per-dataset report directories"
    )
    parser.add_argument("--out", type=Path, required=True, metavar="DIR", help="summary directory")
    parser.add_argument(
        "--params",
        type=Path,
        default=Path("params.yaml"),
        help="parameter file (default: params.yaml)",
    )


def run(args: argparse.Namespace) -> int:
    raise NotBuiltError(
        "the cross-dataset summary arrives with the issue 'Per-dataset HTML "
        "reports'; nothing was written"
    )
