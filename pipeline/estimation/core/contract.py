"""The run contract every filter family implements, and the one writer of a run directory.

A *family* (the INS/GNSS filters, the vehicle-model filters, the cascaded filters) turns a
dataset's tables into a run in three steps: prepare its inputs from the tables, run its kernel
(numba, or filterpy driving the same model: ``Backend``), and decode the kernel's output into
a ``RunOutput``: the three run tables, the metrics and the family's own result. ``Family`` is
that protocol, with ``track``: the run's position errors, on which the scenario driver
(``pipeline.outages.runs``) measures the outage windows of every family.
``pipeline.estimation.families`` lists the families. Everything after the decode is shared:
``write_run`` writes every family's run directory the same way.

A run directory holds ``estimate.parquet`` (a canonical ``estimator`` table with a sigma
column per estimated column), ``smoothed.parquet`` (the same for the smoothed run, when the
filter was smoothed), ``innovations.parquet`` (one row per gated measurement block),
``events.parquet`` (rejections, resets, repairs, skipped inputs) and ``metrics.json``; all
appear together or not at all.
"""

from __future__ import annotations

import json
import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, Protocol

import pyarrow as pa
import pyarrow.parquet as pq

from navreplay.ingest.atomic import atomic_directory, atomic_write_json
from navreplay.ingest.meta import META_NAME, SensorMeta, read_meta
from navreplay.ingest.schema import TableName
from navreplay.ingest.tables import Provenance, read_table, write_table
from navreplay.ingest.typed import to_plain
from navreplay.ingest.writers.tum import write_tum
from navreplay.pipeline.estimation.core.integrity import IntegrityParams, assess
from navreplay.pipeline.estimation.core.tables import with_fix_latency
from navreplay.pipeline.estimation.core.windows import ErrorTrack

log = logging.getLogger(__name__)

#: ``numba``: the compiled replay loop; ``filterpy``: filterpy's filters on the same model
Backend = Literal["numba", "filterpy"]


@dataclass(frozen=True)
class RunInputs:
    """A dataset's tables as read once for one or many runs.

    Attributes:
        dataset: the dataset id (``meta.json``).
        tables: canonical tables by name; only those that exist.
        sensors: the dataset's sensor metadata (IMU noise, lever arm, wheelbase).
        sources: the files read (the tables and ``meta.json``), recorded in the provenance.
        log_tables: the log's own tables where ``tables`` are a scenario's changes of them
            (None: ``tables`` are the log's): what a family learns its noise models from, so
            every scenario of a log runs with the same ones.
    """

    dataset: str
    tables: dict[str, pa.Table]
    sensors: SensorMeta | None
    sources: tuple[Path, ...]
    log_tables: dict[str, pa.Table] | None = None

    @classmethod
    def read(cls, tables_dir: Path, names: Sequence[TableName]) -> RunInputs:
        """The tables of ``names`` that exist in ``tables_dir``, with its ``meta.json``."""
        meta = read_meta(tables_dir)
        tables: dict[str, pa.Table] = {}
        sources: list[Path] = []
        for name in names:
            path = tables_dir / f"{name.value}.parquet"
            if path.is_file():
                tables[name.value] = read_table(path, name).table
                sources.append(path)
        latency = meta.sensors.gnss_latency_s if meta.sensors is not None else None
        with_fix_latency(tables, latency)
        return cls(meta.dataset, tables, meta.sensors, (*sources, tables_dir / META_NAME))

    @property
    def lever_b(self) -> tuple[float, float, float]:
        """The GNSS antenna relative to the IMU, body FRD, m (zero if not declared)."""
        if self.sensors is None:
            return (0.0, 0.0, 0.0)
        lx, ly, lz = self.sensors.lever_arm_m
        return (float(lx), float(ly), float(lz))


@dataclass(frozen=True)
class RunTables:
    """The three tables of a run directory (``metrics.json`` aside)."""

    estimate: pa.Table
    innovations: pa.Table
    events: pa.Table


