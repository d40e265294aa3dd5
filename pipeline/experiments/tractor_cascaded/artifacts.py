"""The tractor experiment's output folder: data tables (CSV/JSON) and figures.

Layout of ``OUT`` (``navreplay experiment tractor_cascaded --out OUT``; the dvc stage writes
``datasets/tractor_straight/experiments/tractor_cascaded``)::

    vs_paper.md             the paper's claims beside ours, one column per reading of
                            Table 1, with the mechanism checks (``note``)
    summary.json            every aggregate: stats and paired differences per label,
                            scenario and metric; the paper comparison; the mechanism checks
    paper_comparison.csv    claim, reading (of Table 1), paper, metric, n, mean, ci_low,
                            ci_high, verdict, note
    convergence.csv         label, bias, band, runs, converged, mean_s, ci_low_s, ci_high_s
    tracking.csv            nominal scenario: label, metric, n, mean, std, ci_low, ci_high
    outage_drift.csv        label, scenario, outage_s, metric, n, mean, std, ci_low, ci_high
    paired.csv              label, scenario, metric (label minus cascaded_ekf), n, mean, ...
    runs.csv                one row per run (label, scenario, seed, every scalar)
    timeseries_<scenario>.csv   the example run of every label, decimated
    figures/*.png, *.svg    ``figures``
    timing.json             wall-clock cost per filter (the only file that is not
                            byte-stable: it measures this machine)

Every other file is a deterministic function of the parameters.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from navreplay.ingest.atomic import atomic_directory, atomic_write_json, atomic_write_text
from navreplay.ingest.typed import to_plain
from navreplay.pipeline.estimation.cascaded.metrics import BIASES
from navreplay.pipeline.estimation.cascaded.outputs import STATE_COLUMNS
from navreplay.pipeline.experiments.tractor_cascaded.comparison import (
    mechanisms,
    paper_comparison,
    reading_name,
)
from navreplay.pipeline.experiments.tractor_cascaded.config import BASELINE, NOMINAL
from navreplay.pipeline.experiments.tractor_cascaded.figures import draw_all
from navreplay.pipeline.experiments.tractor_cascaded.note import vs_paper
from navreplay.pipeline.experiments.tractor_cascaded.runs import (
    ExperimentInputs,
    RunSummary,
    labels,
    run_experiment,
    summarize,
)

_STAT_COLS = ("n", "mean", "std", "ci_low", "ci_high")


def _fmt(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, float):
        return "nan" if math.isnan(v) else f"{v:.9g}"
    return str(v)


def write_csv(path: Path, header: Sequence[str], rows: Iterable[Sequence[Any]]) -> None:
    """Write a CSV atomically with deterministic number formatting (9 significant digits)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    for row in rows:
        w.writerow([_fmt(v) for v in row])
    atomic_write_text(path, buf.getvalue())


def _stat_row(stat: Mapping[str, Any]) -> list[Any]:
    return [stat.get(c) for c in _STAT_COLS]


def write_tables(
    out: Path,
    runs: Sequence[RunSummary],
    summary: dict[str, Any],
    comparison: list[dict[str, Any]],
    bands: tuple[float, ...],
    seeds: int,
    outage_lengths: Mapping[str, float],
) -> list[Path]:
    """The CSV tables (module docstring); returns their paths."""
    stats = summary["stats"]
    paths: list[Path] = []
    p = out / "paper_comparison.csv"
    write_csv(p, ("claim", "reading", "paper", "metric", *_STAT_COLS, "verdict", "note"),
              ([r["claim"], r["reading"], r["paper"], r["metric"], *_stat_row(r["ours"]),
                r["verdict"], r["note"]] for r in comparison))  # fmt: skip
    paths.append(p)
    rows = []
    for label, by_scen in stats.items():
        for (name, _), band in zip(BIASES, bands, strict=True):
            c = by_scen.get(NOMINAL, {}).get(f"conv_{name}", {"n": 0})
            rows.append([label, name, band, seeds, c["n"], c.get("mean"), c.get("ci_low"),
                         c.get("ci_high")])  # fmt: skip
    p = out / "convergence.csv"
    write_csv(p, ("label", "bias", "band", "runs", "converged", "mean_s", "ci_low_s",
                  "ci_high_s"), rows)  # fmt: skip
    paths.append(p)
    track = ("pos_err_e_rms_m", "pos_err_n_rms_m", "pos_err_e_rms_settled_m",
             "pos_err_n_rms_settled_m", "pos_err_n_mean_settled_m", "heading_err_rms_settled_rad",
             "lateral_rms_settled_m", "lateral_abs_max_settled_m", "step_recovery_s",
             "lateral_abs_end_m", "diverged")  # fmt: skip
    p = out / "tracking.csv"
    write_csv(p, ("label", "metric", *_STAT_COLS),
              ([label, m, *_stat_row(by_scen[NOMINAL][m])] for label, by_scen in stats.items()
               if NOMINAL in by_scen for m in track))  # fmt: skip
    paths.append(p)
    drift = (
        "drift_end_m",
        "drift_max_m",
        "drift_e_end_m",
        "drift_n_end_m",
        "lateral_abs_outage_end_m",
        "lateral_abs_outage_max_m",
        "heading_err_outage_end_rad",
    )
    p = out / "outage_drift.csv"
    write_csv(p, ("label", "scenario", "outage_s", "metric", *_STAT_COLS),
              ([label, scen, outage_lengths[scen], m, *_stat_row(by_scen[scen][m])]
               for label, by_scen in stats.items() for scen in outage_lengths
               if scen in by_scen for m in drift))  # fmt: skip
    paths.append(p)
    p = out / "paired.csv"
    write_csv(p, ("label", "scenario", "metric", *_STAT_COLS),
              ([label, scen, m, *_stat_row(st)] for label, by_scen in summary["paired"].items()
               for scen, ms in by_scen.items() for m, st in ms.items()))  # fmt: skip
    paths.append(p)
    names = sorted({k for r in runs for k in r.values})
    p = out / "runs.csv"
    write_csv(p, ("label", "scenario", "seed", *names),
              ([r.spec.label, r.spec.scenario, r.spec.seed_index,
                *[r.values.get(k, math.nan) for k in names]] for r in runs))  # fmt: skip
    paths.append(p)
    return paths


