"""What a dataset report is rendered from, loaded and checked.

``load_dataset(dataset, tables_dir, runs_dir, experiments_dir)`` reads:

- ``tables_dir/meta.json`` (``ingest.meta``) and ``tables_dir/ingest_report.json`` (the audit;
  ``ingest.api`` documents its structure), and the ``truth``, ``gnss`` and ``estimator`` (the
  vehicle's own estimate, ``report.onboard``) tables if present, and the log's ``events`` and
  ``vibration`` (``ingest.context``);
- every run under ``runs_dir``: any directory holding a ``metrics.json`` (layout free, e.g.
  ``runs/<filter>/<scenario>/``), with its ``estimate.parquet`` and ``innovations.parquet``
  (written by ``navreplay run``, ``estimation.core.contract.write_run``). The run's filter and
  scenario come from ``metrics.json`` (``filter``, ``scenario``). A smoothed run's
  ``smoothed.parquet`` appears as a run of its own, ``<filter> smoothed``, whose metrics are
  ``metrics.json`` ``smoothed`` (``smoothed_run``), so that every figure and table shows it
  beside the filter. A run whose ``status`` is
  ``skipped`` carries a ``reason`` and no tables. Outage windows come from
  ``metrics.json`` ``outage_windows`` (or ``windows``): a list of objects with either
  ``start_ns`` (or ``start_t_ns``, as the scenario engine writes it) and ``end_ns`` or
  ``duration_s``, or ``start_s``/``duration_s`` (seconds after the run's first estimate),
  plus the per-window metrics of architecture section 5 when present (``sats``,
  ``err_end_m``, ``err_max_m``, ``err_rms_m``, ``drift_pct_distance``, ``reconverge_s``);
- every experiment under ``experiments_dir`` (``pipeline.report.experiments``).

Missing sections are fine (the page leaves them out); a malformed file is a
``ReportInputError`` naming the file and what is wrong.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from navreplay.ingest.errors import IngestError
from navreplay.ingest.meta import META_NAME, DatasetMeta, read_meta
from navreplay.ingest.schema import ContextName, TableName
from navreplay.ingest.tables import read_table
from navreplay.pipeline.report.experiments import load_experiments
from navreplay.pipeline.report.input_files import ReportInputError, read_json

REPORT_NAME = "ingest_report.json"


@dataclass(frozen=True)
class Window:
    """One outage window of a run: absolute times and its per-window metrics (if any)."""

    start_ns: int
    end_ns: int
    metrics: dict[str, Any]

    @property
    def duration_s(self) -> float:
        return (self.end_ns - self.start_ns) / 1e9


@dataclass
class Run:
    """One run directory: metrics, and the estimate and innovations tables (when it ran)."""

    path: Path
    filter: str
    scenario: str
    metrics: dict[str, Any]
    estimate: pa.Table | None
    innovations: pa.Table | None
    windows: list[Window]

    @property
    def status(self) -> str:
        return str(self.metrics.get("status", "ok"))

    @property
    def ran(self) -> bool:
        return self.estimate is not None and self.estimate.num_rows > 0


@dataclass
class DatasetInputs:
    """Everything one dataset's report is rendered from."""

    dataset: str
    tables_dir: Path
    meta: DatasetMeta | None
    ingest_report: dict[str, Any] | None
    truth: pa.Table | None
    gnss: pa.Table | None
    runs: list[Run]
    onboard: pa.Table | None = None
    experiments: list[Any] = field(default_factory=list)
    events: pa.Table | None = None
    vibration: pa.Table | None = None

    def t0_ns(self) -> int:
        """The time origin of every plot: the first truth, fix or estimate time (without any,
        the first event's)."""
        starts: list[int] = []
        for t in (self.truth, self.gnss):
            if t is not None and t.num_rows:
                starts.append(int(t.column("t_ns")[0].as_py()))
        for r in self.runs:
            if r.ran and r.estimate is not None:
                starts.append(int(r.estimate.column("t_ns")[0].as_py()))
        if not starts:  # a log with nothing but its own account
            for t in (self.events, self.vibration):
                if t is not None and t.num_rows:
                    starts.append(int(t.column("t_ns")[0].as_py()))
        return min(starts) if starts else 0

    def filters(self) -> list[str]:
        """Filter names in first-seen order of the sorted runs (a stable colour order)."""
        seen: dict[str, None] = {}
        for r in self.runs:
            seen.setdefault(r.filter, None)
        return list(seen)

    def scenarios(self) -> list[str]:
        """Scenario names, ``nominal`` first, then as sorted."""
        names = sorted({r.scenario for r in self.runs})
        return sorted(names, key=lambda s: (s != "nominal", s))


def _table(path: Path, name: TableName | ContextName | None = None) -> pa.Table | None:
    if not path.is_file():
        return None
    try:
        if name is not None:
            return read_table(path, name).table
        return pq.read_table(path)
    except (IngestError, OSError, pa.ArrowException) as err:
        raise ReportInputError(path, f"cannot read the table: {err}") from err