@dataclass(frozen=True)
class RunOutput:
    """A finished run of any family.

    Attributes:
        tables: the run's tables, decoded from the kernel's output.
        metrics: ``metrics.json`` (accuracy, consistency, cost; family-specific keys beside
            the common ones).
        sources: the input files, for the provenance.
        result: the family's own result (``RunResult``, ``VehicleRunResult``,
            ``CascadedResult``), for the experiments and scenario checks that read it; what
            ran, on which backend, and how it ended are read from it.
        smoothed: the smoothed run's estimate table and its family result, if the filter
            was smoothed (``metrics["smoothed"]`` holds its metrics).
    """

    tables: RunTables
    metrics: dict[str, Any]
    sources: tuple[Path, ...]
    result: ResultLike
    smoothed: tuple[pa.Table, ResultLike] | None = None

    @classmethod
    def decode(
        cls,
        result: ResultLike,
        estimate: pa.Table,
        innovations: pa.Table,
        metrics: dict[str, Any],
        sources: tuple[Path, ...],
        integrity: IntegrityParams,
    ) -> RunOutput:
        """A family's run from its result, its estimate and innovation tables (the events
        table is the same for every family) and its metrics, with the integrity monitor's
        verdict (``core.integrity``) under ``integrity``: a run that ended ``ok`` but no
        longer agrees with its measurements takes the monitor's status and reason."""
        tables = RunTables(estimate, innovations, events_table(result.events))
        verdict = assess(innovations, integrity)
        metrics = dict(metrics, integrity=verdict.to_json())
        if metrics.get("status") == "ok" and verdict.status != "ok":
            metrics["status"], metrics["failure"] = verdict.status, verdict.reason
            log.warning("filter %s: %s: %s", result.filter, verdict.status, verdict.reason)
        return cls(tables, metrics, sources, result)

    @property
    def filter(self) -> str:
        return self.result.filter

    @property
    def backend(self) -> str:
        return self.result.backend

    @property
    def status(self) -> str:
        """How the run ended: the family's status, or the integrity monitor's."""
        return str(self.metrics.get("status", self.result.status))


class Family(Protocol):
    """A filter family: its filters, the tables they read, and how one of them runs."""

    @property
    def name(self) -> str:
        """The family's name (``ins``, ``vehicle``, ``cascaded``)."""
        ...

    @property
    def filters(self) -> tuple[str, ...]:
        """The filter names of the family."""
        ...

    @property
    def inputs(self) -> tuple[TableName, ...]:
        """The canonical tables its filters can read."""
        ...

    def run(self, inputs: RunInputs, name: str, section: Any, backend: Backend) -> RunOutput:
        """Prepare the inputs, run the kernel, decode its output; ``section`` is the filter's
        section of ``params.yaml`` ``filters`` (``FiltersParams.section(name)``).

        Raises:
            PipelineError: the tables cannot drive the filter (``ReplayInputError``), or it
                diverged and its params say ``raise`` (``DivergenceError``).
        """
        ...

    def track(self, run: RunOutput, inputs: RunInputs) -> ErrorTrack | None:
        """The run's position errors against the truth of ``inputs``, else against its GNSS
        fixes (``inputs`` as recorded: a scenario's withheld fixes included); None without
        either. The outage-window metrics of every scenario are measured on it."""
        ...


class ResultLike(Protocol):
    """What every family's result holds that ``RunMetrics.of`` reads."""

    @property
    def filter(self) -> str: ...
    @property
    def backend(self) -> str: ...
    @property
    def status(self) -> str: ...
    @property
    def failure(self) -> str | None: ...
    @property
    def runtime_s(self) -> float: ...
    @property
    def duration_s(self) -> float: ...
    @property
    def t_ns(self) -> Any: ...
    @property
    def events(self) -> Sequence[EventLike]: ...


