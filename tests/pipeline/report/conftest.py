"""Fixtures of the report tests: a small dataset with real runs, written by the real writers.

``dataset_dir`` holds a 70 s seoul_campus drive (the synthesizer with params.yaml's settings,
10 s at rest first) as
canonical tables with meta.json and an ingest report, and two real ``lc_ekf`` runs written by
``navreplay run``'s own code: ``nominal`` and ``outage_15s`` (the fixes inside one 15 s window
removed before the replay, and the window recorded in metrics.json as the scenario engine
records it).
"""

from __future__ import annotations

import json
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest

from navreplay.ingest.meta import DatasetMeta, SourceRecord, write_meta
from navreplay.ingest.schema import TableName
from navreplay.ingest.tables import Provenance, write_table
from navreplay.pipeline.estimation.core.contract import write_run
from navreplay.pipeline.estimation.families import run_tables
from navreplay.pipeline.params import load_params
from navreplay.pipeline.synth.seoul_campus import simulate

REPO = Path(__file__).resolve().parents[3]
OUTAGE_START_S = 30.0
OUTAGE_S = 15.0


def _ingest_report(tables: dict[str, pa.Table]) -> dict[str, object]:
    out: dict[str, object] = {}
    for name, t in tables.items():
        ts = np.asarray(t.column("t_ns").to_numpy())
        dt = np.diff(np.unique(ts))
        out[name] = {
            "stream": f"/{name}",
            "hygiene": {"reordered": 0, "dropped_late": 0, "duplicates_exact_dropped": 2},
            "stats": {
                "rows": t.num_rows,
                "duration_s": (ts[-1] - ts[0]) / 1e9,
                "rate_hz": 1e9 / float(np.median(dt)),
                "median_dt_ms": float(np.median(dt)) / 1e6,
                "jitter_ms": 0.0,
                "max_dt_ms": float(dt.max()) / 1e6,
                "gaps": {"count": 0, "total_s": 0.0, "longest_s": 0.0},
                "segments": [],
                "nonfinite": {"lat_deg": {"nan": 3, "inf": 0}} if name == "gnss" else {},
            },
            "frame_conversions": ["imu: FLU -> FRD"] if name == "imu" else [],
        }
    return {
        "files": [{"name": "drive.mcap", "format": "mcap", "completeness": ["complete"]}],
        "time_base": {"base": "gps", "decisions": ["/imu: utc -> gps (18 s)"]},
        "tables": out,
        "warnings": ["gnss: 3 fixes without a position (NaN)"],
    }


def write_tables(directory: Path, tables: dict[str, pa.Table], sensors: object) -> None:
    directory.mkdir(parents=True)
    for name, t in tables.items():
        write_table(directory / f"{name}.parquet", TableName(name), t, Provenance.create(name))
    meta = DatasetMeta(
        dataset="tiny",
        time_base="gps",
        sources=(SourceRecord("drive.mcap", "ab" * 32, "mcap"),),
        tables={k: v.num_rows for k, v in tables.items()},
        sensors=sensors,  # type: ignore[arg-type]
    )
    write_meta(directory, meta)
    (directory / "ingest_report.json").write_text(json.dumps(_ingest_report(tables)))


@pytest.fixture(scope="session")
def dataset_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``<root>/tables``, ``<root>/runs/lc_ekf/{nominal,outage_15s}`` (see the module doc)."""
    root = tmp_path_factory.mktemp("tiny")
    sp = load_params(REPO / "params.yaml").synth.seoul_campus
    result = simulate(replace(sp, duration_s=70.0, stationary_s=10.0), seed=11, variant="cw")
    tables = {k: v for k, v in result.tables.items() if k in ("imu", "gnss", "truth")}
    sensors = result.sensors
    write_tables(root / "tables", tables, sensors)
    params = load_params(REPO / "params.yaml").filters.get("lc_ekf")
    out = run_tables(root / "tables", "lc_ekf", params, "numba")
    write_run(root / "runs" / "lc_ekf" / "nominal", out, params, "nominal")
    # the outage run: the same tables without the fixes inside the window
    g = tables["gnss"]
    t = np.asarray(g.column("t_ns").to_numpy())
    a = int(t[0]) + round(OUTAGE_START_S * 1e9)
    b = a + round(OUTAGE_S * 1e9)
    cut = dict(tables, gnss=g.filter(pa.array((t < a) | (t >= b))))
    write_tables(root / "outage_tables", cut, sensors)
    out = run_tables(root / "outage_tables", "lc_ekf", params, "numba")
    run_dir = root / "runs" / "lc_ekf" / "outage_15s"
    write_run(run_dir, out, params, "outage_15s")
    metrics = json.loads((run_dir / "metrics.json").read_text())
    metrics["outage_windows"] = [{"start_ns": a, "end_ns": b, "sats": 0}]
    (run_dir / "metrics.json").write_text(json.dumps(metrics))
    return root


@pytest.fixture
def dataset_copy(dataset_dir: Path, tmp_path: Path) -> Path:
    """A copy of ``dataset_dir`` (at ``tmp_path/ds``) that a test may add to or change."""
    root = tmp_path / "ds"
    shutil.copytree(dataset_dir, root)
    return root
