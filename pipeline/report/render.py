"""One dataset's report: ``index.html`` and ``tables/`` (CSV and JSON of every number shown).

``render_dataset(data, out_dir, ...)`` writes, atomically (``ingest.atomic.atomic_directory``):

- ``index.html``: self-contained (inline CSS, script and SVG; no network);
- ``tables/runs.csv|json`` (one row per run: accuracy, consistency, gating, cost),
  ``tables/nis.csv`` (per run and stream), ``tables/windows.csv`` (per outage window),
  ``tables/drift_by_length.csv`` (complete outages of the runs by length), the outages
  stage's ``tables/sat_reduction.csv`` and ``tables/drift_vs_length.csv`` copied as they are
  (when ``experiments_dir`` holds them: ``experiments.find_outage_results``),
  ``tables/onboard_comparison.csv`` (each run against the log's own estimate, when the
  dataset has an ``estimator`` table: ``report.onboard``), ``tables/audit.csv`` and
  ``tables/provenance.json``;
- ``trajectories/truth.tum`` and ``trajectories/onboard.tum``: the references as TUM
  trajectories (``ingest.writers.tum``), to compare with each run's ``trajectory.tum`` in
  evo (``evo_ape tum trajectories/truth.tum <run>/trajectory.tum``);
- ``metrics.json``: the headline numbers per filter and scenario, flat, for
  ``dvc metrics show/diff``.

Sections appear only when their data exist. The same inputs give the same bytes: figures are
byte-stable (``svg``), tables are sorted, JSON is written with sorted keys, and nothing
records the time of rendering.
"""

from __future__ import annotations

import logging
import shutil
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from navreplay.ingest.atomic import atomic_directory, atomic_write_json, atomic_write_text
from navreplay.ingest.tables import git_commit, package_version
from navreplay.ingest.writers.tum import write_tum
from navreplay.pipeline.report import (
    audit,
    events,
    figures,
    figures_context,
    figures_outage,
    onboard,
    sections,
)
from navreplay.pipeline.report import html as h
from navreplay.pipeline.report import tables as tb
from navreplay.pipeline.report.experiments import (
    DRIFT_NAME,
    SAT_REDUCTION_NAME,
    find_outage_results,
)
from navreplay.pipeline.report.inputs import SMOOTHED, DatasetInputs
from navreplay.pipeline.report.series import ErrorSeries

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class RenderedReport:
    """What was written, and what ``navreplay analyze`` prints at the end."""

    out_dir: Path
    index: Path
    runs: list[dict[str, Any]]
    warnings: list[str]
    figures: int
    onboard: list[dict[str, Any]]
    log_account: str | None = None  # the log's own account in a line (``events.summary``)


def _headline(rows: Sequence[dict[str, Any]]) -> dict[str, Any]:
    keys = ("pos_err_h_rms_m", "pos_err_3d_rms_m", "pos_err_3d_max_m", "nees_mean",
            "realtime_factor", "gate_rejections")  # fmt: skip
    out: dict[str, Any] = {}
    for r in rows:
        vals = {k: r[k] for k in keys if r.get(k) is not None}
        if vals:
            out.setdefault(str(r["filter"]), {})[str(r["scenario"])] = vals
    return out


def _subtitle(data: DatasetInputs, version: str) -> str:
    """What ran: the filters' runs (a smoothed run counts beside its filter's)."""
    forward = [r for r in data.runs if not r.filter.endswith(SMOOTHED)]
    ran = sum(r.ran for r in forward)
    not_ran = f" ({len(forward) - ran} did not run)" if ran < len(forward) else ""
    n_smoothed = len(data.runs) - len(forward)
    smoothed = f", {n_smoothed} of them smoothed" if n_smoothed else ""
    n_filters = len({r.filter for r in forward})
    return (
        f"{ran} runs{not_ran} of {n_filters} filters under {len(data.scenarios())} "
        f"scenarios{smoothed}; navreplay {version}"
    )


