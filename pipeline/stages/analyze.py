"""One-off post-mission analysis of a log that is not in the DVC registry.

Ingests LOG (and any companion files), runs the default filters under the default scenarios,
and renders a report into DIR, showing progress on the long steps and a summary at the end.

examples:
  navreplay analyze flight.bin --out analysis/flight
  navreplay analyze drive.mcap --filters lc_ekf,tc_ukf_nhc --scenarios nominal,outage_60s --out a/
"""

from __future__ import annotations

import argparse
from pathlib import Path

from pipeline.errors import NotBuiltError


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "logs", nargs="+", type=Path, metavar="LOG", help="log file(s) of one drive or flight"
    )
    parser.add_argument(
        "--out",
        type=Path,
        required=True,
        metavar="DIR",
        help="output directory (tables, runs and the report)",
    )
    parser.add_argument(
        "--filters",
        metavar="A,B",
        help="comma-separated filter names (default: those in params.yaml)",
    )
    parser.add_argument(
        "--scenarios",
        metavar="X,Y",
        help="comma-separated scenario names (default: those in params.yaml)",
    )
    parser.add_argument(
        "--dataset-config",
        type=Path,
        metavar="YAML",
        help="dataset descriptor for the log (see `navreplay ingest --help`)",
    )
    parser.add_argument(
        "--params",
        type=Path,
        default=Path("params.yaml"),
        help="parameter file (default: params.yaml)",
    )


def run(args: argparse.Namespace) -> int:
    raise NotBuiltError(
        "one-off analysis arrives with the issue 'Per-dataset HTML reports'; nothing was written"
    )
