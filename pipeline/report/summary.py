"""The cross-dataset summary: filters ranked with paired differences and intervals.

Reads each dataset report's ``tables/runs.json`` (``render``) and ``tables/sat_reduction.csv``.
A *cell* is one (dataset, scenario) in which several filters ran; filters are compared only
inside cells, on the same data (paired), and only on errors against a truth: a run of a log
without one reports residuals to the fixes it fused (``reference`` ``fixes_residual``), which
rank how closely a filter follows its inputs, not how accurate it is, so such runs are listed
but never ranked (``not_ranked``). Smoothed runs (``<filter> smoothed``) are listed, never
ranked: they saw the fixes after every outage.

- rank: per cell, filters ranked by 3-D RMS position error, or by horizontal RMS in a cell
  where a filter has no 3-D error (the planar vehicle-model and cascaded filters) (1 = best,
  ties share the mean rank); the table gives the mean rank, the cells it rests on, and the
  cells won;
- paired difference of B against A over their common cells: the log-ratio
  ``ln(e_B / e_A)`` per cell, its mean with a 95 % t-interval, reported as the ratio
  ``exp(mean)`` (below 1: B is better), and the mean difference in metres with its interval.
  One cell gives a point value without an interval.

For the logs without truth, filters are ranked the same way on their drift against the
onboard estimate at the ends of the outage windows (``onboard_cells``, from each report's
``tables/onboard_comparison.csv``): a leaderboard across logs, labelled as against another
estimate. Also the per-satellite-count reduction table of every dataset that has one (paper 001).
Writes ``index.html``, ``tables/ranking.csv``, ``tables/paired.csv``, ``tables/runs.csv``
(every finished run of every dataset, the data of ``dvc plots``),
``tables/sat_reduction.csv`` and ``metrics.json`` (the ranking, for ``dvc metrics``).
"""

from __future__ import annotations

import itertools
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from navreplay.ingest.atomic import atomic_directory, atomic_write_json, atomic_write_text
from navreplay.ingest.tables import git_commit, package_version
from navreplay.pipeline.estimation.core.integrity import FINISHED
from navreplay.pipeline.report import figures_outage
from navreplay.pipeline.report import html as h
from navreplay.pipeline.report import tables as tb
from navreplay.pipeline.report.experiments import SAT_REDUCTION_NAME, read_csv
from navreplay.pipeline.report.input_files import ReportInputError, read_json
from navreplay.pipeline.report.inputs import SMOOTHED
from navreplay.pipeline.report.onboard import CSV_NAME as ONBOARD_NAME
from navreplay.pipeline.report.sections import paper_pct
from navreplay.pipeline.report.tables import PAPER_PAIR, PAPER_REDUCTION_PCT

Row = dict[str, Any]
METRIC = "pos_err_3d_rms_m"
#: the cell's metric where some filter of it has no 3-D error (planar models)
METRIC_H = "pos_err_h_rms_m"


@dataclass(frozen=True)
class DatasetResult:
    """One dataset report's numbers."""

    dataset: str
    path: Path
    runs: list[Row]
    sat_reduction: tuple[tuple[str, ...], tuple[tuple[str, ...], ...]] | None
    onboard_windows: list[Row] = field(default_factory=list)


def load_report(report_dir: Path) -> DatasetResult:
    """A dataset report directory written by ``render.render_dataset``."""
    path = report_dir / "tables" / "runs.json"
    if not path.is_file():
        raise ReportInputError(path, "missing: not a dataset report directory (run the report)")
    runs = read_json(path)
    if not isinstance(runs, list) or not all(isinstance(r, dict) for r in runs):
        raise ReportInputError(path, "expected a list of run rows")
    prov = read_json(report_dir / "tables" / "provenance.json")
    dataset = str(prov.get("dataset", report_dir.name)) if isinstance(prov, dict) else ""
    red_path = report_dir / "tables" / SAT_REDUCTION_NAME
    red = None
    if red_path.is_file():
        t = read_csv(red_path)
        red = (t.header, t.rows)
    windows: list[Row] = []
    onboard_path = report_dir / "tables" / ONBOARD_NAME
    if onboard_path.is_file():
        t = read_csv(onboard_path)
        rows = [dict(zip(t.header, r, strict=True)) for r in t.rows]
        windows = [r for r in rows if r.get("scope") == "window"]
    return DatasetResult(dataset or report_dir.name, report_dir, runs, red, windows)