def render_dataset(
    data: DatasetInputs,
    out_dir: Path,
    *,
    experiments_dir: Path | None = None,
    params_hash: str | None = None,
    title: str | None = None,
) -> RenderedReport:
    """Render the report of ``data`` into ``out_dir`` (see the module docstring)."""
    series = tb.all_series(data)
    run_rows = tb.metrics_rows(data, series)
    nis_rows = tb.nis_rows(data.runs)
    win_rows = tb.window_rows(data, series)
    drift_rows = tb.drift_by_length(win_rows)
    onboard_rows = onboard.comparison_rows(data, onboard.differences(data))
    outage = find_outage_results(experiments_dir)
    audit_rows = audit.audit_rows(data.ingest_report)
    filters = data.filters()
    figs: list[str] = []

    def fig(svg: str | None, caption: str) -> str:
        if svg is None:
            return ""
        figs.append(svg)
        return h.figure(svg, caption)

    track = fig(
        figures.track(data, "track"),
        "Track: reference, the onboard estimate where the log has one, and each filter's nominal "
        "run (east/north from the first sample).",
    )

    context = fig(
        figures_context.context(data, "context"),
        "The receiver's satellites, fix type and reported accuracy, the height of the fixes, "
        "the onboard estimate and each filter's nominal run, the measurements each filter's "
        "gate rejected, and the log's modes, arming, events, messages and vibration where it "
        "has them, on one time axis; outage windows shaded.",
    )
    log_events = events.event_rows(data)
    vibration = events.vibration_rows(data)
    context += events.section(log_events, vibration)

    def per_scenario(
        plot: Callable[[DatasetInputs, str, dict[tuple[str, str], ErrorSeries], str], str | None],
        key: str,
        caption: Callable[[str], str],
    ) -> list[str]:
        """One figure per scenario, keys ``<key>0``, ``<key>1`` ..."""
        scenarios = enumerate(data.scenarios())
        return [fig(plot(data, sc, series, f"{key}{i}"), caption(sc)) for i, sc in scenarios]

    err_parts = per_scenario(
        figures.errors,
        "err",
        lambda sc: (
            f"{sc}: horizontal position error (line) and the filter's 3σ (band); "
            "outage windows shaded."
        ),
    )
    outage_parts = per_scenario(
        figures_outage.windows_detail,
        "win",
        lambda sc: (
            f"{sc}: 3-D error (horizontal where the reference has no heights) from "
            f"{figures_outage.PRE_S:g} s before to {figures_outage.POST_S:g} s after each "
            "outage window."
        ),
    )
    drift_fig = fig(
        figures_outage.drift_by_length(drift_rows, filters, "drift"),
        "Mean 3-D error at the end of complete outages, by outage length.",
    )
    nis_parts = [
        fig(figures.nis(data, r, f"nis{j}"), f"NIS of {r.filter} ({r.scenario}) per stream.")
        for j, r in enumerate(r for r in data.runs if r.scenario == "nominal" and r.ran)
    ]
    bias_fig = fig(
        figures.biases(data, "bias"),
        "IMU bias estimates with ±3σ bands; dashed: the true biases where the dataset has them.",
    )
    exp_html = sections.experiments(data.experiments, figs)
    provenance = {
        "dataset": data.dataset,
        "package_version": package_version(),
        "git_commit": git_commit(),
        "params_hash": params_hash,
        "time_base": data.meta.time_base if data.meta else None,
        "sources": [
            {"name": s.name, "sha256": s.sha256, "format": s.format}
            for s in (data.meta.sources if data.meta else ())
        ],
        "runs": [
            {
                "filter": r.filter,
                "scenario": r.scenario,
                "params_hash": r.metrics.get("params_hash"),
                "backend": r.metrics.get("backend"),
                "path": r.path.name,
            }
            for r in data.runs
        ],
    }
    warnings = audit.warnings(data)
    body = [
        ("verdict", "Verdict", sections.verdict_section(data, run_rows, win_rows, warnings)),
        ("overview", "Overview", sections.overview(data, run_rows)),
        ("audit", "Data quality", audit.audit_section(data)),
        ("context", "Log context", context),
        ("track", "Track", track),
        ("metrics", "Accuracy and consistency", sections.metrics(run_rows)),
        (
            "onboard",
            "Against the onboard estimate",
            sections.onboard(
                onboard_rows, onboard.test_ratio_rows(data), onboard.innovation_rows(data)
            ),
        ),
        ("noise", "Noise models", sections.noise(data.runs)),
        ("errors", "Errors against time", "".join(err_parts)),
        ("outages", "Outage windows", sections.windows(win_rows) + "".join(outage_parts)),
        (
            "drift",
            "Drift against outage length",
            sections.drift(drift_rows, outage.drift) + drift_fig,
        ),
        (
            "satellites",
            "Error reduction per satellite count",
            sections.sat_reduction(outage.sat_reduction, outage.sat_reduction_note),
        ),
        ("nis", "Innovation consistency (NIS)", sections.nis(nis_rows) + "".join(nis_parts)),
        ("biases", "Bias estimates", bias_fig),
        ("experiments", "Experiments", exp_html),
        ("cost", "Run cost", sections.cost(run_rows)),
        ("provenance", "Provenance", sections.provenance(provenance)),
    ]
    subtitle = _subtitle(data, str(provenance["package_version"]))
    page = h.page(title or f"navreplay report: {data.dataset}", subtitle, body, opened=_OPENED)
    tables = {
        "runs.csv": tb.to_csv(run_rows),
        "nis.csv": tb.to_csv(nis_rows, _NIS_COLS),
        "windows.csv": tb.to_csv(win_rows, _WIN_COLS),
        "drift_by_length.csv": tb.to_csv(drift_rows, _DRIFT),
        "audit.csv": tb.to_csv(audit_rows, _AUDIT),
    }
    if onboard_rows:
        tables[onboard.CSV_NAME] = tb.to_csv(onboard_rows, onboard.COLUMNS)
    if log_events:
        tables["events.csv"] = tb.to_csv(log_events, events.COLUMNS)
    with atomic_directory(out_dir) as tmp:
        (tmp / "tables").mkdir()
        atomic_write_text(tmp / "index.html", page)
        for name, text in tables.items():
            atomic_write_text(tmp / "tables" / name, text)
        atomic_write_json(tmp / "tables" / "runs.json", run_rows)
        atomic_write_json(tmp / "tables" / "provenance.json", provenance)
        _copy_inputs(tmp, data, experiments_dir)
        atomic_write_json(tmp / "metrics.json", _headline(run_rows))
    log.info("wrote %s (%d figures)", out_dir / "index.html", len(figs))
    return RenderedReport(
        out_dir,
        out_dir / "index.html",
        run_rows,
        warnings,
        len(figs),
        onboard_rows,
        events.summary(log_events, vibration),
    )


