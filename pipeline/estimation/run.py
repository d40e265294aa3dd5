"""One filter run from a tables directory to a run directory (the pure core of the stage).

``run_tables`` reads the canonical tables and ``meta.json``, replays the filter and returns
the result and metrics; ``write_run`` writes the run directory atomically
(``ingest.atomic.atomic_directory``): ``estimate.parquet``, ``innovations.parquet``,
``events.parquet`` and ``metrics.json`` (see ``outputs`` and ``metrics``).
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pyarrow as pa

from ingest.atomic import atomic_directory, atomic_write_json
from ingest.meta import META_NAME, read_meta
from ingest.schema import TableName
from ingest.tables import Provenance, read_table, write_table
from ingest.typed import to_plain
from pipeline.estimation.config import InsFilterParams
from pipeline.estimation.metrics import compute_metrics
from pipeline.estimation.outputs import (
    estimate_table,
    events_table,
    innovations_table,
    write_parquet,
)
from pipeline.estimation.replay import Backend, RunResult, run_filter

log = logging.getLogger(__name__)

_INPUTS = (TableName.IMU, TableName.GNSS, TableName.GNSS_OBS, TableName.TRUTH)


@dataclass(frozen=True)
class RunOutput:
    """A finished run: the result, its metrics and the input files it read."""

    result: RunResult
    metrics: dict[str, Any]
    sources: tuple[Path, ...]


def read_inputs(tables_dir: Path) -> tuple[dict[str, pa.Table], tuple[Path, ...]]:
    """The canonical tables a filter run can use that exist in ``tables_dir``."""
    tables: dict[str, pa.Table] = {}
    sources: list[Path] = []
    for name in _INPUTS:
        path = tables_dir / f"{name.value}.parquet"
        if path.is_file():
            tables[name.value] = read_table(path, name).table
            sources.append(path)
    return tables, tuple(sources)


def run_tables(tables_dir: Path, name: str, params: InsFilterParams, backend: Backend) -> RunOutput:
    """Replay filter ``name`` over the tables in ``tables_dir`` (with its ``meta.json``)."""
    meta = read_meta(tables_dir)
    tables, sources = read_inputs(tables_dir)
    result = run_filter(tables, meta.sensors, name, params, backend=backend)
    metrics = compute_metrics(result, tables.get("truth"))
    metrics["dataset"] = meta.dataset
    return RunOutput(result, metrics, (*sources, tables_dir / META_NAME))


def write_run(
    out_dir: Path,
    run: RunOutput,
    params: InsFilterParams,
    scenario: str,
    windows: list[dict[str, Any]] | None = None,
) -> None:
    """Write the run directory atomically (all files appear together, or none).

    ``windows`` (the scenario's outage and fault windows) also go into the Parquet
    provenance, as JSON under ``extra["scenario_windows"]``.
    """
    plain = to_plain(params)
    extra = {"filter": run.result.filter, "scenario": scenario, "backend": run.result.backend}
    if windows is not None:
        extra["scenario_windows"] = json.dumps(windows, sort_keys=True)
    prov = Provenance.create(TableName.ESTIMATOR, sources=run.sources, params=plain, extra=extra)
    meta = {b"navreplay": prov.to_json().encode()}
    metrics = dict(run.metrics, scenario=scenario, params_hash=prov.params_hash)
    with atomic_directory(out_dir) as tmp:
        write_table(tmp / "estimate.parquet", TableName.ESTIMATOR, estimate_table(run.result), prov)
        write_parquet(tmp / "innovations.parquet", innovations_table(run.result), meta)
        write_parquet(tmp / "events.parquet", events_table(run.result), meta)
        atomic_write_json(tmp / "metrics.json", metrics)
    log.info("wrote %s (%s, %s)", out_dir, run.result.filter, run.result.status)
