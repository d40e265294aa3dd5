"""Render the self-contained HTML report of one dataset from its runs.

examples:
  navreplay report seoul_campus_cw --tables datasets/seoul_campus_cw/tables \
      --runs datasets/seoul_campus_cw/runs --out reports/seoul_campus_cw
"""

from __future__ import annotations

import argparse
from pathlib import Path

from pipeline.errors import NotBuiltError


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
        required=True,
        metavar="DIR",
        help="directory holding the dataset's run directories",
    )
    parser.add_argument(
        "--out",
        type=Path,
        required=True,
        metavar="DIR",
        help="report directory (index.html, tables/, figures)",
    )
    parser.add_argument(
        "--params",
        type=Path,
        default=Path("params.yaml"),
        help="parameter file (default: params.yaml)",
    )


def run(args: argparse.Namespace) -> int:
    raise NotBuiltError(
        "reports arrive with the issue 'Per-dataset HTML reports'; nothing was written"
    )