def _copy_inputs(tmp: Path, data: DatasetInputs, experiments_dir: Path | None) -> None:
    """The experiments' and the outages stage's tables as they are, and the references as TUM
    trajectories (evo: ``evo_ape tum trajectories/truth.tum <run>/trajectory.tum``)."""
    for e in data.experiments:
        for t in e.tables:
            dest = tmp / "tables" / "experiments" / e.name / t.path.name
            dest.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(t.path, dest)
            if t.path.with_suffix(".json").is_file():  # the same rows as JSON
                shutil.copyfile(t.path.with_suffix(".json"), dest.with_suffix(".json"))
    outage = find_outage_results(experiments_dir)
    for table, name in ((outage.sat_reduction, SAT_REDUCTION_NAME), (outage.drift, DRIFT_NAME)):
        if table is not None:
            shutil.copyfile(table.path, tmp / "tables" / name)
    for ref, name in ((data.truth, "truth"), (data.onboard, "onboard")):
        if ref is not None and ref.num_rows:
            (tmp / "trajectories").mkdir(exist_ok=True)
            write_tum(tmp / "trajectories" / f"{name}.tum", ref)


# the sections shown open under the verdict; the others fold until opened
_OPENED = ("overview", "metrics", "onboard")
_NIS_COLS = ("filter", "scenario", "stream", "count", "nis_mean", "dof_mean", "bound_low",
             "bound_high", "consistent", "rejected")  # fmt: skip
_WIN_COLS = ("filter", "scenario", "window", "start_s", "duration_s", "sats", "err_end_m",
             "err_max_m", "err_mean_m", "err_rms_m", "drift_pct_distance", "reconverge_s",
             "inside_3sigma_frac", "reference")  # fmt: skip
_DRIFT = ("filter", "outage_s", "windows", "err_end_mean_m", "ci_low_m", "ci_high_m")
_AUDIT = tuple(k for k, _ in audit.COLUMNS)