_RUN_COLS = ("run", "dataset", "filter", "scenario", "pos_err_h_rms_m", "pos_err_3d_rms_m",
             "pos_err_3d_max_m", "nees_mean", "realtime_factor")  # fmt: skip


def _finite(v: Any) -> bool:
    return isinstance(v, int | float) and math.isfinite(v)


def _against_truth(run: Row) -> bool:
    """Whether a run's errors are against a truth (a report before the ``reference`` column
    had only those)."""
    return bool(run.get("reference", "truth") == "truth")


def not_ranked(results: Sequence[DatasetResult]) -> list[str]:
    """The datasets with finished runs whose errors are residuals, not errors (no truth)."""
    return [
        d.dataset
        for d in results
        if any(r.get("status") in FINISHED and not _against_truth(r) for r in d.runs)
    ]


def _cells(results: Sequence[DatasetResult]) -> dict[tuple[str, str], dict[str, float]]:
    """Per (dataset, scenario) with two or more finished runs: each filter's error, the 3-D
    RMS where every run of the cell has one, else the horizontal RMS."""
    runs: dict[tuple[str, str], dict[str, Row]] = {}
    for d in results:
        for r in d.runs:
            if not _against_truth(r) or str(r["filter"]).endswith(SMOOTHED):
                continue  # a smoothed run knew the fixes after each outage: not a filter
            if r.get("status") in FINISHED and (_finite(r.get(METRIC)) or _finite(r.get(METRIC_H))):
                runs.setdefault((d.dataset, str(r["scenario"])), {})[str(r["filter"])] = r
    cells: dict[tuple[str, str], dict[str, float]] = {}
    for key, by_filter in sorted(runs.items()):
        metric = METRIC if all(_finite(r.get(METRIC)) for r in by_filter.values()) else METRIC_H
        errs = {f: float(r[metric]) for f, r in by_filter.items() if _finite(r.get(metric))}
        if len(errs) >= 2:
            cells[key] = errs
    return cells


def onboard_cells(results: Sequence[DatasetResult]) -> dict[tuple[str, str], dict[str, float]]:
    """Per (dataset, scenario) of a log without truth where two or more filters drifted
    through outage windows: each filter's mean 3-D difference from the onboard estimate at
    the windows' ends (``report.onboard``; the onboard EKF kept GNSS through them)."""
    ends: dict[tuple[str, str], dict[str, list[float]]] = {}
    for d in results:
        if d.dataset not in not_ranked(results):
            continue  # a dataset with a truth is ranked on its errors
        for w in d.onboard_windows:
            try:
                end = float(w.get("pos_3d_end_m", ""))
            except ValueError:
                continue
            if math.isfinite(end) and not str(w["filter"]).endswith(SMOOTHED):
                by = ends.setdefault((d.dataset, str(w["scenario"])), {})
                by.setdefault(str(w["filter"]), []).append(end)
    return {
        key: {f: float(np.mean(v)) for f, v in by.items()}
        for key, by in sorted(ends.items())
        if len(by) >= 2
    }


def ranking(cells: dict[tuple[str, str], dict[str, float]]) -> list[Row]:
    """Mean rank per filter over the cells (see the module docstring), best first."""
    from scipy.stats import rankdata  # scipy.stats takes seconds to import (distributions)

    ranks: dict[str, list[float]] = {}
    wins: dict[str, int] = {}
    for errs in cells.values():
        names = sorted(errs)
        r = rankdata([errs[n] for n in names])
        for n, rk in zip(names, r, strict=True):
            ranks.setdefault(n, []).append(float(rk))
        best = min(names, key=lambda n: (errs[n], n))
        wins[best] = wins.get(best, 0) + 1
    rows = [
        {
            "filter": f,
            "mean_rank": float(np.mean(rs)),
            "cells": len(rs),
            "wins": wins.get(f, 0),
            "datasets": len({c[0] for c, e in cells.items() if f in e}),
        }
        for f, rs in ranks.items()
    ]
    return sorted(rows, key=lambda r: (r["mean_rank"], -r["cells"], r["filter"]))