@dataclass(frozen=True)
class RunMetrics:
    """What every family's run reports, the shared keys of ``metrics.json``; each family adds
    its accuracy and consistency keys beside them (``to_json``).

    Attributes:
        filter, backend, status, failure: what ran, on which backend, and how it ended (the
            failure text when it did not end ``ok``).
        runtime_s, duration_s, epochs: its cost, the span of log replayed and the estimates.
        nis: the family's per-stream NIS summary (``nis_mean``, ``rejected`` and more).
        events: the run's events counted by kind (``gate_reset``, ``cov_repair`` ...).
    """

    filter: str
    backend: str
    status: str
    failure: str | None
    runtime_s: float
    duration_s: float
    epochs: int
    nis: dict[str, dict[str, Any]]
    events: dict[str, int]

    @classmethod
    def of(cls, result: ResultLike, nis: dict[str, dict[str, Any]]) -> RunMetrics:
        """A finished run's record; ``nis`` is the family's per-stream summary."""
        kinds: dict[str, int] = {}
        for e in result.events:
            kinds[e.kind] = kinds.get(e.kind, 0) + 1
        return cls(
            result.filter,
            result.backend,
            result.status,
            result.failure,
            result.runtime_s,
            result.duration_s,
            int(result.t_ns.size),
            nis,
            kinds,
        )

    @property
    def realtime_factor(self) -> float | None:
        return self.duration_s / self.runtime_s if self.runtime_s else None

    @property
    def gate_rejections(self) -> int:
        return int(sum(v["rejected"] for v in self.nis.values()))

    def to_json(self) -> dict[str, Any]:
        """The shared keys of ``metrics.json``, in their order."""
        return {
            "filter": self.filter,
            "backend": self.backend,
            "status": self.status,
            "failure": self.failure,
            "runtime_s": self.runtime_s,
            "duration_s": self.duration_s,
            "realtime_factor": self.realtime_factor,
            "epochs": self.epochs,
            "nis": self.nis,
            "nis_mean": {k: v["nis_mean"] for k, v in self.nis.items()},
            "gate_rejections": self.gate_rejections,
            "gate_resets": self.events.get("gate_reset", 0),
            "cov_repairs": self.events.get("cov_repair", 0),
            "events": self.events,
        }


class EventLike(Protocol):
    """What ``events_table`` reads of an event."""

    @property
    def t_ns(self) -> int: ...
    @property
    def kind(self) -> str: ...
    @property
    def stream(self) -> str: ...
    @property
    def sv(self) -> str: ...
    @property
    def value(self) -> float: ...


def events_table(events: Sequence[EventLike]) -> pa.Table:
    """``events.parquet``: skips, rejections, resets, repairs and data defects, in the order
    given."""
    return pa.table(
        {
            "t_ns": pa.array([e.t_ns for e in events], pa.int64()),
            "kind": pa.array([e.kind for e in events], pa.string()),
            "stream": pa.array([e.stream for e in events], pa.string()),
            "sv": pa.array([e.sv for e in events], pa.string()),
            "value": pa.array(
                [e.value if math.isfinite(e.value) else None for e in events], pa.float64()
            ),
        }
    )


def write_parquet(path: Path, table: pa.Table, metadata: dict[bytes, bytes]) -> None:
    """Write a non-canonical run table with the run's provenance in its metadata."""
    pq.write_table(
        table.replace_schema_metadata(metadata), path, compression="zstd", write_page_index=True
    )


def write_run(
    out_dir: Path,
    run: RunOutput,
    params: object,
    scenario: str,
    windows: list[dict[str, Any]] | None = None,
) -> None:
    """Write the run directory atomically (all files appear together, or none).

    ``params`` is the filter's parameter section (hashed into the provenance and
    ``metrics.json``); ``windows`` (the scenario's outage and fault windows) also go into the
    Parquet provenance, as JSON under ``extra["scenario_windows"]``.
    """
    extra = {"filter": run.filter, "scenario": scenario, "backend": run.backend}
    if windows is not None:
        extra["scenario_windows"] = json.dumps(windows, sort_keys=True)
    prov = Provenance.create(
        TableName.ESTIMATOR, sources=run.sources, params=to_plain(params), extra=extra
    )
    meta = {b"navreplay": prov.to_json().encode()}
    metrics = dict(run.metrics, scenario=scenario, params_hash=prov.params_hash)
    with atomic_directory(out_dir) as tmp:
        write_table(tmp / "estimate.parquet", TableName.ESTIMATOR, run.tables.estimate, prov)
        write_parquet(tmp / "innovations.parquet", run.tables.innovations, meta)
        write_parquet(tmp / "events.parquet", run.tables.events, meta)
        write_tum(tmp / "trajectory.tum", run.tables.estimate)
        if run.smoothed is not None:
            write_table(tmp / "smoothed.parquet", TableName.ESTIMATOR, run.smoothed[0], prov)
        atomic_write_json(tmp / "metrics.json", metrics)
    log.info("wrote %s (%s, %s)", out_dir, run.filter, run.status)
