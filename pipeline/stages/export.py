"""Export a navreplay table or run output for other tools: a flat CSV (PlotJuggler, a
spreadsheet) or a TUM trajectory (evo and the SLAM tools).

FILE is any Parquet file navreplay wrote: a canonical table (``tables/imu.parquet``,
``tables/events.parquet`` ...) or a run's ``estimate.parquet`` / ``innovations.parquet``.
``--csv`` writes every column with ``time_s`` (seconds on the table's time base) first, the
column PlotJuggler's CSV loader offers as the time axis; ``--tum`` writes the position (WGS-84
ECEF) and attitude of a navigation solution (``estimate``, ``truth``, ``estimator``), as each
run's ``trajectory.tum`` already is. Nothing is written where a file exists unless ``--force``.

examples:
  navreplay export runs/lc_ekf/nominal/estimate.parquet --csv lc_ekf.csv
  navreplay export datasets/mydrive/tables/truth.parquet --tum truth.tum
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def configure(parser: argparse.ArgumentParser) -> None:
    parser.description = __doc__
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    parser.add_argument("file", type=Path, metavar="FILE", help="a navreplay Parquet file")
    what = parser.add_mutually_exclusive_group(required=True)
    what.add_argument("--csv", type=Path, metavar="OUT", help="flat CSV, time_s first")
    what.add_argument("--tum", type=Path, metavar="OUT", help="TUM trajectory (ECEF)")
    parser.add_argument("--force", action="store_true", help="replace OUT if it exists")


def run(args: argparse.Namespace) -> int:
    import pyarrow.parquet as pq

    from navreplay.ingest.writers.flatcsv import write_flat_csv
    from navreplay.ingest.writers.tum import write_tum

    out: Path = args.csv or args.tum
    if not args.file.is_file():
        return _error(f"{args.file}: no such file")
    if out.exists() and not args.force:
        return _error(f"{out} exists; choose another name or pass --force")
    try:
        if args.csv is not None:
            rows = write_flat_csv(args.file, out)
        else:
            table = pq.read_table(args.file)
            missing = {"t_ns", "lat_deg", "lon_deg", "alt_m"} - set(table.column_names)
            if missing:
                return _error(
                    f"{args.file} is not a navigation solution (no {', '.join(sorted(missing))});"
                    " --tum takes an estimate, truth or estimator table"
                )
            rows = write_tum(out, table)
    except (OSError, ValueError) as err:  # pyarrow's ArrowInvalid is a ValueError
        return _error(f"{args.file}: {err}")
    print(f"wrote {out} ({rows} rows)")
    return 0


def _error(text: str) -> int:
    print(f"navreplay export: {text}", file=sys.stderr)
    return 2
