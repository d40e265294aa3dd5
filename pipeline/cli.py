"""The ``navreplay`` command line: a thin shell over the stage modules.

Each subcommand lives in ``pipeline.stages.<name>`` with two functions, ``configure(parser)``
(arguments only, cheap imports) and ``run(args) -> int`` (the work). The DVC stages in
``dvc.yaml`` call these same subcommands, so a one-off run and the pipeline share one code path.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys
from collections.abc import Sequence
from typing import Protocol, cast

from navreplay.ingest.errors import IngestError
from navreplay.pipeline._numba_cache import fewer_gc_passes
from navreplay.pipeline.errors import NotBuiltError, PipelineError

log = logging.getLogger("navreplay")

EXIT_ERROR = 2
EXIT_NOT_BUILT = 3
EXIT_INTERRUPTED = 130

# name -> (module, one-line help). Order is the order shown by --help.
COMMANDS: dict[str, tuple[str, str]] = {
    "ingest": (
        "navreplay.pipeline.stages.ingest",
        "convert logs (MCAP, ROS bags, tlog, DataFlash, ULog, RINEX, CSV) to tables",
    ),
    "warm": (
        "navreplay.pipeline.stages.warm",
        "compile every filter now, so that its first run loads it from the cache",
    ),
    "run": (
        "navreplay.pipeline.stages.run",
        "replay a filter over canonical tables under scenarios",
    ),
    "montecarlo": (
        "navreplay.pipeline.stages.montecarlo",
        "replay one filter under outages drawn over the drive (Monte Carlo)",
    ),
    "outages": (
        "navreplay.pipeline.stages.outages",
        "reduction per satellite count and drift vs outage length from the Monte Carlo",
    ),
    "analyze": (
        "navreplay.pipeline.stages.analyze",
        "one-off post-mission analysis of a log: ingest + filters + report",
    ),
    "fleet": (
        "navreplay.pipeline.stages.fleet",
        "analyze many logs (a report each) and summarize the fleet, locally or on a Dask cluster",
    ),
    "synth": ("navreplay.pipeline.stages.synth", "generate a synthesized dataset with exact truth"),
    "experiment": (
        "navreplay.pipeline.stages.experiment",
        "run a paper experiment (tables + figures; Monte Carlo where the paper's claims need it)",
    ),
    "report": ("navreplay.pipeline.stages.report", "render the HTML report of one dataset"),
    "summarize": ("navreplay.pipeline.stages.summarize", "rank filters across datasets"),
    "bench": (
        "navreplay.pipeline.stages.bench",
        "run the speed benchmarks against reference backends",
    ),
    "export": (
        "navreplay.pipeline.stages.export",
        "a table or run as flat CSV (PlotJuggler) or a TUM trajectory (evo)",
    ),
    "where-reports": ("navreplay.pipeline.stages.where_reports", "list the generated reports"),
    "params": (
        "navreplay.pipeline.stages.params",
        "print the parameters in force (built-in defaults, ./params.yaml or --params over them)",
    ),
}


class _Stage(Protocol):
    def configure(self, parser: argparse.ArgumentParser) -> None: ...

    def run(self, args: argparse.Namespace) -> int: ...


def _stage(name: str) -> _Stage:
    return cast(_Stage, importlib.import_module(COMMANDS[name][0]))


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="navreplay",
        description=(
            "Replay recorded vehicle and drone logs through GPS/INS filters under injected GNSS "
            "outages and reduced satellite counts, and report how far each filter drifts. "
            "`dvc repro` runs the whole pipeline over the datasets in params.yaml; these "
            "subcommands run its steps one at a time."
        ),
        epilog="Run `navreplay COMMAND --help` for the options of each command.",
    )
    verbosity = parser.add_mutually_exclusive_group()
    verbosity.add_argument("-v", "--verbose", action="store_true", help="log debug detail")
    verbosity.add_argument("-q", "--quiet", action="store_true", help="log warnings only")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name, (_, help_text) in COMMANDS.items():
        stage = _stage(name)
        p = sub.add_parser(
            name,
            help=help_text,
            description=(stage.__doc__ or help_text).strip(),
            formatter_class=argparse.RawDescriptionHelpFormatter,
        )
        stage.configure(p)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``navreplay`` console script; returns the process exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.WARNING if args.quiet else logging.INFO,
        format="%(levelname)s %(name)s: %(message)s",
    )
    try:
        with fewer_gc_passes():  # the stages' imports and kernel compiles: see there
            return _stage(args.command).run(args)
    except NotBuiltError as err:
        print(f"navreplay {args.command}: not built yet: {err}", file=sys.stderr)
        return EXIT_NOT_BUILT
    except (IngestError, PipelineError) as err:
        print(f"navreplay {args.command}: error: {err}", file=sys.stderr)
        return EXIT_ERROR
    except KeyboardInterrupt:
        print(
            f"navreplay {args.command}: interrupted; nothing partial was left behind",
            file=sys.stderr,
        )
        return EXIT_INTERRUPTED


if __name__ == "__main__":
    sys.exit(main())
