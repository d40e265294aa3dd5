"""Figures of the tractor experiment (matplotlib, Agg), written as PNG and SVG.

Drawn from the experiment's data only (the example run's time series and the Monte Carlo
summary), so they can be regenerated from the CSV/JSON files. Output is byte-stable: fixed
sizes, no timestamps (``metadata``), a fixed SVG hash salt.

- ``tracking``: true tracks after the 3 m step (paper Fig. 2/7), East estimation error,
  true lateral error;
- ``bias_estimates``: the four bias estimates against truth with the convergence band
  (Fig. 3/8); ``bias_errors``: their absolute errors, log scale (Fig. 12-13);
- ``position_errors``: East and North estimation error (Fig. 14);
- ``outage_<scenario>``: horizontal estimation error and true lateral error around a GPS
  outage (shaded);
- ``monte_carlo``: bias convergence times and outage drift, means with confidence intervals.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from pipeline.estimation.cascaded.metrics import BIASES
from pipeline.estimation.cascaded.model import NAV_E, NAV_N
from pipeline.nav.earth import F64

Series = Mapping[str, F64]
COLORS = {
    "cascaded_ekf": "#1f77b4",
    "cascaded_ekf_psi_d": "#17becf",
    "cascaded_ukf": "#d62728",
    "cascaded_hybrid": "#2ca02c",
}
BIAS_TITLES = ("radar bias r_b (m/s)", "gyro bias g_b (rad/s)", "heading bias psi_b (rad)",
               "steer bias delta_b (rad)")  # fmt: skip


def _save(fig: Any, out_dir: Path, name: str, dpi: int) -> list[Path]:
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = [out_dir / f"{name}.png", out_dir / f"{name}.svg"]
    fig.savefig(paths[0], dpi=dpi, metadata={"Software": None})
    fig.savefig(paths[1], metadata={"Date": None, "Creator": None})
    plt.close(fig)
    return paths


def _label(label: str) -> str:
    return label.removeprefix("cascaded_").replace("_psi_d", " (J1 at psi_d)").upper()


def _shade_outages(ax: Any, s: Series) -> None:
    t, ok = s["t_s"], s["gps_valid"] > 0.5
    if ok.all():
        return
    idx = np.flatnonzero(~ok)
    ax.axvspan(t[idx[0]], t[idx[-1]], color="0.85", label="GPS outage", zorder=0)


def tracking(series: Mapping[str, Series], out_dir: Path, dpi: int) -> list[Path]:
    """True tracks, East estimation error and true lateral error (nominal example run)."""
    fig, axes = plt.subplots(3, 1, figsize=(9, 9), constrained_layout=True)
    for label, s in series.items():
        c = COLORS.get(label)
        axes[0].plot(s[f"truth{NAV_N}"], s[f"truth{NAV_E}"], color=c, label=_label(label))
        axes[1].plot(s["t_s"], s[f"x{NAV_E}"] - s[f"truth{NAV_E}"], color=c, lw=0.8)
        axes[2].plot(s["t_s"], s["lateral_err_m"], color=c, lw=0.8)
    first = next(iter(series.values()))
    axes[0].axhline(3.0, color="k", ls="--", lw=0.8, label="desired line")
    axes[0].set(xlabel="North (m)", ylabel="East (m)", xlim=(0, 40),
                title="True track after the 3 m step (first 40 m)")  # fmt: skip
    axes[1].set(xlabel="time (s)", ylabel="East error (m)", title="East estimation error")
    axes[2].set(xlabel="time (s)", ylabel="lateral error (m)",
                title="True lateral error to the line")  # fmt: skip
    axes[2].set_ylim(-0.2, 0.2)
    axes[2].set_xlim(first["t_s"][0], first["t_s"][-1])
    axes[0].legend(loc="lower right", fontsize=8)
    for ax in axes:
        ax.grid(alpha=0.3)
    return _save(fig, out_dir, "tracking", dpi)


def bias_estimates(series: Mapping[str, Series], bands: tuple[float, ...], out_dir: Path,
                   dpi: int) -> list[Path]:  # fmt: skip
    """Bias estimates against truth, with the convergence band (nominal example run)."""
    fig, axes = plt.subplots(2, 2, figsize=(11, 7), constrained_layout=True)
    for ax, (_, i), title, band in zip(axes.flat, BIASES, BIAS_TITLES, bands, strict=True):
        for label, s in series.items():
            ax.plot(s["t_s"], s[f"x{i}"], color=COLORS.get(label), lw=0.9, label=_label(label))
        s0 = next(iter(series.values()))
        truth = s0[f"truth{i}"]
        ax.plot(s0["t_s"], truth, "k--", lw=0.8, label="truth")
        ax.fill_between(s0["t_s"], truth - band, truth + band, color="0.9", label="band")
        ax.set(title=title, xlabel="time (s)")
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8)
    return _save(fig, out_dir, "bias_estimates", dpi)


def bias_errors(series: Mapping[str, Series], out_dir: Path, dpi: int) -> list[Path]:
    """Absolute bias errors on a log scale (paper Fig. 12-13)."""
    fig, axes = plt.subplots(2, 2, figsize=(11, 7), constrained_layout=True)
    for ax, (_, i), title in zip(axes.flat, BIASES, BIAS_TITLES, strict=True):
        for label, s in series.items():
            err = np.abs(s[f"x{i}"] - s[f"truth{i}"])
            ax.semilogy(s["t_s"], np.maximum(err, 1e-5), color=COLORS.get(label), lw=0.8,
                        label=_label(label))  # fmt: skip
        ax.set(title=f"|error| of the {title}", xlabel="time (s)")
        ax.grid(alpha=0.3, which="both")
    axes[0, 0].legend(fontsize=8)
    return _save(fig, out_dir, "bias_errors", dpi)


def position_errors(series: Mapping[str, Series], out_dir: Path, dpi: int) -> list[Path]:
    """East and North estimation errors (paper Fig. 14)."""
    fig, axes = plt.subplots(2, 1, figsize=(9, 6), constrained_layout=True)
    for ax, i, name in ((axes[0], NAV_E, "East"), (axes[1], NAV_N, "North")):
        for label, s in series.items():
            ax.plot(s["t_s"], s[f"x{i}"] - s[f"truth{i}"], color=COLORS.get(label), lw=0.8,
                    label=_label(label))  # fmt: skip
        ax.set(title=f"{name} estimation error", xlabel="time (s)", ylabel="m")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    return _save(fig, out_dir, "position_errors", dpi)


def outage(series: Mapping[str, Series], scenario: str, out_dir: Path, dpi: int) -> list[Path]:
    """Horizontal estimation error (log) and true lateral error around a GPS outage."""
    fig, axes = plt.subplots(2, 1, figsize=(9, 6.5), constrained_layout=True)
    for label, s in series.items():
        c = COLORS.get(label)
        e_h = np.hypot(s[f"x{NAV_E}"] - s[f"truth{NAV_E}"], s[f"x{NAV_N}"] - s[f"truth{NAV_N}"])
        axes[0].semilogy(s["t_s"], np.maximum(e_h, 1e-3), color=c, lw=0.9, label=_label(label))
        axes[1].plot(s["t_s"], s["lateral_err_m"], color=c, lw=0.9)
    first = next(iter(series.values()))
    for ax in axes:
        _shade_outages(ax, first)
        ax.set_xlim(first["t_s"][0], first["t_s"][-1])
        ax.grid(alpha=0.3, which="both")
    axes[0].set(title=f"Horizontal position estimation error ({scenario})", ylabel="m")
    axes[1].set(title="True lateral error to the line (the LQR steers on the estimates)",
                xlabel="time (s)", ylabel="m")  # fmt: skip
    axes[0].legend(fontsize=8)
    return _save(fig, out_dir, f"outage_{scenario}", dpi)


def monte_carlo(summary: dict[str, Any], labels: list[str], scenarios: list[str], out_dir: Path,
                dpi: int) -> list[Path]:  # fmt: skip
    """Means and confidence intervals: bias convergence time, outage drift."""
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5), constrained_layout=True)
    width = 0.8 / max(1, len(labels))
    for k, label in enumerate(labels):
        st = summary["stats"].get(label, {})
        for j, (name, _) in enumerate(BIASES):
            c = st.get("nominal", {}).get(f"conv_{name}", {})
            if c.get("mean") is None:
                axes[0].plot(j + k * width, 0, marker="x", color=COLORS.get(label))
                continue
            lo, hi = c.get("ci_low") or c["mean"], c.get("ci_high") or c["mean"]
            axes[0].errorbar(j + k * width, c["mean"], yerr=[[c["mean"] - lo], [hi - c["mean"]]],
                             fmt="o", color=COLORS.get(label), capsize=3,
                             label=_label(label) if j == 0 else None)  # fmt: skip
        for j, scen in enumerate(s for s in scenarios if s != "nominal"):
            d = st.get(scen, {}).get("drift_end_m", {})
            if d.get("mean") is None:
                continue
            lo, hi = d.get("ci_low") or d["mean"], d.get("ci_high") or d["mean"]
            axes[1].errorbar(j + k * width, d["mean"], yerr=[[d["mean"] - max(lo, 1e-6)],
                             [hi - d["mean"]]], fmt="o", color=COLORS.get(label), capsize=3,
                             label=_label(label) if j == 0 else None)  # fmt: skip
    axes[0].set_xticks(np.arange(len(BIASES)) + 0.4 - width / 2,
                       [n.removesuffix("_mps").removesuffix("_radps").removesuffix("_rad")
                        for n, _ in BIASES])  # fmt: skip
    axes[0].set(title="Bias convergence time (x: never within the band)", ylabel="s")
    outs = [s for s in scenarios if s != "nominal"]
    axes[1].set_xticks(np.arange(len(outs)) + 0.4 - width / 2, outs)
    axes[1].set_yscale("log")
    axes[1].set(title="Horizontal drift at the outage end", ylabel="m")
    for ax in axes:
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
    return _save(fig, out_dir, "monte_carlo", dpi)


def draw_all(
    series: Mapping[str, Mapping[str, Series]],
    summary: dict[str, Any],
    labels: list[str],
    bands: tuple[float, ...],
    out_dir: Path,
    dpi: int,
) -> list[Path]:
    """Every figure; ``series[scenario][label]`` are the example run's time series."""
    plt.rcParams["svg.hashsalt"] = "navreplay"
    nominal = series["nominal"]
    paths = tracking(nominal, out_dir, dpi)
    paths += bias_estimates(nominal, bands, out_dir, dpi)
    paths += bias_errors(nominal, out_dir, dpi)
    paths += position_errors(nominal, out_dir, dpi)
    for scen, by_label in series.items():
        if scen != "nominal":
            paths += outage(by_label, scen, out_dir, dpi)
    paths += monte_carlo(summary, labels, list(series), out_dir, dpi)
    return paths