def write_timeseries(out: Path, series: Mapping[str, Mapping[str, Mapping[str, np.ndarray]]]
                     ) -> list[Path]:  # fmt: skip
    """``timeseries_<scenario>.csv``: the example run of every label, named columns."""
    paths = []
    for scen, by_label in series.items():
        header = ["label", "t_s", "gps_valid", "lateral_err_m"]
        for _, name, sname in STATE_COLUMNS:
            header += [f"{name}_est", f"{name}_true", sname]
        rows = []
        for label, s in by_label.items():
            for k in range(s["t_s"].size):
                row: list[Any] = [label, float(s["t_s"][k]), int(s["gps_valid"][k]),
                                  float(s["lateral_err_m"][k])]  # fmt: skip
                for i, _, _ in STATE_COLUMNS:
                    row += [float(s[f"x{i}"][k]), float(s[f"truth{i}"][k]),
                            float(s[f"sigma{i}"][k])]  # fmt: skip
                rows.append(row)
        p = out / f"timeseries_{scen}.csv"
        write_csv(p, header, rows)
        paths.append(p)
    return paths


def timing(runs: Sequence[RunSummary], steps: int, dt_s: float) -> dict[str, Any]:
    """Wall-clock cost per label: filter time per run and per sample, closed-loop time."""
    out: dict[str, Any] = {}
    for label in dict.fromkeys(r.spec.label for r in runs):
        sel = [r for r in runs if r.spec.label == label]
        filt = np.array([r.runtime_s for r in sel])
        wall = np.array([r.wall_s for r in sel])
        out[label] = {
            "runs": len(sel),
            "filter_s_per_run_mean": float(filt.mean()),
            "filter_us_per_sample_mean": float(filt.mean() / steps * 1e6),
            "closed_loop_s_per_run_mean": float(wall.mean()),
            "filter_realtime_factor": float(steps * dt_s / filt.mean()) if filt.mean() else None,
        }
    return out


def write_json(path: Path, data: Any) -> Path:
    """Deterministic JSON (``ingest.atomic.atomic_write_json``); NaN becomes null."""
    atomic_write_json(path, _clean(data))
    return path


def _clean(v: Any) -> Any:
    if isinstance(v, dict):
        return {str(k): _clean(x) for k, x in v.items()}
    if isinstance(v, list | tuple):
        return [_clean(x) for x in v]
    if isinstance(v, float | np.floating):
        f = float(v)
        return None if not math.isfinite(f) else f
    if isinstance(v, np.integer):
        return int(v)
    return v


def write_experiment(
    out_dir: Path,
    inputs: ExperimentInputs,
    dpi: int,
) -> dict[str, Any]:
    """Run the tractor experiment and write its folder atomically; returns the summary."""
    exp, sim = inputs.exp, inputs.sim
    runs = run_experiment(inputs)
    summary = summarize(runs, exp)
    ukf = inputs.sections.get("cascaded_ukf")
    mech = mechanisms(summary, exp, sim, ukf)
    interval = inputs.sections[BASELINE].process_noise.interval_s
    comparison = paper_comparison(summary, exp, mech, interval)
    scenarios = exp.scenarios()
    outage_lengths = {s: w[0][1] - w[0][0] for s, w in scenarios.items() if w}
    series: dict[str, dict[str, Any]] = {s: {} for s in scenarios}
    for r in runs:
        if r.series is not None:
            series[r.spec.scenario][r.spec.label] = r.series
    bands = inputs.sections[BASELINE].convergence_band.values()
    with atomic_directory(out_dir, extra_suffixes=(".md",)) as tmp:
        write_tables(tmp, runs, summary, comparison, bands, exp.seeds, outage_lengths)
        write_timeseries(tmp, series)
        doc = {
            "experiment": "tractor_cascaded",
            "params": {k: v for k, v in to_plain(exp).items() if k != "workers"},
            "labels": labels(exp),
            "runs": len(runs),
            "scenarios": {s: [list(w) for w in ws] for s, ws in scenarios.items()},
            "convergence_band": dict(zip((n for n, _ in BIASES), bands, strict=True)),
            "paper_comparison": comparison,
            "mechanisms": mech,
            **summary,
        }
        write_json(tmp / "summary.json", doc)
        atomic_write_text(tmp / "vs_paper.md", vs_paper(summary, comparison, mech, exp, interval))
        write_json(tmp / "timing.json", timing(runs, sim.steps + 1, sim.dt_s))
        draw_all(
            series, summary, labels(exp), bands, tmp / "figures", dpi, reading_name("", interval)
        )
    return doc
