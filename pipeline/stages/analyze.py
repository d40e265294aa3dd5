"""One-off post-mission analysis of a log that is not in the DVC registry.

Ingests LOG (and any companion files), runs the filters that fit what the log contains under
the chosen scenarios, and renders a report into DIR/report, showing progress on stderr and a
summary at the end: where the report is, the key metrics, what was skipped and why, and the
warnings of the ingest audit. Filters that do not fit (no IMU, no fixes, no satellite orbits)
are skipped with the reason.

Outage scenarios are fitted to the log: on a log too short for a scenario's windows (the
defaults want some 10 minutes) fewer or shorter windows are placed where the log has GNSS,
and the summary says what was changed. `--outage` adds outages of your own.

Parameters: the built-in defaults, with ./params.yaml (when present) or --params laid over
them; `navreplay params` prints them.

Every run has a status: ok; inconsistent (it finished, but its innovations are larger than
its covariance says: read its figures with care); diverged (its estimate left the
measurements, or its state became invalid); not_aligned (it never started). The integrity
monitor (pipeline/estimation/core/integrity.py) decides the first three.

Exit status: 0 when at least one filter finished (ok or inconsistent), 2 for bad input or
parameters, 3 when none could (the report and the first lines of the summary say why).

examples:
  navreplay analyze flight.bin --out analysis/flight
  navreplay analyze drive.mcap --filters lc_ekf,tc_ukf_nhc --scenarios nominal,outage_60s --out a/
  navreplay analyze flight.bin --outage 30s --outage 20s@45s --out a/
  navreplay analyze drive.mcap --smooth --out a/
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from navreplay.pipeline.stages.options import (
    add_analysis_options,
    add_out,
    add_params,
    split_names,
)

#: The exit status when no filter could run on the log.
EXIT_NOTHING_RAN = 3


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "logs", nargs="+", type=Path, metavar="LOG", help="log file(s) of one drive or flight"
    )
    add_out(parser, "output directory (tables, runs and the report)")
    add_analysis_options(parser)
    parser.add_argument(
        "--dataset-config",
        type=Path,
        metavar="YAML",
        help="dataset descriptor for the log (see `navreplay ingest --help`)",
    )
    add_params(parser)


def _progress(line: str) -> None:
    print(f"[analyze] {line}", file=sys.stderr, flush=True)


def _window_drift(rows: list[dict[str, Any]]) -> dict[tuple[str, str], float]:
    """Per run: the mean 3-D difference from the onboard estimate at its outage windows' ends."""
    ends: dict[tuple[str, str], list[float]] = {}
    for o in rows:
        if o["scope"] == "window" and o.get("pos_3d_end_m") is not None:
            ends.setdefault((o["filter"], o["scenario"]), []).append(float(o["pos_3d_end_m"]))
    return {k: sum(v) / len(v) for k, v in ends.items()}


def _finished(
    r: dict[str, Any],
    width: int,
    onboard: dict[tuple[str, str], dict[str, Any]],
    drift: dict[tuple[str, str], float],
) -> str:
    """The summary line of a run that finished (``r``: its row of the report's runs)."""
    from navreplay.pipeline.report.inputs import SMOOTHED
    from navreplay.pipeline.report.tables import fmt

    status = "" if r["status"] == "ok" else f" ({r['status'].upper()}: {r.get('reason')})"
    h, m3 = fmt(r.get("pos_err_h_rms_m")) or "-", fmt(r.get("pos_err_3d_max_m")) or "-"
    if r.get("reference") == "truth":
        text = f"horizontal RMS {h:>8} m vs truth, 3-D max {m3:>8} m"
    else:  # a residual to the fixes the filter fused: never an accuracy
        text = f"residual to its fixes: horizontal RMS {h} m, 3-D max {m3} m"
    ob = onboard.get((r["filter"], r["scenario"]))
    if ob is not None:
        text += (
            f"; vs the onboard estimate: horizontal RMS {fmt(ob['pos_h_rms_m'])} m, "
            f"yaw RMS {fmt(ob['yaw_rms_deg']) or '-'} deg"
        )
    end = drift.get((r["filter"], r["scenario"]))
    if end is not None:
        text += f", drift at the outages' ends {fmt(end)} m (mean)"
    if not str(r["filter"]).endswith(SMOOTHED):  # a smoothed run's cost is its filter's
        text += f", {fmt(r.get('realtime_factor')) or '-'}x real time"
    return f"  {r['filter']:<{width}} {r['scenario']:<18} {text}{status}"


def run(args: argparse.Namespace) -> int:
    from navreplay.ingest.config import load_dataset_config
    from navreplay.pipeline.analyze import analyze
    from navreplay.pipeline.estimation.core.integrity import FINISHED
    from navreplay.pipeline.params import load_params

    params = load_params(args.params)
    config = load_dataset_config(args.dataset_config) if args.dataset_config else None
    res = analyze(
        args.logs,
        args.out,
        params,
        filters=split_names(args.filters),
        scenarios=split_names(args.scenarios),
        outages=args.outage,
        smooth=args.smooth,
        config=config,
        config_dir=args.dataset_config.parent if args.dataset_config else None,
        progress=_progress,
    )
    lines = [f"navreplay analyze: done in {res.seconds:.1f} s", f"  report: {res.report.index}"]
    ran = [r for r in res.report.runs if r["status"] in FINISHED]
    if not ran:
        lines.append("  no filter could run on this log:")
    width = max((len(str(r["filter"])) for r in res.report.runs), default=12)
    for r in res.report.runs:
        if r["status"] not in (*FINISHED, "skipped"):
            state = str(r["status"]).replace("_", " ")
            lines.append(f"  {r['filter']:<{width}} {r['scenario']:<18} {state}: {r.get('reason')}")
    onboard = {(o["filter"], o["scenario"]): o for o in res.report.onboard if o["scope"] == "run"}
    drift = _window_drift(res.report.onboard)
    lines += [_finished(r, width, onboard, drift) for r in ran]
    for s in res.skipped:
        lines.append(f"  skipped {s.filter} / {s.scenario}: {s.reason}")
    if res.report.log_account:
        lines.append(f"  the log says: {res.report.log_account}")
    for note in res.notes:
        lines.append(f"  note: {note}")
    for w in res.report.warnings:
        lines.append(f"  warning (ingest audit): {w}")
    print("\n".join(lines))
    return 0 if ran else EXIT_NOTHING_RAN
