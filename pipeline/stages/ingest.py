"""Convert one drive's logs into canonical Parquet tables.

The format of each LOG is detected from its content (magic bytes), not its extension. Several
files of one drive (e.g. a bag with the IMU plus the receiver's RINEX observation and
navigation files) merge into one dataset with their time bases reconciled. Writes
DIR/{imu,gnss,gnss_obs,vehicle,truth,estimator,mag}.parquet (those the logs contain), the
log's messages, modes, arming and events in DIR/events.parquet and its vibration in
DIR/vibration.parquet (autopilot logs),
DIR/meta.json and DIR/ingest_report.json; nothing partial is ever left at DIR.

examples:
  navreplay ingest --list drive.mcap
  navreplay ingest drive.mcap drive.obs drive.nav --out datasets/mydrive/tables
  navreplay ingest flight.bin --dataset-config datasets/myflight/dataset.yaml --out out/
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from navreplay.ingest.detect import Format
from navreplay.pipeline.errors import ParamsError
from navreplay.pipeline.stages.options import add_out, add_params

FORMATS = ("auto", *(f.value for f in Format))


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "logs",
        nargs="*",
        type=Path,
        metavar="LOG",
        help="log file(s) or rosbag2 directory of one drive (default: the descriptor's logs)",
    )
    add_out(parser, "output directory for the tables (required unless --list)", required=False)
    parser.add_argument(
        "--format",
        choices=FORMATS,
        default="auto",
        help="force a format instead of detecting it (default: auto)",
    )
    parser.add_argument(
        "--dataset-config",
        type=Path,
        metavar="YAML",
        help="dataset descriptor: topic overrides, sensor metadata, mounting, CSV column mapping",
    )
    parser.add_argument(
        "--list",
        action="store_true",
        help="show what the log contains (topics, messages, counts, rates) "
        "and exit without converting",
    )
    parser.add_argument(
        "--strict",
        action="store_true",
        help="fail on any recoverable defect (truncation, corrupt chunk, "
        "reordered or dropped samples) instead of salvaging",
    )
    add_params(parser, "ingest.strict, ingest.reorder_window_s and ingest.gap_factor")


def run(args: argparse.Namespace) -> int:
    from navreplay.ingest.api import IngestOptions, ingest, inspect
    from navreplay.ingest.config import input_paths, load_dataset_config
    from navreplay.pipeline.params import load_params

    config = None
    config_dir = None
    logs = list(args.logs)
    if args.dataset_config is not None:
        config = load_dataset_config(args.dataset_config)
        config_dir = args.dataset_config.parent
        if not logs:
            logs = input_paths(config, args.dataset_config)
    if not logs:
        raise ParamsError("logs", "no LOG given and no dataset descriptor listing `logs`")
    loaded = load_params(args.params)
    strict = args.strict or loaded.ingest.strict
    window_s, gap_factor = loaded.ingest.reorder_window_s, loaded.ingest.gap_factor
    params = {"reorder_window_s": window_s, "gap_factor": gap_factor}
    options = IngestOptions(
        strict=strict,
        reorder_window_s=window_s,
        gap_factor=gap_factor,
        format=None if args.format == "auto" else Format(args.format),
    )
    if args.list:
        inventories, plans = inspect(logs, config=config, config_dir=config_dir, options=options)
        sys.stdout.write(format_listing(inventories, plans, config.required if config else ()))
        return 0
    if args.out is None:
        raise ParamsError("--out", "an output directory is required unless --list is given")
    result = ingest(
        logs, args.out, config=config, config_dir=config_dir, options=options, params=params
    )
    sys.stdout.write(format_summary(result.report, result.out_dir))
    return 0


def format_listing(
    inventories: list,  # type: ignore[type-arg]
    plans: dict,  # type: ignore[type-arg]
    required: tuple[str, ...] = (),
) -> str:
    """The --list text: every stream of every file, and which one each table gets."""
    lines: list[str] = []
    chosen = {q.key for p in plans.values() for q in (p, p.companion) if q is not None}
    streams = [s for inv in inventories for s in inv.streams]
    kw = max((len(s.key) for s in streams), default=0)
    tw = max((len(s.msgtype) for s in streams), default=0)
    for inv in inventories:
        lines.append(f"{inv.path}  [{inv.format.value}]")
        for s in inv.streams:
            rate = f"{s.rate_hz:8.2f} Hz" if s.rate_hz is not None else "       ? Hz"
            count = f"{s.count:>9}" if s.count is not None else "        ?"
            table = s.table.value if s.table is not None else "-"
            mark = "*" if s.key in chosen else " "
            lines.append(
                f" {mark} {s.key:<{kw}}  {s.msgtype:<{tw}} {count} {rate}  -> {table:<9} {s.detail}"
            )
        lines.extend(f"   note: {n}" for n in inv.notes)
    lines.append("selection:")
    for t, p in plans.items():
        lines.append(f"  {t.value:<9} <- {p.key} ({p.reason})")
        if p.companion is not None:
            lines.append(f"  {'':<9}  + {p.companion.key} ({p.companion.reason}, joined by time)")
    chosen_tables = {t.value for t in plans}
    for name in required:
        if name not in chosen_tables:
            lines.append(f"  {name:<9} <- nothing: REQUIRED by the descriptor, ingest will fail")
    return "\n".join(lines) + "\n"


_CONTEXT = {"events": "messages, modes, arming, events", "vibration": "vibration, clipping"}


def format_summary(report: dict, out_dir: Path) -> str:  # type: ignore[type-arg]
    """A few lines after a successful ingest: tables, rows, completeness, warnings."""
    lines = [f"wrote {out_dir}"]
    for name, t in report["tables"].items():
        st = t["stats"]
        rate = f"{st['rate_hz']:.2f} Hz" if st.get("rate_hz") else "-"
        lines.append(f"  {name:<9} {st['rows']:>9} rows  {rate:>11}  from {t['stream']}")
    for name, rows in report.get("context", {}).items():
        lines.append(f"  {name:<9} {rows:>9} rows  {'':>11}  the log's {_CONTEXT[name]}")
    for f in report["files"]:
        checked = f.get("verification", "")
        unverified = " (unverified: no checksums)" if checked.startswith("unverified") else ""
        lines.append(f"  {f['name']}: {', '.join(f['completeness'])}{unverified}")
        lines.extend(f"    {d['reason']}" for d in f["defects"])
    lines.extend(f"  warning: {w}" for w in report["warnings"])
    lines.extend(
        f"  not usable for INS/GNSS ({lim['table']}): {lim['reason']}"
        for lim in report.get("limits", ())
    )
    return "\n".join(lines) + "\n"