def paired(cells: dict[tuple[str, str], dict[str, float]], order: Sequence[str]) -> list[Row]:
    """Every pair (A better-ranked, B) with common cells: ratio and difference intervals."""
    rows = []
    for a, b in itertools.combinations(order, 2):
        common = [e for e in cells.values() if a in e and b in e]
        if not common:
            continue
        ea = np.array([e[a] for e in common])
        eb = np.array([e[b] for e in common])
        lm, llo, lhi = tb.t_interval(np.log(eb / ea))
        dm, dlo, dhi = tb.t_interval(eb - ea)
        rows.append(
            {
                "a": a,
                "b": b,
                "cells": len(common),
                "ratio_b_over_a": math.exp(lm),
                "ratio_ci_low": math.exp(llo) if math.isfinite(llo) else math.nan,
                "ratio_ci_high": math.exp(lhi) if math.isfinite(lhi) else math.nan,
                "diff_m": dm,
                "diff_ci_low_m": dlo,
                "diff_ci_high_m": dhi,
            }
        )
    return rows


def _unranked_note(results: Sequence[DatasetResult]) -> str:
    names = not_ranked(results)
    if not names:
        return ""
    return (
        f" Not ranked: {', '.join(names)}. They have no truth, so their errors are residuals "
        "to the fixes the filters fused (how closely a filter follows its inputs, not its "
        "accuracy); their reports compare each run with the onboard estimate."
    )


