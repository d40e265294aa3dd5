"""Run the speed benchmarks and print side-by-side ratios against the reference backends.

The benchmarks live in benchmarks/ of the source checkout (also `make bench`); each prints
its own table, measured against its reference in the same run. Options after the names are
passed to the benchmarks (see `python -m benchmarks --help`).

examples:
  navreplay bench
  navreplay bench ros_ingest --ros-imu-messages 500000
  navreplay bench ingest_memory --memory-log-mb 2048
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

from navreplay.pipeline.errors import PipelineError


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "args",
        nargs=argparse.REMAINDER,
        metavar="NAME|OPTION",
        help="benchmarks to run (default: all) and their options",
    )


def checkout_root() -> Path:
    """The source checkout holding benchmarks/ (the package is installed editable from it)."""
    return Path(__file__).resolve().parents[2]


def run(args: argparse.Namespace) -> int:
    root = checkout_root()
    if not (root / "benchmarks" / "__main__.py").is_file():
        raise PipelineError(
            f"no benchmarks/ beside the installed package ({root}): run from a source checkout"
        )
    done = subprocess.run([sys.executable, "-m", "benchmarks", *args.args], cwd=root, check=False)
    return done.returncode
