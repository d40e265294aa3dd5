"""The main figures of a dataset report, each returned as inline SVG text (``svg``).

- ``track``: east/north of the truth (or the GNSS fixes) and of each filter's nominal run;
- ``errors``: one figure per scenario, a panel per filter: the position error against the
  reference with the filter's 3-sigma envelope, outage windows shaded;
- ``nis``: one figure per filter: NIS per update for each stream (decimated), its running mean
  over ``NIS_WINDOW`` updates, and the two-sided 95 % chi-square bounds for one update;
- ``biases``: the six IMU bias estimates of every filter with 3-sigma bands, and the truth.

Time axes are seconds from the dataset's first sample (``DatasetInputs.t0_ns``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from navreplay.pipeline.distributions import chi2_ppf
from navreplay.pipeline.report.inputs import DatasetInputs, Run, column, times_ns
from navreplay.pipeline.report.series import ErrorSeries, local_en
from navreplay.pipeline.report.svg import (
    TRUTH_COLOUR,
    colour,
    decimate_minmax,
    figure_svg,
    fixed_layout,
    shade_windows,
    style,
)

NIS_WINDOW = 50
MAX_SCATTER = 1500
MAX_PATH = 1500  # points per track line
BAND_POINTS = 400  # per 3-sigma envelope of the error figures
PANEL_POINTS = 400  # per line in the small panels of the bias and NIS figures
_BIASES = (
    ("acc_bias_x_mps2", "accel bias x, m/s²"),
    ("acc_bias_y_mps2", "accel bias y, m/s²"),
    ("acc_bias_z_mps2", "accel bias z, m/s²"),
    ("gyro_bias_x_radps", "gyro bias x, rad/s"),
    ("gyro_bias_y_radps", "gyro bias y, rad/s"),
    ("gyro_bias_z_radps", "gyro bias z, rad/s"),
)


def _sigma_name(col: str) -> str:
    """``acc_bias_x_mps2`` -> ``acc_bias_x_sigma_mps2`` (``estimation.ins.outputs``)."""
    stem, unit = col.rsplit("_", 1)
    return f"{stem}_sigma_{unit}"


def _nominal(data: DatasetInputs) -> list[Run]:
    return [r for r in data.runs if r.scenario == "nominal" and r.ran]


def _origin(data: DatasetInputs) -> tuple[float, float] | None:
    for t in (data.truth, data.gnss):
        if t is not None and t.num_rows:
            lat, lon = column(t, "lat_deg"), column(t, "lon_deg")
            ok = np.isfinite(lat) & np.isfinite(lon)
            if ok.any():
                return float(lat[ok][0]), float(lon[ok][0])
    for r in _nominal(data):
        assert r.estimate is not None
        return float(column(r.estimate, "lat_deg")[0]), float(column(r.estimate, "lon_deg")[0])
    return None


def _stacked(plt: Any, rows: int, height_in: float) -> tuple[Any, Any]:
    """A figure of ``rows`` full-width panels, one above the other, over a shared time axis:
    the figure and its panels, top to bottom."""
    fig, axes = plt.subplots(rows, 1, figsize=(9.0, height_in), sharex=True, squeeze=False)
    fixed_layout(fig, top=0.6, hgap=0.35)
    return fig, axes[:, 0]


def track(data: DatasetInputs, key: str) -> str | None:
    """East/north track of the reference, the onboard estimate (where the log has one) and
    each filter's nominal run, metres."""
    origin = _origin(data)
    if origin is None:
        return None
    filters = data.filters()
    with style() as plt:
        fig, ax = plt.subplots(figsize=(7.5, 6.0))
        fixed_layout(fig)
        ref = data.truth if data.truth is not None and data.truth.num_rows else None
        if ref is not None:
            e, n = local_en(column(ref, "lat_deg"), column(ref, "lon_deg"), *origin)
            step = max(1, e.size // MAX_PATH)
            ax.plot(e[::step], n[::step], color=TRUTH_COLOUR, lw=2.2, alpha=0.5, label="truth")
        if data.gnss is not None and data.gnss.num_rows:
            e, n = local_en(column(data.gnss, "lat_deg"), column(data.gnss, "lon_deg"), *origin)
            step = max(1, e.size // MAX_SCATTER)
            ax.plot(e[::step], n[::step], ".", ms=2.0, color="#888888", label="GNSS fixes")
        if data.onboard is not None and data.onboard.num_rows:
            ob = data.onboard
            e, n = local_en(column(ob, "lat_deg"), column(ob, "lon_deg"), *origin)
            step = max(1, e.size // MAX_PATH)
            ax.plot(e[::step], n[::step], color="#000000", lw=1.0, ls="--",
                    label="onboard estimate")  # fmt: skip
        for r in _nominal(data):
            assert r.estimate is not None
            e, n = local_en(column(r.estimate, "lat_deg"), column(r.estimate, "lon_deg"), *origin)
            step = max(1, e.size // MAX_PATH)  # a 2-D path: stride keeps its order
            e_d, n_d = e[::step], n[::step]
            ax.plot(e_d, n_d, color=colour(filters.index(r.filter)), label=r.filter)
        ax.set_xlabel("east, m")
        ax.set_ylabel("north, m")
        ax.set_aspect("equal", adjustable="datalim")
        ax.legend(loc="best")
        ax.set_title(f"{data.dataset}: track (origin {origin[0]:.6f}°, {origin[1]:.6f}°)")
        return figure_svg(fig, key)


def errors(
    data: DatasetInputs,
    scenario: str,
    series: dict[tuple[str, str], ErrorSeries],
    key: str,
) -> str | None:
    """Horizontal error and 3-sigma envelope per filter under one scenario."""
    runs = [r for r in data.runs if r.scenario == scenario and (r.filter, scenario) in series]
    if not runs:
        return None
    t0 = data.t0_ns()
    filters = data.filters()
    with style() as plt:
        fig, panels = _stacked(plt, len(runs), 1.2 + 1.5 * len(runs))
        for ax, r in zip(panels, runs, strict=True):
            s = series[(r.filter, scenario)]
            t = s.t_s(t0)
            c = colour(filters.index(r.filter))
            env = 3.0 * s.sigma_h_m
            te, ee = decimate_minmax(t, env, BAND_POINTS)  # a smooth band needs few points
            ax.fill_between(te, 0.0, ee, color=c, alpha=0.15, lw=0, label="3σ horizontal")
            ax.plot(*decimate_minmax(t, s.err_h_m), color=c, label=f"{r.filter} horizontal error")
            wins = [((w.start_ns - t0) / 1e9, (w.end_ns - t0) / 1e9) for w in r.windows]
            shade_windows(ax, wins, "outage window")
            finite = s.err_h_m[np.isfinite(s.err_h_m)]
            if finite.size and np.nanmax(finite) > 50.0 * max(np.median(finite), 1e-3):
                ax.set_yscale("log")
                # no decades of sub-millimetre noise: a residual at a fused fix can be ~1e-9 m
                ax.set_ylim(bottom=max(1e-3, float(np.nanmax(finite)) * 1e-5))
            ax.set_ylabel("m")
            ax.legend(loc="upper right", ncols=3)
            what = (
                "error against truth"
                if s.reference == "truth"
                else "residual to the GNSS fixes (fused outside outage windows: not an accuracy)"
            )
            ax.set_title(f"{r.filter}: {what}", loc="left")
        panels[-1].set_xlabel("time since start, s")
        fig.suptitle(f"{data.dataset}: position error, scenario {scenario}")
        return figure_svg(fig, key)


def _running_mean(x: np.ndarray, n: int) -> np.ndarray:
    if x.size < n:
        return np.full(x.size, np.mean(x) if x.size else np.nan)
    c = np.cumsum(np.insert(x, 0, 0.0))
    out = np.full(x.size, np.nan)
    out[n - 1 :] = (c[n:] - c[:-n]) / n
    return out


def nis(data: DatasetInputs, run: Run, key: str) -> str | None:
    """NIS per stream of one run, with the 95 % chi-square bounds of a single update."""
    inn = run.innovations
    if inn is None or inn.num_rows == 0:
        return None
    t0 = data.t0_ns()
    t = (times_ns(inn) - t0) / 1e9
    streams = inn.column("stream").to_pylist()
    names = sorted(set(streams))
    values = column(inn, "nis")
    dims = column(inn, "dim")
    arr = np.asarray(streams, dtype=object)
    with style() as plt:
        fig, panels = _stacked(plt, len(names), 0.8 + 1.7 * len(names))
        for ax, name in zip(panels, names, strict=True):
            sel = arr == name
            ts, vs = t[sel], values[sel]
            dof = int(np.median(dims[sel])) if sel.any() else 1
            # every update's extremes as a thin line (a scatter of thousands of markers is
            # megabytes of SVG), under the running mean
            ax.plot(*decimate_minmax(ts, vs, PANEL_POINTS), color="#999999", lw=0.4,
                    label="NIS per update")  # fmt: skip
            ax.plot(
                *decimate_minmax(ts, _running_mean(vs, NIS_WINDOW), PANEL_POINTS),
                color="#0072B2",
                label=f"mean of {NIS_WINDOW}",
            )
            lo, hi = chi2_ppf(0.025, dof), chi2_ppf(0.975, dof)
            ax.axhline(dof, color="#009E73", lw=0.8, ls="--", label=f"dof = {dof}")
            ax.axhspan(lo, hi, color="#009E73", alpha=0.08, lw=0, label="95 % bounds, one update")
            wins = [((w.start_ns - t0) / 1e9, (w.end_ns - t0) / 1e9) for w in run.windows]
            shade_windows(ax, wins, None)
            if np.nanmax(vs, initial=0.0) > 20.0 * dof:
                ax.set_yscale("log")
            ax.set_ylabel("NIS")
            ax.set_title(f"stream {name}", loc="left")
            ax.legend(loc="upper right", ncols=4)
        panels[-1].set_xlabel("time since start, s")
        fig.suptitle(f"{data.dataset}: NIS of {run.filter}, scenario {run.scenario}")
        return figure_svg(fig, key)


def biases(data: DatasetInputs, key: str, runs: Sequence[Run] | None = None) -> str | None:
    """IMU bias estimates (3-sigma bands) of each filter's nominal run, with the truth."""
    runs = [r for r in (runs or _nominal(data)) if r.estimate is not None]
    runs = [r for r in runs if all(c in r.estimate.column_names for c, _ in _BIASES)]  # type: ignore[union-attr]
    if not runs:
        return None
    t0 = data.t0_ns()
    filters = data.filters()
    with style() as plt:
        fig, axes = plt.subplots(2, 3, figsize=(10.0, 5.6), sharex=True)
        fixed_layout(fig, top=0.6, hgap=0.35)
        for ax, (col, label) in zip(axes.ravel(), _BIASES, strict=True):
            for r in runs:
                est = r.estimate
                assert est is not None
                t = (times_ns(est) - t0) / 1e9
                v = column(est, col)
                sig = column(est, _sigma_name(col))
                c = colour(filters.index(r.filter))
                step = max(1, t.size // (PANEL_POINTS // 2))
                ax.fill_between(
                    t[::step],
                    (v - 3 * sig)[::step],
                    (v + 3 * sig)[::step],
                    color=c,
                    alpha=0.12,
                    lw=0,
                )
                ax.plot(*decimate_minmax(t, v, PANEL_POINTS), color=c, label=r.filter)
            if data.truth is not None and col in data.truth.column_names:
                tt = (times_ns(data.truth) - t0) / 1e9
                ax.plot(
                    *decimate_minmax(tt, column(data.truth, col), PANEL_POINTS),
                    color=TRUTH_COLOUR,
                    ls="--",
                    lw=1.4,
                    label="truth",
                )
            ax.set_title(label, loc="left")
        axes[0, 0].legend(loc="best")
        for ax in axes[1]:
            ax.set_xlabel("time since start, s")
        fig.suptitle(f"{data.dataset}: IMU bias estimates (bands: ±3σ), scenario nominal")
        return figure_svg(fig, key)
