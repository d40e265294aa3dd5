"""One-off post-mission analysis: ingest a log, run the filters that fit it, render a report.

``analyze(logs, out_dir, ...)`` writes ``out_dir/tables`` (``navreplay ingest``),
``out_dir/runs/<filter>/<scenario>`` (``navreplay run``) and ``out_dir/report``
(``navreplay report``), reporting progress through ``progress`` (one line per step and per
filter run) and returning what the summary needs.

Which filters fit (``plan``): the INS/GNSS filters need an ``imu`` table; loosely coupled
ones (``lc_*``) need ``gnss`` fixes, tightly coupled ones (``tc_*``) need ``gnss_obs`` with
satellite positions; the ``*_nhc`` variants need a ground vehicle (or an unknown platform). A
filter that does not fit is skipped with the reason, never run on
data it cannot use. Each filter replays under each scenario (``pipeline.outages.runs``: the
scenario engine applies outage windows, k-satellite windows or faults to the tables first);
a scenario the log cannot support (e.g. k satellites without raw observables) or a run that
fails is skipped with its reason, and the others go on.

Outage scenarios are fitted to the log first (``pipeline.scenarios.fit``): a log too short
for a scenario's windows gets fewer or shorter ones, each change stated in ``notes``; the
``outages`` asked for (``--outage 30s``, ``30s@45s``) are added as scenarios of their own.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pyarrow.parquet as pq

from navreplay.ingest.api import IngestOptions, ingest
from navreplay.ingest.config import DatasetConfig
from navreplay.ingest.meta import META_NAME, read_meta
from navreplay.ingest.platform import UNKNOWN, Platform
from navreplay.ingest.tables import params_hash
from navreplay.ingest.typed import to_plain
from navreplay.pipeline.errors import DivergenceError, ParamsError, PipelineError
from navreplay.pipeline.estimation.ins.config import FILTER_KINDS
from navreplay.pipeline.params import Params
from navreplay.pipeline.report.render import RenderedReport

if TYPE_CHECKING:
    from navreplay.pipeline.estimation.core.contract import RunInputs
    from navreplay.pipeline.scenarios.config import ScenariosParams

Progress = Callable[[str], None]

#: the platforms the non-holonomic constraint may be fused on (unknown: the user's choice)
NHC_PLATFORMS = ("ground", "unknown")
NHC_REASON = "the non-holonomic constraint holds for ground vehicles"


@dataclass
class Skipped:
    """A filter or scenario that was not run, and why."""

    filter: str
    scenario: str
    reason: str


@dataclass
class AnalysisResult:
    """What ``analyze`` did: the report, the runs, the skips."""

    tables_dir: Path
    report: RenderedReport
    skipped: list[Skipped] = field(default_factory=list)
    seconds: float = 0.0
    notes: list[str] = field(default_factory=list)


def _has_sat_positions(tables_dir: Path) -> bool:
    path = tables_dir / "gnss_obs.parquet"
    if not path.is_file():
        return False
    col = pq.read_table(path, columns=["sat_x_m"]).column("sat_x_m")
    return len(col) > 0 and col.null_count < len(col)


def _limits(tables_dir: Path) -> dict[str, str]:
    """What the ingest found a log cannot give a replay (``ingest_report.json`` ``limits``):
    code -> reason."""
    path = tables_dir / "ingest_report.json"
    if not path.is_file():
        return {}
    report = json.loads(path.read_text(encoding="utf-8"))
    return {str(x["code"]): str(x["reason"]) for x in report.get("limits", [])}


def plan(tables_dir: Path, filters: Sequence[str]) -> tuple[list[str], list[Skipped]]:
    """The filters of ``filters`` that fit the tables, and the others with the reason (the
    ingest's own where it said why a table is missing or unusable). The ``*_nhc`` filters fit
    only a ``ground`` or ``unknown`` platform (``meta.json`` ``sensors.platform``)."""
    have = {p.stem for p in tables_dir.glob("*.parquet")}
    limits = _limits(tables_dir)
    platform = _platform(tables_dir)
    run, skip = [], []
    for f in filters:
        kind = FILTER_KINDS.get(f)
        if kind is None:
            skip.append(Skipped(f, "*", "not an INS/GNSS filter analyze can run yet"))
        elif "imu" not in have:
            why = limits.get("imu_refused", "the log has no IMU stream")
            skip.append(Skipped(f, "*", why))
        elif kind.coupling == "loose" and "gnss_no_fix" in limits:
            skip.append(
                Skipped(f, "*", f"loose coupling needs GNSS fixes: {limits['gnss_no_fix']}")
            )
        elif kind.coupling == "loose" and "gnss" not in have:
            skip.append(Skipped(f, "*", "loose coupling needs GNSS fixes; the log has none"))
        elif kind.coupling == "tight" and not _has_sat_positions(tables_dir):
            why = (
                "raw observables without satellite positions (no ephemeris)"
                if "gnss_obs" in have
                else "no raw GNSS observables"
            )
            skip.append(Skipped(f, "*", f"tight coupling needs pseudoranges and orbits: {why}"))
        elif kind.nhc and platform.kind not in NHC_PLATFORMS:
            skip.append(Skipped(f, "*", f"{NHC_REASON}; this log is a {platform.text()}"))
        else:
            run.append(f)
    return run, skip


def _platform(tables_dir: Path) -> Platform:
    """The vehicle kind ingest recorded in ``meta.json`` (unknown without one)."""
    if not (tables_dir / META_NAME).is_file():
        return UNKNOWN
    return read_meta(tables_dir).sensors.platform


def write_skip(run_dir: Path, s: Skipped) -> None:
    """``run_dir/metrics.json`` of a run that was not made: status skipped and the reason."""
    from navreplay.ingest.atomic import atomic_write_json

    run_dir.mkdir(parents=True, exist_ok=True)
    atomic_write_json(
        run_dir / "metrics.json",
        {"filter": s.filter, "scenario": s.scenario, "status": "skipped", "reason": s.reason},
    )


def analyze(
    logs: Sequence[Path],
    out_dir: Path,
    params: Params,
    *,
    filters: Sequence[str] | None = None,
    scenarios: Sequence[str] | None = None,
    outages: Sequence[str] = (),
    smooth: bool = False,
    config: DatasetConfig | None = None,
    config_dir: Path | None = None,
    progress: Progress = lambda _: None,
    name: str | None = None,
) -> AnalysisResult:
    """Ingest, run and report one log (see the module docstring); ``outages`` are
    ``--outage`` texts (``pipeline.scenarios.fit.parse_outage``); ``smooth``: every INS
    filter smoothed as well (``filters.<name>.smooth``); ``name``: the dataset's name in the
    report (default: the dataset config's id, else the first log's stem)."""
    from navreplay.pipeline.estimation.core.contract import RunInputs, write_run
    from navreplay.pipeline.estimation.ins.run import INPUTS
    from navreplay.pipeline.outages.runs import run_scenarios
    from navreplay.pipeline.report.inputs import load_dataset
    from navreplay.pipeline.report.render import render_dataset

    t_start = time.perf_counter()
    filters = list(filters or params.run.filters)
    named, scenarios, extra = _scenarios(params, scenarios, outages)
    tables_dir = out_dir / "tables"
    progress(f"ingest {', '.join(str(p) for p in logs)}")
    options = IngestOptions(
        strict=params.ingest.strict,
        reorder_window_s=params.ingest.reorder_window_s,
        gap_factor=params.ingest.gap_factor,
    )
    result = ingest(logs, tables_dir, config=config, config_dir=config_dir, options=options)
    rows = ", ".join(f"{k} {v:,}" for k, v in sorted(result.tables.items()))
    progress(f"ingest done: {rows}")
    runnable, skipped = plan(tables_dir, filters)
    runs_dir = out_dir / "runs"
    inputs = RunInputs.read(tables_dir, INPUTS) if runnable else None
    notes: list[str] = []
    if inputs is not None:
        named, scenarios, notes = _fit(inputs, named, scenarios, extra, runnable, skipped, runs_dir)
        for note in notes:
            progress(f"note: {note}")
    todo = [(f, s) for f in runnable for s in scenarios]
    for i, (f, sc) in enumerate(todo, start=1):
        assert inputs is not None  # read above whenever there is something to run
        run_dir = runs_dir / f / sc
        progress(f"run {i}/{len(todo)}: {f} under {sc}")
        t0 = time.perf_counter()
        section = replace(params.filters.get(f), smooth=True) if smooth else params.filters.get(f)
        try:
            ((_, out, applied),) = run_scenarios(
                inputs, f, section, named, [sc], params.run.backend
            )
        except (DivergenceError, PipelineError) as err:
            s = Skipped(f, sc, f"failed: {err}")
            skipped.append(s)
            write_skip(run_dir, s)
            progress(f"  {f} under {sc}: {err}")
            continue
        if named.get(sc).windows is not None and not applied.outage_windows:
            s = Skipped(f, sc, "none of the scenario's outage windows fits in this log")
            skipped.append(s)
            write_skip(run_dir, s)
            progress(f"  {f} under {sc}: {s.reason}")
            continue
        write_run(run_dir, out, section, sc, applied.metadata()["windows"])
        progress(f"  {f}: {_one_line(out.metrics)} ({time.perf_counter() - t0:.1f} s)")
    for s in skipped:
        if s.scenario == "*":
            write_skip(runs_dir / s.filter / "nominal", Skipped(s.filter, "nominal", s.reason))
    progress("report")
    dataset = name or (config.id if config is not None else logs[0].stem)
    data = load_dataset(dataset, tables_dir, runs_dir, out_dir / "experiments")
    report = render_dataset(
        data,
        out_dir / "report",
        params_hash=params_hash(to_plain(params)),
        title=f"navreplay analysis: {', '.join(p.name for p in logs)}",
    )
    return AnalysisResult(tables_dir, report, skipped, time.perf_counter() - t_start, notes)


def _scenarios(
    params: Params, scenarios: Sequence[str] | None, outages: Sequence[str]
) -> tuple[ScenariosParams, list[str], list[str]]:
    """The scenarios section with the outages asked for added, the scenarios to run and the
    names of those outages."""
    from navreplay.pipeline.scenarios.fit import with_outages

    names = list(scenarios or params.run.scenarios)
    try:
        named, extra = with_outages(params.scenarios, [*params.scenarios.fit.outages, *outages])
    except ValueError as err:
        raise ParamsError("scenarios.fit.outages", str(err)) from err
    names += [sc for sc in extra if sc not in names]
    unknown = [sc for sc in names if sc not in named.named]
    if unknown:
        known = ", ".join(named.named)
        raise ParamsError("scenarios.named", f"no scenario {unknown} (known: {known})")
    return named, names, extra


def _fit(
    inputs: RunInputs,
    named: ScenariosParams,
    scenarios: list[str],
    extra: list[str],
    runnable: list[str],
    skipped: list[Skipped],
    runs_dir: Path,
) -> tuple[ScenariosParams, list[str], list[str]]:
    """The scenarios fitted to the log (``scenarios.fit``), those that still run and the
    notes; a scenario none of whose windows fits is skipped (and written) for every filter."""
    from navreplay.pipeline.scenarios.fit import fit_scenarios

    fitted = fit_scenarios(inputs.tables, named, scenarios, as_many_as_fit=extra)
    for sc, why in fitted.unfit.items():
        for f in runnable:
            s = Skipped(f, sc, why)
            skipped.append(s)
            write_skip(runs_dir / f / sc, s)
    kept = [sc for sc in scenarios if sc not in fitted.unfit]
    return fitted.scenarios, kept, list(fitted.notes)


def _one_line(m: dict[str, Any]) -> str:
    parts = [str(m.get("status"))]
    if m.get("pos_err_h_rms_m") is not None:
        parts.append(f"horizontal RMS {m['pos_err_h_rms_m']:.2f} m vs truth")
    if m.get("realtime_factor"):
        parts.append(f"{m['realtime_factor']:.0f}x real time")
    return ", ".join(parts)
