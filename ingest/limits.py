"""What a log's tables cannot give an INS/GNSS replay, said exactly (``ingest_report.json``
``limits``, each logged as a warning and printed by ``navreplay ingest``).

A log can ingest cleanly and still hold nothing a loosely coupled filter can start on: a bench
log whose receiver never had a fix, a few hundred milliseconds of a truncated file, a vehicle
that never moves (the filters take their heading from the GNSS velocity), an IMU logged at a
rate no INS can integrate. (A slow IMU alone is not a limit: a SITL tlog's 4 Hz telemetry
still gives an estimate.) Each ``Limit`` names the table, a stable ``code`` and the reason
with the log's own numbers, so that ``analyze``/``run`` can refuse with it instead of
running to zero epochs:

==================  ===========================================================================
``imu_refused``     no ``imu`` table: the reader refused the log's IMU stream
                    (``StreamInfo.refused``, e.g. PX4 samples covering 3 % of the time)
``gnss_no_fix``     the GNSS records hold no 3-D fix
``gnss_static``     every 3-D fix has a horizontal speed below ``STATIC_SPEED_MPS`` (or, without
                    velocities, lies within ``STATIC_SPREAD_M`` of the others)
``short_overlap``   IMU samples and 3-D fixes overlap for less than ``MIN_OVERLAP_S``
==================  ===========================================================================
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.parquet as pq

from navreplay.ingest.readers.base import Inventory
from navreplay.ingest.schema import FixType

STATIC_SPEED_MPS = 0.5
STATIC_SPREAD_M = 5.0
MIN_OVERLAP_S = 10.0
_M_PER_DEG = 111_320.0


@dataclass(frozen=True)
class Limit:
    """One reason the tables cannot drive an INS/GNSS replay."""

    table: str
    code: str
    reason: str

    def to_json(self) -> dict[str, str]:
        return {"table": self.table, "code": self.code, "reason": self.reason}


def find_limits(
    tables_dir: Path, tables: dict[str, Any], inventories: Sequence[Inventory]
) -> list[Limit]:
    """The limits of the tables in ``tables_dir`` (``tables``: the report's per-table part)."""
    out: list[Limit] = []
    if "imu" not in tables:
        for inv in inventories:
            for s in inv.streams:
                if s.refused:
                    out.append(Limit("imu", "imu_refused", f"{inv.path.name}: {s.refused}"))
    imu_span: tuple[int, int] | None = None
    if "imu" in tables:
        stats = tables["imu"]["stats"]
        if stats.get("first_t_ns") is not None:
            imu_span = (stats["first_t_ns"], stats["last_t_ns"])
    if "gnss" in tables and (tables_dir / "gnss.parquet").is_file():
        out += _gnss(tables_dir / "gnss.parquet", tables["gnss"], imu_span, tables.get("imu"))
    return out


def _gnss(
    path: Path, report: dict[str, Any], imu_span: tuple[int, int] | None, imu: Any
) -> list[Limit]:
    cols = ["t_ns", "lat_deg", "lon_deg", "vel_n_mps", "vel_e_mps", "fix_type"]
    df = pq.read_table(path, columns=cols).to_pandas()
    key = report["stream"]
    records = int(report["hygiene"]["rows_in"])
    no_fix = int(report["counters"].get("no_fix", 0))
    fixed = df[df["fix_type"] >= FixType.FIX_3D]
    if not len(df):
        return []  # an empty table: the ingest already warns
    if not len(fixed):
        kinds = ", ".join(
            f"{n} x type {int(t)}"
            for t, n in sorted(df["fix_type"].value_counts().items(), key=lambda x: x[0])
        )
        return [
            Limit(
                "gnss",
                "gnss_no_fix",
                f"no GPS fix in the log: {records} GPS records ({key}), all with fix type < 3 "
                f"({no_fix} without any fix; fix types of the {len(df)} distinct epochs: "
                f"{kinds})",
            )
        ]
    out: list[Limit] = []
    t = fixed["t_ns"].to_numpy(np.int64)
    span_s = (int(t[-1]) - int(t[0])) * 1e-9
    speed = np.hypot(fixed["vel_n_mps"].to_numpy(float), fixed["vel_e_mps"].to_numpy(float))
    lat, lon = fixed["lat_deg"].to_numpy(float), fixed["lon_deg"].to_numpy(float)
    north = (lat - np.nanmedian(lat)) * _M_PER_DEG
    east = (lon - np.nanmedian(lon)) * _M_PER_DEG * np.cos(np.radians(np.nanmedian(lat)))
    spread = float(np.nanmax(np.hypot(north, east))) if len(lat) else 0.0
    if np.isfinite(speed).any():
        top = float(np.nanmax(speed))
        if top < STATIC_SPEED_MPS:
            out.append(
                Limit(
                    "gnss",
                    "gnss_static",
                    f"the vehicle does not move: the GNSS horizontal speed stays below "
                    f"{top:.2f} m/s over {len(fixed)} 3-D fixes ({span_s:.1f} s, all within "
                    f"{spread:.1f} m); the filters take their heading from the GNSS velocity",
                )
            )
    elif spread < STATIC_SPREAD_M:
        out.append(
            Limit(
                "gnss",
                "gnss_static",
                f"the vehicle does not move: {len(fixed)} 3-D fixes ({span_s:.1f} s) all within "
                f"{spread:.1f} m and no GNSS velocity; the filters take their heading from the "
                "GNSS velocity",
            )
        )
    if imu_span is not None:
        overlap_s = (min(imu_span[1], int(t[-1])) - max(imu_span[0], int(t[0]))) * 1e-9
        if overlap_s < MIN_OVERLAP_S:
            stats = imu["stats"]
            out.append(
                Limit(
                    "imu",
                    "short_overlap",
                    f"IMU samples and 3-D GNSS fixes overlap for {max(overlap_s, 0.0):.2f} s "
                    f"(IMU {stats['duration_s']:.2f} s, {stats['rows']} samples; "
                    f"{len(fixed)} 3-D fixes over {span_s:.2f} s): less than "
                    f"{MIN_OVERLAP_S:.0f} s",
                )
            )
    return out
