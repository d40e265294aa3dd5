"""List the reports the pipeline has generated (what `make demo` prints at the end)."""

from __future__ import annotations

import argparse
from pathlib import Path


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--root", type=Path, default=Path("reports"), help="reports directory (default: reports)"
    )


def run(args: argparse.Namespace) -> int:
    pages = sorted(args.root.glob("*/index.html"))
    if not pages:
        print(f"No reports under {args.root}/ yet; run `dvc repro` (or `make demo`).")
        return 1
    print("Reports:")
    for page in pages:
        print(f"  {page.resolve()}")
    return 0
