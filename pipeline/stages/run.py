"""Replay one filter over a dataset's canonical tables under one scenario.

Reads TABLES_DIR/{imu,gnss,gnss_obs,truth}.parquet and meta.json (IMU noise, lever arm).
Writes DIR atomically: estimate.parquet (the navigation solution under the truth table's
column names, with a sigma column for each), innovations.parquet (NIS per update),
events.parquet (gate rejections, resets, skipped inputs) and metrics.json. A diverging
filter exits with status 2 and writes nothing, unless its params say on_divergence: flag.

examples:
  navreplay run datasets/seoul_campus_cw/tables --filter tc_ukf_nhc --out runs/tc_ukf_nhc
  navreplay run TABLES --filter lc_ekf --scenario outage_60s --out runs/lc_ekf-outage
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from pipeline.errors import NotBuiltError, ParamsError

log = logging.getLogger(__name__)


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "tables",
        type=Path,
        metavar="TABLES_DIR",
        help="directory of canonical tables written by `navreplay ingest`",
    )
    parser.add_argument(
        "--filter",
        required=True,
        metavar="NAME",
        help="filter name from params.yaml (lc_ekf, tc_ekf, tc_ukf, tc_ukf_nhc, "
        "cascaded_ekf, fwekf, vehicle_imm, ...)",
    )
    parser.add_argument(
        "--scenario",
        default="nominal",
        metavar="NAME",
        help="scenario name from params.yaml (default: nominal)",
    )
    parser.add_argument(
        "--params",
        type=Path,
        default=Path("params.yaml"),
        help="parameter file (default: params.yaml)",
    )
    parser.add_argument(
        "--backend",
        choices=("numba", "filterpy"),
        help="override run.backend from the parameter file",
    )
    parser.add_argument(
        "--out", type=Path, required=True, metavar="DIR", help="output directory of the run"
    )


def run(args: argparse.Namespace) -> int:
    from pipeline.estimation.families import runner
    from pipeline.params import load_params

    params = load_params(args.params)
    try:
        run_filter = runner(args.filter)
    except KeyError as err:
        raise ParamsError(
            f"filters.{args.filter}", str(err.args[0]), source=str(args.params)
        ) from err
    if args.scenario != "nominal":
        raise NotBuiltError(
            f"scenario {args.scenario!r}: only 'nominal' exists until the scenario engine "
            "arrives (issue 'Outage and satellite-count experiments'); nothing was written"
        )
    backend = args.backend or params.run.backend
    m = run_filter(args.tables, args.filter, params.filters, backend, args.out, args.scenario)
    summary = f"{args.filter} ({backend}): {m['status']}, {m['epochs']} epochs"
    if m.get("truth"):
        summary += f", horizontal RMS {m['pos_err_h_rms_m']:.2f} m"
    summary += f", {m['realtime_factor']:.0f}x real time -> {args.out}"
    print(summary)
    return 0
