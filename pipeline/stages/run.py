"""Replay one filter over a dataset's canonical tables under one or more scenarios.

Reads the tables the filter's family needs from TABLES_DIR (imu, gnss, gnss_obs, truth for
the INS/GNSS filters; vehicle, gnss, truth for the vehicle-model and cascaded filters) and
meta.json (IMU noise, lever arm), applies each scenario of params.yaml `scenarios.named` to
the tables (outage windows, k satellites kept, faults; fault scenarios for INS filters only)
and replays the filter. Writes a run directory atomically:
estimate.parquet (the navigation solution under the truth table's column names, with a sigma
column for each), innovations.parquet (NIS per update), events.parquet (gate rejections,
resets, skipped inputs) and metrics.json (accuracy, consistency, cost; per outage window the
drift metrics; the scenario and its windows under `windows`; for fault scenarios the
catalogue's pass criteria under `fault_checks`). A diverging filter exits with status 2 and
writes nothing, unless its params say on_divergence: flag. The integrity monitor
(pipeline/estimation/core/integrity.py) then checks the run against its own innovations: a run
whose estimate left the measurements is diverged, one whose innovations are larger than its
covariance says is inconsistent (metrics.json `integrity` has the tests per stream). A filter
that never aligned (a static or bench log, no fix, no motion) writes its run with status
not_aligned and the reason. A run that is diverged or not_aligned exits with status 3 (0 with
--keep-going).

With one --scenario, DIR is the run directory. With several, or `--scenario all` (the
scenarios of params.yaml `run.scenarios`), DIR holds one run directory per scenario,
DIR/<scenario>/, and appears as a whole or not at all. The scenarios replay on run.workers
forked processes, or on a Dask cluster with --scheduler (`compute` in params.yaml).

The first run after installing or changing navreplay compiles the filter (numba, 10-30 s;
cached for later runs); `navreplay warm` compiles every filter ahead of time.

examples:
  navreplay run datasets/seoul_campus_cw/tables --filter tc_ukf_nhc --out runs/tc_ukf_nhc
  navreplay run TABLES --filter lc_ekf --scenario outage_60s --out runs/lc_ekf-outage
  navreplay run TABLES --filter tc_ukf --scenario all --out datasets/seoul_campus_cw/runs/tc_ukf
"""

from __future__ import annotations

import argparse
import logging
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from navreplay.pipeline.errors import ParamsError
from navreplay.pipeline.stages.options import add_params, add_scheduler

#: The exit status when a run never aligned or diverged (it is written, with the status and
#: the reason).
EXIT_NOTHING_USABLE = 3

if TYPE_CHECKING:
    from navreplay.pipeline.estimation.core.contract import Backend
    from navreplay.pipeline.params import Params

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
        action="append",
        metavar="NAME",
        help="scenario name from params.yaml scenarios.named (default: nominal); repeat for "
        "several, or `all` for those of run.scenarios (DIR then holds one folder per scenario)",
    )
    add_params(parser)
    parser.add_argument(
        "--backend",
        choices=("numba", "filterpy"),
        help="override run.backend from the parameter file",
    )
    parser.add_argument(
        "--out", type=Path, required=True, metavar="DIR", help="output directory of the run"
    )
    parser.add_argument(
        "--smooth",
        action="store_true",
        help="INS filters: also run the Rauch-Tung-Striebel backward pass and write "
        "smoothed.parquet beside estimate.parquet, its metrics under metrics.json `smoothed` "
        "(the same as filters.<name>.smooth: true)",
    )
    parser.add_argument(
        "--keep-going",
        action="store_true",
        help="exit 0 when a run diverged or never aligned (its status and reason are in its "
        "metrics.json and the report) instead of 3; the dvc stages use this, so that the "
        "reports show such a run instead of the pipeline stopping",
    )
    parser.add_argument(
        "--skip-unfit",
        action="store_true",
        help="when the tables lack what the filter needs (e.g. tight coupling without raw "
        "observables), write a run marked skipped with the reason and exit 0 instead of failing "
        "(the dvc run matrix uses this, so a recorded log without raw GNSS still gets its report)",
    )
    add_scheduler(parser)


def run(args: argparse.Namespace) -> int:
    from navreplay.pipeline.params import load_params

    params = load_params(args.params)
    backend: Backend = args.backend or params.run.backend
    asked: list[str] = args.scenario or ["nominal"]
    names = list(params.run.scenarios) if asked == ["all"] else asked
    return _run(args, params, backend, asked, names)


