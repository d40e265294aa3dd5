"""The options most stages share: the parameter file and the output directory."""

from __future__ import annotations

import argparse
from pathlib import Path

PARAMS_HELP = "parameter file (default: params.yaml)"


def add_params(
    parser: argparse.ArgumentParser,
    help: str = PARAMS_HELP,
    *,
    default: Path | None = Path("params.yaml"),
) -> None:
    """``--params FILE``: the parameter file (``args.params``)."""
    parser.add_argument("--params", type=Path, default=default, help=help)


def add_dir(
    parser: argparse.ArgumentParser, flag: str, help: str, *, required: bool = False
) -> None:
    """``FLAG DIR``: a directory the stage reads or writes (a ``Path``)."""
    parser.add_argument(flag, type=Path, required=required, metavar="DIR", help=help)


def add_out(parser: argparse.ArgumentParser, help: str, *, required: bool = True) -> None:
    """``--out DIR``: the stage's output directory (``args.out``)."""
    add_dir(parser, "--out", help, required=required)
