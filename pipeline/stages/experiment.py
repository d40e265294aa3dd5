"""Run one paper experiment over ingested tables; write JSON/CSV tables and figures.

Experiments (pure functions in pipeline/experiments/):
  vehicle_bands      paper 003: the four vehicle filters per speed band, nominal and with
                     periodic GNSS outages (--tables: car_speed_ramp), and the switched/IMM
                     acceptance as paired differences over experiments.vehicle_bands.seeds
                     synthesized realizations of car_speed_ramp (paired.csv, paired_note.md)
  vehicle_switch_speed  paper 003: the switching speed of vehicle_switched, calibrated on
                     held-out realizations of car_speed_ramp (no --tables; seeds
                     synth.seed + experiments.vehicle_bands.calibration_seed_offset + i);
                     params.yaml filters.vehicle_switched.switching holds its result
  fwekf_convergence  paper 004: EKF against FWEKF from the same start, noisy and noise-free
                     (--tables: fwekf_reference, --tables-noise-free: fwekf_reference_noise_free;
                     convergence.csv/png, convergence_note.md: the paper's figures beside ours)
  fwekf_faults       paper 004 on seoul_campus: nominal, F7 multipath burst, F8 optimistic
                     accuracy, outages, lc_ekf / lc_ekf_white (alpha = 1) / fwekf (--tables:
                     seoul_campus_cw; faults.csv, faults_note.md: where the weighting helps)
  vehicle_smartloc   paper 003 on the real smartLoc drive: least-squares fixes from the
                     pseudoranges, the four vehicle filters with and without outages
                     (--tables: `navreplay ingest` of the smartLoc Input and GT files)
  tractor_cascaded   paper 000: the cascaded EKF, UKF and hybrid steering the simulated
                     tractor in closed loop (no --tables: the simulator runs each filter's
                     own trajectory); Monte Carlo with GPS outages, the paper's claims beside
                     ours (experiments.tractor_cascaded; everything but timing.json is
                     byte-identical for the same parameters)
  robustness         issue 22: every INS filter, fwekf and iae_ekf on generated drives across
                     IMU grades (tactical to phone), fix errors white or correlated (10, 60 s)
                     with the covariance given or absent, GNSS 1-10 Hz, IMU 25-400 Hz, nominal
                     and with 10/30/60 s outages (no --tables; --seeds, --first-seed,
                     --cells; runs.csv, cells.csv, acceptance.csv, note.md: RMS against the
                     raw fixes or SPP, NEES, status, recovery after the outages)

examples:
  navreplay experiment vehicle_bands --tables datasets/car_speed_ramp/tables \\
      --out datasets/car_speed_ramp/experiments/vehicle_bands
  navreplay experiment tractor_cascaded --out datasets/tractor_straight/experiments/tractor_cascaded
  navreplay experiment robustness --seeds 1 --cells "consumer tau60" --out /tmp/robustness
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from navreplay.pipeline.errors import ParamsError
from navreplay.pipeline.stages.options import add_dir, add_out, add_params, add_scheduler

if TYPE_CHECKING:
    import pyarrow as pa

    from navreplay.ingest.meta import SensorMeta
    from navreplay.pipeline.params import Params

log = logging.getLogger(__name__)

#: The exit status when some of a sweep's simulations failed (the others are written).
EXIT_TASKS_FAILED = 4

EXPERIMENTS = (
    "vehicle_bands",
    "vehicle_switch_speed",
    "fwekf_convergence",
    "fwekf_faults",
    "vehicle_smartloc",
    "tractor_cascaded",
    "robustness",
)
#: experiments that simulate instead of reading ingested tables
NO_TABLES = ("tractor_cascaded", "vehicle_switch_speed", "robustness")


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("name", choices=EXPERIMENTS, help="experiment")
    add_dir(
        parser,
        "--tables",
        "tables dir (all but tractor_cascaded, vehicle_switch_speed, robustness)",
    )
    add_dir(parser, "--tables-noise-free", "fwekf_convergence: tables of the noise-free dataset")
    add_params(parser, "parameters")
    add_out(parser, "output dir")
    robust = parser.add_argument_group("robustness")
    robust.add_argument("--seeds", type=int, default=2, metavar="N",
                        help="seeds per cell (default 2)")  # fmt: skip
    robust.add_argument("--first-seed", type=int, default=1, metavar="S",
                        help="the seeds are S .. S+N-1 (default 1; e.g. --first-seed 3 checks "
                        "a change on seeds that did not choose it)")  # fmt: skip
    robust.add_argument(
        "--cells", nargs="+", default=[], metavar="SUBSET",
        help="cell groups (base, grades, declared, rates) or label words, e.g. "
        "'consumer tau60 nocov' (default: every cell)",
    )  # fmt: skip
    robust.add_argument("--workers", type=int, default=2, metavar="N",
                        help="processes, at most 2 (default 2)")  # fmt: skip
    add_scheduler(robust)


def _read(tables_dir: Path) -> tuple[dict[str, pa.Table], SensorMeta]:
    from navreplay.ingest.meta import read_meta
    from navreplay.ingest.schema import TableName
    from navreplay.ingest.tables import read_table

    tables: dict[str, pa.Table] = {}
    for name in TableName:
        path = tables_dir / f"{name.value}.parquet"
        if path.is_file():
            tables[name.value] = read_table(path, name).table
    return tables, read_meta(tables_dir).sensors


def run(args: argparse.Namespace) -> int:
    from navreplay.ingest.atomic import atomic_write_text
    from navreplay.pipeline.experiments import (
        fwekf_faults,
        fwekf_notes,
        fwekf_paper,
        vehicle_bands,
        vehicle_paired,
        vehicle_smartloc,
    )
    from navreplay.pipeline.experiments.outputs import write_rows
    from navreplay.pipeline.params import load_params

    params = load_params(args.params)
    out: Path = args.out
    dpi = params.report.figure_dpi
    if args.name == "tractor_cascaded":
        return _tractor_cascaded(params, out)
    if args.name == "vehicle_switch_speed":
        return _vehicle_switch_speed(params, out)
    if args.name == "robustness":
        return _robustness(
            params, out, range(args.first_seed, args.first_seed + args.seeds), args.cells,
            args.workers, args.scheduler,
        )  # fmt: skip
    if args.tables is None:
        raise ParamsError("--tables", f"experiment {args.name} needs --tables DIR")
    tables, sensors = _read(args.tables)
    if args.name == "vehicle_bands":
        rows = vehicle_bands.band_table(tables, params.filters)
        write_rows(out, "bands", rows)
        vehicle_bands.band_figure(rows, out / "bands.png", dpi)
        exp = params.experiments.vehicle_bands
        seed_rows, paired = vehicle_paired.monte_carlo(
            params.synth.car_speed_ramp, params.filters, params.synth.seed, exp
        )
        write_rows(out, "paired_seeds", seed_rows)
        write_rows(out, "paired", paired, all_ok=all(c["ok"] for c in paired),
                   seeds=exp.seeds, confidence=exp.confidence,
                   equivalence_rel=exp.equivalence_rel)  # fmt: skip
        atomic_write_text(
            out / "paired_note.md",
            vehicle_paired.note(paired, exp, params.filters.vehicle("vehicle_switched").switching),
        )
        ok = sum(c["ok"] for c in paired)
        print(f"vehicle_bands: {ok}/{len(paired)} paired checks pass ({exp.seeds} seeds) -> {out}")
    elif args.name == "fwekf_convergence":
        if args.tables_noise_free is None:
            raise ParamsError("--tables-noise-free", "fwekf_convergence needs both datasets")
        nf_tables, nf_sensors = _read(args.tables_noise_free)
        rest = params.synth.fwekf_reference.alignment_s
        cases, rows = {}, []
        for case, tabs, sens in (("noisy", tables, sensors), ("noise_free", nf_tables, nf_sensors)):
            for paper_r in (False, True):
                runs = fwekf_paper.run_case(tabs, sens, params.filters, rest, paper_r=paper_r)
                tuning = "paper_r" if paper_r else "declared"
                rows += [dict(r, tuning=tuning) for r in fwekf_paper.convergence_rows(case, runs)]
                if not paper_r:
                    cases[case] = runs
        write_rows(out, "convergence", rows)
        fwekf_paper.convergence_figure(cases, out / "convergence.png", dpi)
        fz = params.filters.fwekf.fuzzy
        atomic_write_text(out / "convergence_note.md", fwekf_notes.convergence_note(rows, fz))
        print(f"fwekf_convergence: {len(rows)} rows -> {out}")
    elif args.name == "vehicle_smartloc":
        rows = vehicle_smartloc.smartloc_rows(tables, params.filters)
        write_rows(out, "smartloc", rows)
        print(f"vehicle_smartloc: {len(rows)} rows -> {out}")
    else:
        rows = fwekf_faults.fault_rows(tables, sensors, params.filters, params.synth.seed)
        write_rows(out, "faults", rows)
        fz = params.filters.fwekf.fuzzy
        atomic_write_text(out / "faults_note.md", fwekf_notes.faults_note(rows, fz))
        print(f"fwekf_faults: {len(rows)} rows -> {out}")
    return 0


def _vehicle_switch_speed(params: Params, out: Path) -> int:
    from navreplay.ingest.atomic import atomic_write_text
    from navreplay.pipeline.experiments import vehicle_switch_speed
    from navreplay.pipeline.experiments.outputs import write_rows

    exp = params.experiments.vehicle_bands
    seeds = vehicle_switch_speed.calibration_seeds(params.synth.seed, exp)
    cal_rows = vehicle_switch_speed.calibration_rows(
        params.synth.car_speed_ramp, params.filters, seeds
    )
    cal = vehicle_switch_speed.dynamic_vs_kinematic(cal_rows, exp.confidence, exp.equivalence_rel)
    up, down = vehicle_switch_speed.switch_speeds(cal)
    write_rows(out, "calibration_seeds", cal_rows)
    write_rows(out, "calibration", cal, speed_up_mps=up, speed_down_mps=down, seeds=seeds)
    atomic_write_text(out / "switch_note.md", vehicle_switch_speed.note(cal, up, down))
    print(f"vehicle_switch_speed: dynamic above {up:g} m/s, back below {down:g} -> {out}")
    return 0


def _robustness(
    params: Params, out: Path, seeds: range, subsets: list[str], workers: int, scheduler: str | None
) -> int:
    import time

    from navreplay.ingest.atomic import atomic_write_text, dumps_json
    from navreplay.pipeline.compute import TaskError, resolve_scheduler, stderr_progress
    from navreplay.pipeline.experiments.outputs import write_rows
    from navreplay.pipeline.experiments.robustness import grid as gr
    from navreplay.pipeline.experiments.robustness import sweep as sw

    if len(seeds) < 1:
        raise ParamsError("--seeds", "must be at least 1")
    if seeds.start < 0:
        raise ParamsError("--first-seed", "must be at least 0")
    cells = gr.select(gr.grid(), subsets)
    if not cells:
        raise ParamsError("--cells", f"no cell matches {subsets}; labels look like "
                          f"{gr.BASE.label()!r}, groups are {', '.join(gr.GROUPS)}")  # fmt: skip
    sweep_params = gr.SweepParams.of(
        params.synth.seoul_campus, params.synth.car_drives, params.filters
    )
    t0 = time.perf_counter()
    print(f"robustness: {len(cells)} cells x {len(seeds)} seeds x {len(sw.FILTERS)} filters ...",
          flush=True)  # fmt: skip
    failed: list[TaskError] = []
    outcomes = sw.sweep(
        sweep_params, cells, seeds, workers=workers,
        scheduler=resolve_scheduler(scheduler, params.compute), compute=params.compute,
        failed=failed, progress=stderr_progress,
    )  # fmt: skip
    filters = list(sw.FILTERS)
    write_rows(out, "runs", [o.row() for o in outcomes])
    per_cell = [dict(zip(("cell", *filters), r, strict=True))
                for r in sw.summarize(outcomes, filters)]  # fmt: skip
    write_rows(out, "cells", per_cell, legend=sw.LEGEND)
    counts = sw.pass_counts(outcomes, filters)
    heads = ("acceptance", *filters, "all")
    write_rows(out, "acceptance", [dict(zip(heads, r, strict=True)) for r in counts])
    atomic_write_text(out / "note.md", sw.note(outcomes, filters, seeds))
    print(f"robustness: {len(outcomes)} runs in {time.perf_counter() - t0:.0f} s -> {out}")
    for row in counts:
        print(f"  {row[0]}: {row[-1]}")
    if failed:
        atomic_write_text(out / "failed.json", dumps_json([f.to_json() for f in failed]))
        for f in failed:
            print(f"error: simulation {f.item} failed: {f.error}", file=sys.stderr)
        print(f"error: {len(failed)} simulations failed (failed.json); the tables hold the "
              "others", file=sys.stderr)  # fmt: skip
        return EXIT_TASKS_FAILED
    return 0


def _tractor_cascaded(params: Params, out: Path) -> int:
    import time

    from navreplay.pipeline.estimation.cascaded.config import CASCADED_KINDS
    from navreplay.pipeline.experiments.tractor_cascaded.artifacts import write_experiment
    from navreplay.pipeline.experiments.tractor_cascaded.runs import ExperimentInputs

    exp = params.experiments.tractor_cascaded
    inputs = ExperimentInputs(
        sim=params.synth.tractor_straight,
        sections={n: params.filters.cascaded(n) for n in CASCADED_KINDS},
        exp=exp,
        seed=params.synth.seed,
    )
    t0 = time.perf_counter()
    doc = write_experiment(out, inputs, params.report.figure_dpi)
    verdicts = ", ".join(r["verdict"] for r in doc["paper_comparison"])
    print(
        f"tractor_cascaded: {doc['runs']} closed-loop runs ({len(doc['labels'])} filter "
        f"variants, {len(doc['scenarios'])} scenarios, {exp.seeds} seeds) in "
        f"{time.perf_counter() - t0:.0f} s -> {out}\npaper's claims: {verdicts}"
    )
    return 0
