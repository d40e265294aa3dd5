"""One cascaded filter run from a tables directory to a run directory (``navreplay run``).

The same contract as the INS filters (``pipeline.estimation.run``): ``run_tables`` reads
the canonical tables (``vehicle``, ``gnss``, optional ``truth``) and ``meta.json``, replays
the recording open loop (the recorded steering command drives the control filter) and
returns the result with its metrics; ``write_run`` writes ``estimate.parquet``,
``innovations.parquet``, ``events.parquet`` and ``metrics.json`` atomically.
"""

from __future__ import annotations

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
from pipeline.estimation.cascaded.backends import Backend, replay
from pipeline.estimation.cascaded.engine import CascadedResult, make_setup
from pipeline.estimation.cascaded.inputs import prepare_inputs
from pipeline.estimation.cascaded.metrics import compute_metrics, truth_from_table
from pipeline.estimation.cascaded.outputs import estimate_table, events_table, innovations_table
from pipeline.estimation.cascaded_config import CascadedFilterParams
from pipeline.estimation.outputs import write_parquet
from pipeline.nav.local import LocalFrame

log = logging.getLogger(__name__)

_INPUTS = (TableName.VEHICLE, TableName.GNSS, TableName.TRUTH)


@dataclass(frozen=True)
class CascadedRunOutput:
    """A finished run: result, metrics, the local map and the input files it read."""

    result: CascadedResult
    metrics: dict[str, Any]
    frame: LocalFrame
    sources: tuple[Path, ...]


def run_tables(
    tables_dir: Path, name: str, params: CascadedFilterParams, backend: Backend
) -> CascadedRunOutput:
    """Replay cascaded filter ``name`` over the tables in ``tables_dir``.

    Raises:
        ReplayInputError: the vehicle or gnss table is missing or unusable.
        DivergenceError: the filter diverged and ``on_divergence`` is ``raise``.
    """
    meta = read_meta(tables_dir)
    tables: dict[str, pa.Table] = {}
    sources: list[Path] = []
    for t in _INPUTS:
        path = tables_dir / f"{t.value}.parquet"
        if path.is_file():
            tables[t.value] = read_table(path, t).table
            sources.append(path)
    inp = prepare_inputs(tables, name)
    result = replay(make_setup(name, params), inp.veh_t, inp.veh, inp.gps_t, inp.gps, backend)
    result.events = sorted([*inp.events, *result.events], key=lambda e: e.t_ns)
    truth = tables.get("truth")
    truth_x = truth_from_table(truth, inp.frame, result.t_ns) if truth is not None else None
    metrics = compute_metrics(result, truth_x, params.convergence_band)
    metrics["dataset"] = meta.dataset
    metrics["frame_origin"] = to_plain(inp.frame)
    return CascadedRunOutput(result, metrics, inp.frame, (*sources, tables_dir / META_NAME))


def write_run(
    out_dir: Path, run: CascadedRunOutput, params: CascadedFilterParams, scenario: str
) -> None:
    """Write the run directory atomically (all files appear together, or none)."""
    prov = Provenance.create(
        TableName.ESTIMATOR,
        sources=run.sources,
        params=to_plain(params),
        extra={"filter": run.result.filter, "scenario": scenario, "backend": run.result.backend},
    )
    meta = {b"navreplay": prov.to_json().encode()}
    metrics = dict(run.metrics, scenario=scenario, params_hash=prov.params_hash)
    with atomic_directory(out_dir) as tmp:
        write_table(
            tmp / "estimate.parquet",
            TableName.ESTIMATOR,
            estimate_table(run.result, run.frame),
            prov,
        )
        write_parquet(tmp / "innovations.parquet", innovations_table(run.result), meta)
        write_parquet(tmp / "events.parquet", events_table(run.result), meta)
        atomic_write_json(tmp / "metrics.json", metrics)
    log.info("wrote %s (%s, %s)", out_dir, run.result.filter, run.result.status)
