"""The numbers of a dataset report, as rows (written as CSV and JSON beside the page).

- ``metrics_rows``: one row per run (filter x scenario) from its ``metrics.json``, plus the
  error against the reference when the run's metrics have none (real logs: the GNSS fixes).
- ``window_rows``: one row per run and outage window. The window metrics the run wrote
  (``metrics.json`` ``outage_windows``, from ``pipeline.estimation.core.windows``: the one
  implementation of architecture section 5) are taken as they are; a run without them (an
  older run, a hand-made window list) gets them measured here with the same definitions:
  error at the window's end, max, mean and RMS of the 3-D error inside it, no re-alignment
  at the window's start; drift as a percentage of the distance the reference travelled.
- ``drift_by_length``: complete outages (0 satellites) grouped per filter and window length:
  mean error at the window's end with a 95 % BCa bootstrap interval across windows (windows
  as the resampling unit, as the outages stage's; it stays inside the errors' range, so it
  never goes below zero as a t-interval of a few skewed errors can).
The per-satellite-count reduction (paper 001, Table 1) is the outages stage's table
(``experiments.find_outage_results``); this module does not recompute it.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from navreplay.pipeline.distributions import t_ppf
from navreplay.pipeline.outages.stats import mean_interval
from navreplay.pipeline.report.inputs import DatasetInputs, Run
from navreplay.pipeline.report.series import ErrorSeries, error_series, local_en

Row = dict[str, Any]
PAPER_REDUCTION_PCT = {0: 54.4, 1: 53.2, 2: 52.6, 3: 52.4, 4: 22.6}  # paper 001, Table 1
PAPER_PAIR = ("tc_ukf", "tc_ukf_nhc")  # its baseline -> candidate
MIN_DISTANCE_M = 50.0  # drift in % of distance only over a distance that means something
# the numbers of a run's metrics.json in its row of ``metrics_rows``, in column order
RUN_METRICS = (
    "pos_err_h_rms_m",
    "pos_err_3d_rms_m",
    "pos_err_3d_max_m",
    "vel_err_3d_rms_mps",
    "nees_mean",
    "nees_dof",
    "gate_rejections",
    "gate_resets",
    "epochs",
    "duration_s",
    "runtime_s",
    "compile_s",
    "realtime_factor",
)


def _num(v: Any) -> float | int | None:
    """A JSON number (ints stay ints), else None."""
    if isinstance(v, bool) or not isinstance(v, int | float):
        return None
    return v


def _nanrms(x: np.ndarray) -> float | None:
    finite = x[np.isfinite(x)]
    return float(np.sqrt(np.mean(finite**2))) if finite.size else None


def metrics_rows(data: DatasetInputs, series: dict[tuple[str, str], ErrorSeries]) -> list[Row]:
    """One row per run (see the module docstring), in the runs' order."""
    rows = []
    for r in data.runs:
        m = r.metrics
        row: Row = {
            "filter": r.filter,
            "scenario": r.scenario,
            "status": r.status,
            "reference": None,
            **{key: _num(m.get(key)) for key in RUN_METRICS},
            "reason": m.get("reason") or m.get("failure"),
        }
        if m.get("truth"):
            row["reference"] = "truth"
        s = series.get((r.filter, r.scenario))
        if s is not None and row["pos_err_h_rms_m"] is None:
            row["reference"] = s.reference
            row["pos_err_h_rms_m"] = _nanrms(s.err_h_m)
            row["pos_err_3d_rms_m"] = _nanrms(s.err_3d_m)
            finite = s.err_3d_m[np.isfinite(s.err_3d_m)]
            row["pos_err_3d_max_m"] = float(finite.max()) if finite.size else None
        rows.append(row)
    return rows


def nis_rows(runs: Iterable[Run]) -> list[Row]:
    """Per run and stream: updates, mean NIS, its 95 % interval, consistency, rejections."""
    rows = []
    for r in runs:
        nis = r.metrics.get("nis")
        if not isinstance(nis, dict):
            continue
        for stream in sorted(nis):
            v = nis[stream]
            if not isinstance(v, dict):
                continue
            lo, hi = (v.get("nis_bounds_95") or [None, None])[:2]
            rows.append(
                {
                    "filter": r.filter,
                    "scenario": r.scenario,
                    "stream": stream,
                    "count": _num(v.get("count")),
                    "nis_mean": _num(v.get("nis_mean")),
                    "dof_mean": _num(v.get("dof_mean")),
                    "bound_low": _num(lo),
                    "bound_high": _num(hi),
                    "consistent": v.get("consistent"),
                    "rejected": _num(v.get("rejected")),
                }
            )
    return rows


def all_series(data: DatasetInputs) -> dict[tuple[str, str], ErrorSeries]:
    """The error series of every run that ran and has a reference."""
    out = {}
    for r in data.runs:
        s = error_series(r, data.truth, data.gnss)
        if s is not None:
            out[(r.filter, r.scenario)] = s
    return out


