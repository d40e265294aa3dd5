"""Run the speed benchmarks and print side-by-side ratios against the reference backends.

The benchmarks live in benchmarks/ of the source checkout (also `make bench`).
"""

from __future__ import annotations

import argparse

from pipeline.errors import NotBuiltError


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("names", nargs="*", metavar="NAME", help="benchmarks to run (default: all)")


def run(args: argparse.Namespace) -> int:
    raise NotBuiltError("benchmarks arrive with the ingest and estimation issues")