def render_summary(report_dirs: Sequence[Path], out_dir: Path) -> Path:
    """Write the summary (see the module docstring); returns the path of its index.html."""
    results = sorted((load_report(p) for p in report_dirs), key=lambda d: d.dataset)
    cells = _cells(results)
    rank = ranking(cells)
    pairs = paired(cells, [r["filter"] for r in rank])
    best = rank[0]["filter"] if rank else None
    vs_best = [p for p in pairs if p["a"] == best]
    all_runs = [
        {"run": f"{d.dataset}/{r['filter']}/{r['scenario']}", "dataset": d.dataset, **r}
        for d in results
        for r in d.runs
        if r.get("status") in FINISHED
        and (r.get(METRIC) is not None or r.get(METRIC_H) is not None)
    ]
    onboard_rank = ranking(onboard_cells(results))
    onboard_html = ""
    if onboard_rank:
        onboard_html = h.table(
            onboard_rank,
            (
                ("filter", "filter"),
                ("mean_rank", "mean rank"),
                ("cells", "cells"),
                ("wins", "best in"),
                ("datasets", "logs"),
            ),
        ) + h.para(
            "For the logs without a truth: a cell is one log under one outage scenario; "
            "filters rank by their mean 3-D difference from the vehicle's onboard estimate at "
            "the ends of the outage windows (the onboard EKF kept GNSS there, so this is each "
            "filter's drift against an estimate that did: another estimate, not truth). "
            "tables/ranking_onboard.csv holds it.",
            "note",
        )
    red_rows: list[Row] = []
    for d in results:
        if d.sat_reduction is not None:
            header, rows = d.sat_reduction
            red_rows += [{"dataset": d.dataset, **dict(zip(header, r, strict=True))} for r in rows]
    ds_rows = [
        {
            "dataset": d.dataset,
            "runs": len(d.runs),
            "ok": sum(r.get("status") in FINISHED for r in d.runs),
            "filters": len({r["filter"] for r in d.runs}),
            "report": Path(os.path.relpath(d.path / "index.html", out_dir)).as_posix(),
        }
        for d in results
    ]
    pair_cols = (("a", "A"), ("b", "B"), ("cells", "cells"), ("ratio_b_over_a", "e_B / e_A"),
                 ("ratio_ci_low", "95 % low"), ("ratio_ci_high", "95 % high"),
                 ("diff_m", "e_B - e_A m"), ("diff_ci_low_m", "95 % low m"),
                 ("diff_ci_high_m", "95 % high m"))  # fmt: skip
    links = "".join(
        f'<li><a href="{h.esc(r["report"])}">{h.esc(r["dataset"])}</a>: {r["ok"]} of '
        f"{r['runs']} runs finished, {r['filters']} filters</li>"
        for r in ds_rows
    )
    red_html = ""
    if red_rows:
        keys = list(dict.fromkeys(k for r in red_rows for k in r))
        red_cells = [
            [
                *(str(r.get(k, "")) for k in keys),
                paper_pct(str(r.get("pair", "")), str(r.get("sats", ""))),
            ]
            for r in red_rows
        ]
        chart = figures_outage.sat_reduction(red_rows, PAPER_REDUCTION_PCT, "satred")
        red_html = (
            h.figure(
                chart,
                "Error reduction per satellite count with its 95 % interval, per "
                "dataset, beside paper 001's Table 1 (black bars).",
            )
            + h.text_table([*keys, "paper %"], red_cells)
            + h.para(f"Paper 001, Table 1 gives {' -> '.join(PAPER_PAIR)} only.", "note")
        )
    sections = [
        (
            "datasets",
            "Datasets",
            h.table(
                ds_rows,
                (
                    ("dataset", "dataset"),
                    ("runs", "runs"),
                    ("ok", "finished"),
                    ("filters", "filters"),
                ),
            )
            + f"<ul>{links}</ul>",
        ),
        (
            "ranking",
            "Filters ranked",
            h.table(
                rank,
                (
                    ("filter", "filter"),
                    ("mean_rank", "mean rank"),
                    ("cells", "cells"),
                    ("wins", "best in"),
                    ("datasets", "datasets"),
                ),
            )
            + h.para(
                "A cell is one dataset under one scenario; ranks by 3-D RMS position error "
                "against the truth among the filters that ran there, or by horizontal RMS "
                "where one of them has no 3-D error (the planar vehicle-model and cascaded "
                "filters) (1 = best)." + _unranked_note(results),
                "note",
            )
            if rank
            else (h.para(_unranked_note(results).strip(), "note") if not_ranked(results) else ""),
        ),
        (
            "paired",
            f"Paired differences against {best}" if best else "Paired differences",
            h.table(vs_best, pair_cols)
            + h.para(
                "Over the cells both filters ran in: the geometric-mean error ratio and the "
                "mean difference with 95 % t-intervals (no interval from one cell). Every pair "
                "is in tables/paired.csv.",
                "note",
            )
            if vs_best
            else "",
        ),
        ("onboard", "Logs without truth: drift against the onboard estimate", onboard_html),
        ("satellites", "Error reduction per satellite count", red_html),
        (
            "provenance",
            "Provenance",
            h.para(f"navreplay {package_version()}, git commit {git_commit() or 'n/a'}."),
        ),
    ]
    page = h.page(
        "navreplay: summary across datasets",
        f"{len(results)} datasets, {len(cells)} comparable cells",
        sections,
    )
    with atomic_directory(out_dir) as tmp:
        (tmp / "tables").mkdir()
        atomic_write_text(tmp / "index.html", page)
        atomic_write_text(tmp / "tables" / "ranking.csv", tb.to_csv(rank))
        if onboard_rank:
            atomic_write_text(tmp / "tables" / "ranking_onboard.csv", tb.to_csv(onboard_rank))
        atomic_write_text(tmp / "tables" / "runs.csv", tb.to_csv(all_runs, _RUN_COLS))
        atomic_write_text(
            tmp / "tables" / "paired.csv", tb.to_csv(pairs, [k for k, _ in pair_cols])
        )
        if red_rows:
            atomic_write_text(tmp / "tables" / "sat_reduction.csv", tb.to_csv(red_rows))
        atomic_write_json(
            tmp / "metrics.json",
            {r["filter"]: {"mean_rank": r["mean_rank"], "cells": r["cells"]} for r in rank},
        )
    return out_dir / "index.html"
