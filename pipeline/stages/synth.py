"""Generate a synthesized dataset with exact truth, written as real log files.

Datasets: seoul_campus_cw, seoul_campus_ccw (paper 001 land-vehicle drive), tractor_straight
(paper 000), fwekf_reference (paper 004), car_speed_ramp (paper 003), multirotor_flight (a
quadrotor that hovers, yaws in place, flies sideways, backwards and figure eights) and
bench_static (the same quadrotor at rest on a bench without a GPS fix), and the campus car on
other drives: car_rolling_start, car_parking_reverse, car_stop_and_go. Parameters and the seed
come from the `synth` section of the parameter file; the same seed gives byte-identical files.

examples:
  navreplay synth seoul_campus_cw --out datasets/seoul_campus_cw/raw
"""

from __future__ import annotations

import argparse
import importlib
import logging
import time
from pathlib import Path

from navreplay.pipeline.errors import NotBuiltError, PipelineError
from navreplay.pipeline.stages.options import add_out, add_params

log = logging.getLogger(__name__)


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("name", metavar="NAME", help="synthesized dataset id")
    add_out(parser, "output directory for the log files and truth")
    add_params(parser)


def run(args: argparse.Namespace) -> int:
    from navreplay.pipeline.params import load_params
    from navreplay.pipeline.synth import DATASETS

    params = load_params(args.params)
    name = str(args.name)
    if name not in DATASETS:
        known = ", ".join(sorted(DATASETS))
        if name in params.datasets:
            raise NotBuiltError(f"no synthesizer for {name!r} yet (built: {known})")
        raise PipelineError(f"unknown synthesized dataset {name!r} (known: {known})")
    start = time.perf_counter()
    module = importlib.import_module(DATASETS[name])
    paths = module.write_dataset(name, params.synth, Path(args.out))
    log.info(
        "%s written to %s in %.1f s: %s",
        name,
        args.out,
        time.perf_counter() - start,
        ", ".join(p.name for p in paths),
    )
    return 0
