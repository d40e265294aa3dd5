"""The options most stages share: the parameter file and the output directory."""

from __future__ import annotations

import argparse
from pathlib import Path

PARAMS_HELP = (
    "parameter file laid over the built-in defaults (default: ./params.yaml when present, "
    "else the built-in defaults alone; `navreplay params` prints the effective ones)"
)


def add_params(parser: argparse.ArgumentParser, help: str = "") -> None:
    """``--params FILE``: the parameter file (``args.params``; None: see ``PARAMS_HELP``)."""
    text = f"{help}: {PARAMS_HELP}" if help else PARAMS_HELP
    parser.add_argument("--params", type=Path, default=None, metavar="FILE", help=text)


def add_dir(
    parser: argparse.ArgumentParser, flag: str, help: str, *, required: bool = False
) -> None:
    """``FLAG DIR``: a directory the stage reads or writes (a ``Path``)."""
    parser.add_argument(flag, type=Path, required=required, metavar="DIR", help=help)


def add_out(parser: argparse.ArgumentParser, help: str, *, required: bool = True) -> None:
    """``--out DIR``: the stage's output directory (``args.out``)."""
    add_dir(parser, "--out", help, required=required)


def add_scheduler(parser: argparse.ArgumentParser | argparse._ArgumentGroup) -> None:
    """``--scheduler WHERE``: where the stage's tasks run (``args.scheduler``; None: the
    ``NAVREPLAY_SCHEDULER`` environment variable, else ``compute.scheduler`` in the params)."""
    parser.add_argument(
        "--scheduler",
        metavar="WHERE",
        help="where the tasks run: processes (forked workers of this process), local (a Dask "
        "cluster on this machine) or a Dask scheduler's address, tcp://HOST:PORT or "
        "tls://HOST:PORT (default: $NAVREPLAY_SCHEDULER, else compute.scheduler in the "
        "params: processes)",
    )


def add_analysis_options(parser: argparse.ArgumentParser, *, what: str = "") -> None:
    """What `analyze` and `fleet` run on a log: ``--filters``, ``--scenarios``, ``--outage``
    (repeatable) and ``--smooth`` (``args.filters``, ``args.scenarios``: comma-separated text,
    see ``split_names``); ``what``: to whom the outages apply (e.g. " on every log")."""
    parser.add_argument(
        "--filters",
        metavar="A,B",
        help="comma-separated filter names (default: run.filters in params.yaml)",
    )
    parser.add_argument(
        "--scenarios",
        metavar="X,Y",
        help="comma-separated scenario names (default: run.scenarios in params.yaml)",
    )
    parser.add_argument(
        "--outage",
        action="append",
        default=[],
        metavar="LEN[@START]",
        help=f"also run a complete GNSS outage{what}: LEN (as many windows as fit, e.g. 30s) or "
        "LEN@START (one window, START seconds after the first IMU sample, e.g. 30s@45s); repeat "
        "for several",
    )
    parser.add_argument(
        "--smooth",
        action="store_true",
        help="also smooth every INS filter's runs (Rauch-Tung-Striebel: the best trajectory the "
        "log allows, shown beside each filter; on a log without truth the outage drift is then "
        "measured against the smoothed nominal run)",
    )


def split_names(text: str | None) -> list[str] | None:
    """``a, b`` -> ``["a", "b"]``; None (the params' default) for no text."""
    return [t.strip() for t in text.split(",") if t.strip()] if text else None
