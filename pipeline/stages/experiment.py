"""Run an experiment of the parameter file and write its data tables and figures.

Experiments: tractor_cascaded (paper 000: the cascaded EKF, UKF and hybrid filters steering
the simulated tractor in closed loop; bias convergence, tracking error, GPS-outage drift,
Monte Carlo with confidence intervals, the paper's claims beside ours). Parameters come from
`experiments.<name>`, the filters' sections and `synth`; the output folder is replaced
atomically, and everything but timing.json is byte-identical for the same parameters.

examples:
  navreplay experiment tractor_cascaded --out datasets/tractor_straight/experiments
"""

from __future__ import annotations

import argparse
import logging
import time
from pathlib import Path

log = logging.getLogger(__name__)

EXPERIMENTS = ("tractor_cascaded",)


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("name", choices=EXPERIMENTS, metavar="NAME", help="experiment name")
    parser.add_argument(
        "--params",
        type=Path,
        default=Path("params.yaml"),
        help="parameter file (default: params.yaml)",
    )
    parser.add_argument(
        "--out", type=Path, required=True, metavar="DIR", help="output directory (replaced)"
    )


def run(args: argparse.Namespace) -> int:
    from pipeline.estimation.cascaded.artifacts import write_experiment
    from pipeline.estimation.cascaded.config import CASCADED_KINDS
    from pipeline.estimation.cascaded.experiments import ExperimentInputs
    from pipeline.params import load_params

    params = load_params(args.params)
    exp = params.experiments.tractor_cascaded
    inputs = ExperimentInputs(
        sim=params.synth.tractor_straight,
        sections={n: params.filters.section(n) for n in CASCADED_KINDS},
        exp=exp,
        seed=params.synth.seed,
    )
    t0 = time.perf_counter()
    doc = write_experiment(args.out, inputs, params.report.figure_dpi)
    verdicts = ", ".join(f"{r['verdict']}" for r in doc["paper_comparison"])
    print(
        f"tractor_cascaded: {doc['runs']} closed-loop runs ({len(doc['labels'])} filter "
        f"variants, {len(doc['scenarios'])} scenarios, {exp.seeds} seeds) in "
        f"{time.perf_counter() - t0:.0f} s -> {args.out}\npaper's claims: {verdicts}"
    )
    return 0
