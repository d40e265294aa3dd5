"""Outage figures: a detail panel per outage window, and drift against outage length.

``windows_detail`` draws, for one scenario, the 3-D error of every filter (horizontal where
the reference has no heights) from ``PRE_S`` before each window to ``POST_S`` after it (x:
seconds from the window's start), one panel per window (the first ``MAX_PANELS``), so an
engineer can read each outage of a long drive at full detail. ``drift_by_length`` plots the
rows of ``tables.drift_by_length``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from navreplay.pipeline.report.inputs import DatasetInputs
from navreplay.pipeline.report.series import ErrorSeries
from navreplay.pipeline.report.svg import (
    OUTAGE_COLOUR,
    colour,
    decimate_minmax,
    figure_svg,
    fixed_layout,
    style,
)

PRE_S = 10.0
POST_S = 30.0
MAX_PANELS = 12
PANEL_POINTS = 400  # per line of a window's panel (a third of the page's width)


def windows_detail(
    data: DatasetInputs, scenario: str, series: dict[tuple[str, str], ErrorSeries], key: str
) -> str | None:
    """Per-window detail of one scenario (see the module docstring); None without windows."""
    runs = [r for r in data.runs if r.scenario == scenario and r.windows]
    runs = [r for r in runs if (r.filter, scenario) in series]
    if not runs:
        return None
    windows = runs[0].windows[:MAX_PANELS]
    filters = data.filters()
    cols = min(3, len(windows))
    rows = (len(windows) + cols - 1) // cols
    with style() as plt:
        fig, axes = plt.subplots(
            rows, cols, figsize=(max(3.4 * cols, 6.8), 0.6 + 2.3 * rows), squeeze=False
        )  # at least the width of its title
        fixed_layout(fig, top=0.6, hgap=0.75, wgap=0.7)
        for i, w in enumerate(windows):
            ax = axes[i // cols, i % cols]
            ax.axvspan(0.0, w.duration_s, color=OUTAGE_COLOUR, alpha=0.25, lw=0)
            what = "3-D"
            for r in runs:
                s = series[(r.filter, scenario)]
                a = w.start_ns - round(PRE_S * 1e9)
                b = w.end_ns + round(POST_S * 1e9)
                sel = (s.t_ns >= a) & (s.t_ns <= b)
                t = (s.t_ns[sel] - w.start_ns) / 1e9
                err = s.err_3d_m[sel]
                if not np.isfinite(err).any():  # a reference without heights (SITL's SIMSTATE)
                    err, what = s.err_h_m[sel], "horizontal"
                ax.plot(
                    *decimate_minmax(t, err, PANEL_POINTS),
                    color=colour(filters.index(r.filter)),
                    label=r.filter,
                )
            sats = w.metrics.get("sats")
            extra = f", {sats} sats" if sats is not None else ""
            ax.set_title(f"window {i + 1}{extra}", loc="left")
            ax.set_xlabel("s from outage start")
            ax.set_ylabel(f"{what} error, m")
        for j in range(len(windows), rows * cols):
            axes[j // cols, j % cols].set_visible(False)
        axes[0, 0].legend(loc="upper left")
        more = len(runs[0].windows) - len(windows)
        note = f" (first {len(windows)} of {len(runs[0].windows)})" if more > 0 else ""
        fig.suptitle(f"{data.dataset}: error around each outage window, {scenario}{note}")
        return figure_svg(fig, key)


def drift_by_length(rows: Sequence[dict[str, Any]], filters: list[str], key: str) -> str | None:
    """Mean 3-D error at the end of complete outages against their length, 95 % intervals."""
    if not rows:
        return None
    with style() as plt:
        fig, ax = plt.subplots(figsize=(6.5, 4.0), layout="constrained")
        names = sorted({str(r["filter"]) for r in rows}, key=lambda f: (f not in filters, f))
        for f in names:
            rr = sorted((r for r in rows if r["filter"] == f), key=lambda r: r["outage_s"])
            x = np.array([r["outage_s"] for r in rr], dtype=float)
            y = np.array([r["err_end_mean_m"] for r in rr], dtype=float)
            lo = np.array([r["ci_low_m"] for r in rr], dtype=float)
            hi = np.array([r["ci_high_m"] for r in rr], dtype=float)
            err = np.vstack([np.nan_to_num(y - lo), np.nan_to_num(hi - y)])
            c = colour(filters.index(f)) if f in filters else "#000000"
            ax.errorbar(x, y, yerr=err, color=c, marker="o", ms=3.5, capsize=3, label=f)
        ax.set_xlabel("outage length, s")
        ax.set_ylabel("3-D error at outage end, m")
        ax.set_title("drift against outage length (complete outages; bars: 95 % CI)")
        ax.legend(loc="upper left")
        return figure_svg(fig, key)


def sat_reduction(rows: Sequence[dict[str, Any]], paper: dict[int, float], key: str) -> str | None:
    """The error reduction per satellite count of every dataset and filter pair (rows of the
    summary's ``sat_reduction.csv``: ``dataset``, ``pair``, ``sats``, ``reduction_pct``,
    ``ci_low_pct``, ``ci_high_pct``) with its 95 % interval, beside ``paper`` (paper 001,
    Table 1: sats -> %)."""

    def num(v: Any) -> float:
        try:
            return float(v)
        except (TypeError, ValueError):
            return float("nan")

    series: dict[str, list[dict[str, Any]]] = {}
    for r in rows:
        series.setdefault(f"{r.get('dataset')}: {r.get('pair')}", []).append(r)
    if not series:
        return None
    with style() as plt:
        fig, ax = plt.subplots(figsize=(9.0, 4.0), layout="constrained")
        width = 0.6 / max(len(series), 1)
        for i, (label, unsorted) in enumerate(sorted(series.items())):
            rr = sorted(unsorted, key=lambda r: num(r.get("sats")))
            x = np.array([num(r.get("sats")) for r in rr]) + (i - (len(series) - 1) / 2) * width
            y = np.array([num(r.get("reduction_pct")) for r in rr])
            lo = np.array([num(r.get("ci_low_pct")) for r in rr])
            hi = np.array([num(r.get("ci_high_pct")) for r in rr])
            err = np.vstack([np.nan_to_num(y - lo), np.nan_to_num(hi - y)])
            ax.errorbar(x, y, yerr=err, color=colour(i), marker="o", ms=3.5, capsize=3, ls="none",
                        label=label)  # fmt: skip
        ks = sorted(paper)
        ax.plot(
            ks,
            [paper[k] for k in ks],
            "k_",
            ms=16,
            mew=2.0,
            label="paper 001, Table 1 (tc_ukf -> tc_ukf_nhc)",
        )
        ax.axhline(0.0, color="#888888", lw=0.6)
        ax.set_xticks(ks)
        ax.set_xlabel("satellites visible in the window")
        ax.set_ylabel("error reduction, %")
        ax.set_title("error reduction per satellite count (bars: 95 % interval)")
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=7.0)
        return figure_svg(fig, key)