def _path_length_m(data: DatasetInputs, a_ns: int, b_ns: int) -> float | None:
    from navreplay.pipeline.report.inputs import column, times_ns

    ref = data.truth if data.truth is not None and data.truth.num_rows > 1 else data.gnss
    if ref is None or ref.num_rows < 2:
        return None
    t = times_ns(ref)
    sel = (t >= a_ns) & (t <= b_ns)
    lat, lon = column(ref, "lat_deg")[sel], column(ref, "lon_deg")[sel]
    ok = np.isfinite(lat) & np.isfinite(lon)
    if ok.sum() < 2:
        return None
    e, n = local_en(lat[ok], lon[ok], float(lat[ok][0]), float(lon[ok][0]))
    return float(np.sum(np.hypot(np.diff(e), np.diff(n))))


_WINDOW_METRICS = ("err_end_m", "err_max_m", "err_mean_m", "err_rms_m", "drift_pct_distance")


def window_rows(data: DatasetInputs, series: dict[tuple[str, str], ErrorSeries]) -> list[Row]:
    """One row per run and outage window (see the module docstring)."""
    rows = []
    t0 = data.t0_ns()
    for r in data.runs:
        s = series.get((r.filter, r.scenario))
        for i, w in enumerate(r.windows):
            row: Row = {
                "filter": r.filter,
                "scenario": r.scenario,
                "window": i,
                "start_s": (w.start_ns - t0) / 1e9,
                "duration_s": w.duration_s,
                "sats": _num(w.metrics.get("sats")),
                "err_end_m": None,
                "err_max_m": None,
                "err_mean_m": None,
                "err_rms_m": None,
                "drift_pct_distance": None,
                "reconverge_s": _num(w.metrics.get("reconverge_s")),
                "inside_3sigma_frac": _num(w.metrics.get("inside_3sigma_frac")),
                "reference": s.reference if s is not None else None,
            }
            given = {k: w.metrics[k] for k in _WINDOW_METRICS if k in w.metrics}
            if given:
                row.update({k: _num(v) for k, v in given.items()})
                row["reference"] = w.metrics.get("reference", row["reference"])
            elif s is not None:
                sel = (s.t_ns >= w.start_ns) & (s.t_ns <= w.end_ns)
                e = s.err_3d_m[sel]
                if e.size:
                    row["err_end_m"] = float(e[-1])
                    row["err_max_m"] = float(e.max())
                    row["err_mean_m"] = float(e.mean())
                    row["err_rms_m"] = float(np.sqrt(np.mean(e**2)))
                    dist = _path_length_m(data, w.start_ns, w.end_ns)
                    if dist is not None and dist > MIN_DISTANCE_M:
                        row["drift_pct_distance"] = 100.0 * float(e[-1]) / dist
            rows.append(row)
    return rows


def t_interval(x: np.ndarray) -> tuple[float, float, float]:
    """(mean, low, high) of the mean with a 95 % t interval (NaN bounds below 2 values)."""
    mean = float(x.mean())
    if x.size < 2:
        return mean, math.nan, math.nan
    half = t_ppf(0.975, x.size - 1) * float(x.std(ddof=1)) / math.sqrt(x.size)
    return mean, mean - half, mean + half


def drift_by_length(windows: Sequence[Row]) -> list[Row]:
    """Complete outages per filter and window length: mean end error with a 95 % interval."""
    groups: dict[tuple[str, float], list[float]] = {}
    for w in windows:
        if w["err_end_m"] is None or (w["sats"] not in (None, 0.0)):
            continue
        if w["sats"] is None and not str(w["scenario"]).startswith("outage"):
            continue
        key = (str(w["filter"]), round(float(w["duration_s"]), 1))
        groups.setdefault(key, []).append(float(w["err_end_m"]))
    rows = []
    for (filt, length), errs in sorted(groups.items()):
        iv = mean_interval(np.asarray(errs, dtype=np.float64))
        mean, lo, hi = iv.estimate, iv.low, iv.high
        rows.append(
            {
                "filter": filt,
                "outage_s": length,
                "windows": len(errs),
                "err_end_mean_m": mean,
                "ci_low_m": lo,
                "ci_high_m": hi,
            }
        )
    return rows


def fmt(v: Any) -> str:
    """A cell as text: 4 significant digits for floats, empty for missing (stable output)."""
    if v is None:
        return ""
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        if math.isnan(v):
            return ""
        if v != 0 and (abs(v) >= 1e5 or abs(v) < 1e-3):
            return f"{v:.3e}"
        return f"{v:.4g}" if abs(v) < 1000 else f"{v:.0f}"
    return str(v)


def to_csv(rows: Sequence[Row], columns: Sequence[str] | None = None) -> str:
    """Rows as CSV text (full precision, ``repr`` of floats; empty cells for None/NaN)."""
    cols = list(columns or (rows[0].keys() if rows else []))
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)
    for r in rows:
        cells = []
        for c in cols:
            v = r.get(c)
            if v is None or (isinstance(v, float) and math.isnan(v)):
                cells.append("")
            else:
                cells.append(repr(v) if isinstance(v, float) else str(v))
        w.writerow(cells)
    return buf.getvalue()