def _run(
    args: argparse.Namespace, params: Params, backend: Backend, asked: list[str], names: list[str]
) -> int:
    from navreplay.ingest.atomic import atomic_directory
    from navreplay.pipeline.analyze import Skipped, plan, write_skip
    from navreplay.pipeline.compute import resolve_scheduler
    from navreplay.pipeline.estimation.core.contract import RunInputs, write_run
    from navreplay.pipeline.estimation.families import family_of
    from navreplay.pipeline.estimation.ins.run import INS
    from navreplay.pipeline.outages.runs import run_scenarios
    from navreplay.pipeline.params import params_label

    try:
        family = family_of(args.filter)
    except KeyError as err:
        raise ParamsError(
            f"filters.{args.filter}", str(err.args[0]), source=params_label(args.params)
        ) from err
    for name in names:
        if name not in params.scenarios.named:
            known = ", ".join(params.scenarios.named)
            raise ParamsError(
                "scenarios.named",
                f"no scenario {name!r} (known: {known}, all)",
                source=params_label(args.params),
            )
    single = len(asked) == 1 and asked != ["all"]
    section = params.filters.section(args.filter)
    if args.smooth:
        if family is not INS:
            raise ParamsError(
                "--smooth", f"smoothing is for the INS/GNSS filters; {args.filter} is a "
                f"{family.name} filter", source=params_label(args.params),
            )  # fmt: skip
        section = replace(params.filters.get(args.filter), smooth=True)
    inputs = RunInputs.read(args.tables, family.inputs)
    if args.skip_unfit and family is INS:
        _, unfit = plan(args.tables, [args.filter])
        if unfit:
            reason = unfit[0].reason
            with atomic_directory(args.out) as tmp:
                for name in names:
                    write_skip(tmp if single else tmp / name, Skipped(args.filter, name, reason))
            print(f"{args.filter}: skipped ({reason}) -> {args.out}")
            return 0
    runs = run_scenarios(
        inputs, args.filter, section, params.scenarios, names, backend, params.run.workers,
        scheduler=resolve_scheduler(args.scheduler, params.compute), compute=params.compute,
    )  # fmt: skip
    statuses = []
    if single:
        for name, out, applied in runs:
            write_run(args.out, out, section, name, applied.metadata()["windows"])
            _summary(args.filter, backend, name, out.metrics, args.out)
            statuses.append(out.metrics["status"])
    else:
        with atomic_directory(args.out) as tmp:
            for name, out, applied in runs:
                write_run(tmp / name, out, section, name, applied.metadata()["windows"])
                _summary(args.filter, backend, name, out.metrics, args.out / name)
                statuses.append(out.metrics["status"])
    failed = {"not_aligned", "diverged"} & set(statuses)
    return EXIT_NOTHING_USABLE if failed and not args.keep_going else 0


def _smoothed_summary(sm: dict[str, Any]) -> str:
    """What the summary line says of the smoothed run."""
    how = sm["smoothing"]
    if how["status"] != "ok":
        return f"; smoothing {how['status'].replace('_', ' ')}: {how['failure']}"
    text = "; smoothed"
    if sm.get("truth"):
        text += f": horizontal RMS {sm['pos_err_h_rms_m']:.2f} m"
    mean, _ = _window_mean(sm, "err_mean_m")
    if mean is not None:
        text += f", outage windows {mean:.1f} m on average"
    return text


def _window_mean(m: dict[str, Any], key: str) -> tuple[float | None, int]:
    """The mean of ``key`` over the outage windows of metrics ``m`` that have one, and their
    number."""
    values = [w[key] for w in m.get("outage_windows", []) if w["err_end_m"] is not None]
    return (sum(values) / len(values) if values else None), len(values)


def _summary(filt: str, backend: str, scenario: str, m: dict[str, Any], out: Path) -> None:
    text = f"{filt} ({backend}) {scenario}: {m['status']}, {m['epochs']} epochs"
    if m["status"] in ("not_aligned", "diverged"):
        print(f"{text}: {m.get('failure')} -> {out}")
        return
    if m.get("truth"):
        text += f", horizontal RMS {m['pos_err_h_rms_m']:.2f} m"
    mean_end, n_windows = _window_mean(m, "err_end_m")
    if mean_end is not None:
        text += f", {n_windows} outage windows ending at {mean_end:.1f} m on average"
    sm = m.get("smoothed")
    if sm is not None:
        text += _smoothed_summary(sm)
    if "fault_checks_passed" in m:
        text += f", fault criteria {'passed' if m['fault_checks_passed'] else 'FAILED'}"
    text += f", {m['realtime_factor']:.0f}x real time -> {out}"
    if m["status"] != "ok":
        text += f"\n  {m['status']}: {m.get('failure')}"
    print(text)