def _windows(path: Path, metrics: dict[str, Any], t_first_ns: int | None) -> list[Window]:
    raw = metrics.get("outage_windows", metrics.get("windows", []))
    if raw is None:
        return []
    if not isinstance(raw, list):
        raise ReportInputError(path, "outage_windows: expected a list of windows")
    out: list[Window] = []
    for i, w in enumerate(raw):
        if not isinstance(w, dict):
            raise ReportInputError(path, f"outage_windows[{i}]: expected an object")
        try:
            start_key = next((k for k in ("start_ns", "start_t_ns") if k in w), None)
            if start_key is not None:
                a = int(w[start_key])
                b = int(w["end_ns"]) if "end_ns" in w else a + round(float(w["duration_s"]) * 1e9)
            else:
                if t_first_ns is None:
                    raise ReportInputError(
                        path, f"outage_windows[{i}]: start_s needs the run's estimate.parquet"
                    )
                a = t_first_ns + round(float(w["start_s"]) * 1e9)
                b = a + round(float(w["duration_s"]) * 1e9)
        except (KeyError, TypeError, ValueError) as err:
            raise ReportInputError(
                path, f"outage_windows[{i}]: needs start_ns/end_ns or start_s/duration_s ({err})"
            ) from err
        if b <= a:
            raise ReportInputError(path, f"outage_windows[{i}]: ends before it starts")
        out.append(Window(a, b, dict(w)))
    return out


def load_run(run_dir: Path) -> Run:
    """One run directory (see the module docstring)."""
    mpath = run_dir / "metrics.json"
    metrics = read_json(mpath)
    if not isinstance(metrics, dict):
        raise ReportInputError(mpath, "expected a JSON object")
    for key in ("filter", "scenario"):
        if not isinstance(metrics.get(key), str):
            raise ReportInputError(mpath, f"{key}: missing or not a string")
    estimate = innovations = None
    if metrics.get("status") != "skipped":
        estimate = _table(run_dir / "estimate.parquet", TableName.ESTIMATOR)
        innovations = _table(run_dir / "innovations.parquet")
        if estimate is None:
            raise ReportInputError(run_dir, "has metrics.json but no estimate.parquet")
    t_first = int(estimate.column("t_ns")[0].as_py()) if estimate and estimate.num_rows else None
    return Run(
        run_dir,
        metrics["filter"],
        metrics["scenario"],
        metrics,
        estimate,
        innovations,
        _windows(mpath, metrics, t_first),
    )


#: what a smoothed run's name adds to its filter's
SMOOTHED = " smoothed"


def smoothed_run(run: Run) -> Run | None:
    """The smoothed estimate of ``run`` (``smoothed.parquet``) as a run of its own, named
    ``<filter> smoothed``: the forward run's metrics with those of ``metrics.json``
    ``smoothed`` in their place (accuracy, consistency, outage windows); no innovations (they
    are the forward filter's). None if the run was not smoothed."""
    sm = run.metrics.get("smoothed")
    path = run.path / "smoothed.parquet"
    if not isinstance(sm, dict) or not path.is_file():
        return None
    estimate = _table(path, TableName.ESTIMATOR)
    name = run.filter + SMOOTHED
    metrics = {**run.metrics, **sm, "filter": name}
    metrics.pop("smoothed", None)
    if "outage_windows" not in sm:
        metrics.pop("outage_windows", None)
    t_first = int(estimate.column("t_ns")[0].as_py()) if estimate and estimate.num_rows else None
    windows = _windows(run.path / "metrics.json", metrics, t_first)
    return Run(run.path, name, run.scenario, metrics, estimate, None, windows)


def load_runs(runs_dir: Path) -> list[Run]:
    """Every run under ``runs_dir``, sorted by (filter, scenario); none if it is absent."""
    if not runs_dir.is_dir():
        return []
    runs = [load_run(p.parent) for p in sorted(runs_dir.rglob("metrics.json"))]
    runs += [s for s in map(smoothed_run, runs) if s is not None]
    seen: dict[tuple[str, str], Path] = {}
    for r in runs:
        key = (r.filter, r.scenario)
        if key in seen:
            raise ReportInputError(
                r.path, f"a second run of {r.filter} under {r.scenario} (first: {seen[key]})"
            )
        seen[key] = r.path
    return sorted(runs, key=lambda r: (r.filter, r.scenario != "nominal", r.scenario))


def load_dataset(
    dataset: str, tables_dir: Path, runs_dir: Path | None, experiments_dir: Path | None
) -> DatasetInputs:
    """Load the inputs of one dataset's report (see the module docstring)."""
    meta = None
    if (tables_dir / META_NAME).is_file():
        try:
            meta = read_meta(tables_dir)
        except IngestError as err:
            raise ReportInputError(tables_dir / META_NAME, str(err)) from err
    report = None
    if (tables_dir / REPORT_NAME).is_file():
        report = read_json(tables_dir / REPORT_NAME)
        if not isinstance(report, dict):
            raise ReportInputError(tables_dir / REPORT_NAME, "expected a JSON object")
    return DatasetInputs(
        dataset=dataset,
        tables_dir=tables_dir,
        meta=meta,
        ingest_report=report,
        truth=_table(tables_dir / "truth.parquet", TableName.TRUTH),
        gnss=_table(tables_dir / "gnss.parquet", TableName.GNSS),
        runs=load_runs(runs_dir) if runs_dir is not None else [],
        onboard=_table(tables_dir / "estimator.parquet", TableName.ESTIMATOR),
        experiments=load_experiments(experiments_dir) if experiments_dir is not None else [],
        events=_table(tables_dir / "events.parquet", ContextName.EVENTS),
        vibration=_table(tables_dir / "vibration.parquet", ContextName.VIBRATION),
    )


def column(table: pa.Table, name: str) -> np.ndarray:
    """A numeric column as float64 (nulls as NaN); a missing column is all NaN."""
    if name not in table.column_names:
        return np.full(table.num_rows, math.nan)
    return np.asarray(table.column(name).to_numpy(zero_copy_only=False), dtype=np.float64)


def times_ns(table: pa.Table) -> np.ndarray:
    return np.asarray(table.column("t_ns").to_numpy(), dtype=np.int64)
