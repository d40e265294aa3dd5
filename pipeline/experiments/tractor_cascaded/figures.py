"""Figures of the tractor experiment (matplotlib, Agg), written as PNG and SVG.

Drawn from the experiment's data only (the example run's time series and the Monte Carlo
summary), so they can be regenerated from the CSV/JSON files. Output is byte-stable: fixed
sizes, no timestamps (``metadata``), a fixed SVG hash salt. The time-series figures show the
filters with the sections' reading of Table 1 (EKF solid, the hybrid dashed on top of it, the
paper's psi_d linearization dotted, UKF red); ``sensitivity`` adds the other readings
(``@q<interval>s`` labels).

- ``tracking``: true tracks after the 3 m step (paper Fig. 2/7), East estimation error,
  true lateral error (symmetric-log scale: the 3 m step and the centimetres after it);
- ``bias_estimates``: the four bias estimates against truth with the convergence band
  (Fig. 3/8); ``bias_errors``: their absolute errors, log scale (Fig. 12-13);
- ``position_errors``: East and North estimation error (Fig. 14);
- ``outage_<scenario>``: horizontal estimation error and true lateral error around a GPS
  outage (shaded);
- ``sensitivity``: radar-bias estimates under each reading of Table 1;
- ``monte_carlo``: bias convergence times (each reading) and outage drift, means with
  confidence intervals.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from navreplay.pipeline.estimation.cascaded.metrics import BIASES
from navreplay.pipeline.estimation.cascaded.model import NAV_E, NAV_N, NAV_RB
from navreplay.pipeline.nav.earth import F64

Series = Mapping[str, F64]
STYLE: dict[str, dict[str, Any]] = {
    "cascaded_ekf": {"color": "#1f77b4", "ls": "-"},
    "cascaded_ekf_psi_d": {"color": "#17becf", "ls": ":"},
    "cascaded_ukf": {"color": "#d62728", "ls": "-"},
    "cascaded_hybrid": {"color": "#2ca02c", "ls": "--"},
}
BIAS_TITLES = ("radar bias r_b (m/s)", "gyro bias g_b (rad/s)", "heading bias psi_b (rad)",
               "steer bias delta_b (rad)")  # fmt: skip
BIAS_TICKS = ("radar", "gyro", "heading", "steer")


def _base(label: str) -> str:
    return label.split("@", maxsplit=1)[0]


def _style(label: str) -> dict[str, Any]:
    return dict(STYLE.get(_base(label), {"color": "0.4", "ls": "-"}))


def _label(label: str) -> str:
    base, _, q = label.partition("@q")
    name = base.removeprefix("cascaded_").replace("_psi_d", " (J1 at psi_d)").upper()
    return f"{name}, Table 1 per {q.removesuffix('s')} s" if q else name


def _paper(series: Mapping[str, Series]) -> dict[str, Series]:
    """The labels with the sections' reading of Table 1 (no ``@q`` variants)."""
    return {k: v for k, v in series.items() if "@" not in k}


def _save(fig: Any, out_dir: Path, name: str, dpi: int) -> list[Path]:
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = [out_dir / f"{name}.png", out_dir / f"{name}.svg"]
    fig.savefig(paths[0], dpi=dpi, metadata={"Software": None})
    fig.savefig(paths[1], metadata={"Date": None, "Creator": None})
    plt.close(fig)
    return paths


def _shade_outages(ax: Any, s: Series) -> None:
    t, ok = s["t_s"], s["gps_valid"] > 0.5
    if ok.all():
        return
    idx = np.flatnonzero(~ok)
    ax.axvspan(t[idx[0]], t[idx[-1]], color="0.85", label="GPS outage", zorder=0)


def _spread_mm(series: Mapping[str, Series], i: int) -> float:
    """Largest difference of state ``i``'s estimation error between the labels, mm."""
    err = np.array([s[f"x{i}"] - s[f"truth{i}"] for s in series.values()])
    return float(np.max(err.max(axis=0) - err.min(axis=0)) * 1e3)


def tracking(series: Mapping[str, Series], out_dir: Path, dpi: int) -> list[Path]:
    """True tracks, East estimation error and true lateral error (nominal example run)."""
    series = _paper(series)
    fig, axes = plt.subplots(3, 1, figsize=(9, 9.5), constrained_layout=True)
    for label, s in series.items():
        st = _style(label)
        axes[0].plot(s[f"truth{NAV_N}"], s[f"truth{NAV_E}"], **st, label=_label(label))
        axes[1].plot(s["t_s"], s[f"x{NAV_E}"] - s[f"truth{NAV_E}"], lw=0.8, **st)
        axes[2].plot(s["t_s"], s["lateral_err_m"], lw=0.9, **st)
    first = next(iter(series.values()))
    axes[0].axhline(3.0, color="k", lw=0.8, alpha=0.6, label="desired line")
    axes[0].set(xlabel="North (m)", ylabel="East (m)", xlim=(0, 60),
                title="True track after the 3 m step (first 60 m)")  # fmt: skip
    spread = _spread_mm(series, NAV_E)
    axes[1].set(
        xlabel="time (s)",
        ylabel="East error (m)",
        title=f"East estimation error (the filters differ by at most {spread:.2g} mm)",
    )
    axes[2].set_yscale("symlog", linthresh=0.05)
    axes[2].set(
        xlabel="time (s)",
        ylabel="lateral error (m, symlog)",
        title="True lateral error to the line (the LQR steers on the estimates)",
    )
    for ax in axes[1:]:
        ax.set_xlim(first["t_s"][0], first["t_s"][-1])
    axes[0].legend(loc="lower right", fontsize=8)
    for ax in axes:
        ax.grid(alpha=0.3, which="both")
    return _save(fig, out_dir, "tracking", dpi)  # fmt: skip


def bias_estimates(series: Mapping[str, Series], bands: tuple[float, ...], out_dir: Path,
                   dpi: int) -> list[Path]:  # fmt: skip
    """Bias estimates against truth, with the convergence band (nominal example run)."""
    series = _paper(series)
    fig, axes = plt.subplots(2, 2, figsize=(11, 7), constrained_layout=True)
    for ax, (_, i), title, band in zip(axes.flat, BIASES, BIAS_TITLES, bands, strict=True):
        s0 = next(iter(series.values()))
        truth = s0[f"truth{i}"]
        ax.fill_between(s0["t_s"], truth - band, truth + band, color="0.9", label="band")
        ax.plot(s0["t_s"], truth, "k", lw=0.8, label="truth")
        for label, s in series.items():
            ax.plot(s["t_s"], s[f"x{i}"], lw=0.9, **_style(label), label=_label(label))
        ax.set(title=title, xlabel="time (s)")
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8)
    return _save(fig, out_dir, "bias_estimates", dpi)


def bias_errors(series: Mapping[str, Series], out_dir: Path, dpi: int) -> list[Path]:
    """Absolute bias errors on a log scale (paper Fig. 12-13)."""
    series = _paper(series)
    fig, axes = plt.subplots(2, 2, figsize=(11, 7), constrained_layout=True)
    for ax, (_, i), title in zip(axes.flat, BIASES, BIAS_TITLES, strict=True):
        for label, s in series.items():
            err = np.abs(s[f"x{i}"] - s[f"truth{i}"])
            ax.semilogy(s["t_s"], np.maximum(err, 1e-5), lw=0.8, **_style(label),
                        label=_label(label))  # fmt: skip
        ax.set(title=f"|error| of the {title}", xlabel="time (s)")
        ax.grid(alpha=0.3, which="both")
    axes[0, 0].legend(fontsize=8)
    return _save(fig, out_dir, "bias_errors", dpi)


def position_errors(series: Mapping[str, Series], out_dir: Path, dpi: int) -> list[Path]:
    """East and North estimation errors (paper Fig. 14)."""
    series = _paper(series)
    fig, axes = plt.subplots(2, 1, figsize=(9, 6), constrained_layout=True)
    for ax, i, name in ((axes[0], NAV_E, "East"), (axes[1], NAV_N, "North")):
        for label, s in series.items():
            ax.plot(s["t_s"], s[f"x{i}"] - s[f"truth{i}"], lw=0.8, **_style(label),
                    label=_label(label))  # fmt: skip
        spread = _spread_mm(series, i)
        ax.set(title=f"{name} estimation error (the filters differ by at most {spread:.2g} mm)",
               xlabel="time (s)", ylabel="m")  # fmt: skip
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    return _save(fig, out_dir, "position_errors", dpi)


def outage(series: Mapping[str, Series], scenario: str, out_dir: Path, dpi: int) -> list[Path]:
    """Horizontal estimation error (log) and true lateral error around a GPS outage."""
    series = _paper(series)
    fig, axes = plt.subplots(2, 1, figsize=(9, 6.5), constrained_layout=True)
    for label, s in series.items():
        st = _style(label)
        e_h = np.hypot(s[f"x{NAV_E}"] - s[f"truth{NAV_E}"], s[f"x{NAV_N}"] - s[f"truth{NAV_N}"])
        axes[0].semilogy(s["t_s"], np.maximum(e_h, 1e-3), lw=0.9, **st, label=_label(label))
        axes[1].plot(s["t_s"], s["lateral_err_m"], lw=0.9, **st)
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


def sensitivity(series: Mapping[str, Series], band: float, out_dir: Path, dpi: int,
                default: str) -> list[Path]:  # fmt: skip
    """Radar-bias estimates with the sections' reading of Table 1 (named ``default``) and
    with each ``@q`` interval."""
    groups: dict[str, dict[str, Series]] = {}
    for label, s in series.items():
        if label != "cascaded_ekf_psi_d":
            groups.setdefault(label.partition("@")[2] or "paper", {})[label] = s
    fig, axes = plt.subplots(1, len(groups), figsize=(5.5 * len(groups), 4),
                             constrained_layout=True, squeeze=False)  # fmt: skip
    for ax, (group, members) in zip(axes[0], groups.items(), strict=True):
        s0 = next(iter(members.values()))
        truth = s0[f"truth{NAV_RB}"]
        ax.fill_between(s0["t_s"], truth - band, truth + band, color="0.9", label="band")
        ax.plot(s0["t_s"], truth, "k", lw=0.8, label="truth")
        for label, s in members.items():
            ax.plot(s["t_s"], s[f"x{NAV_RB}"], lw=0.9, **_style(label),
                    label=_label(_base(label)))  # fmt: skip
        q = group.removeprefix("q").removesuffix("s")
        per = default if group == "paper" else f"Table 1 per {q} s"
        ax.set(title=f"Radar bias, {per}", xlabel="time (s)", ylabel="m/s")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    return _save(fig, out_dir, "sensitivity", dpi)


def _errorbar(ax: Any, xpos: float, stat: Mapping[str, Any], label: str, first: bool) -> None:
    st = _style(label)
    mean = stat.get("mean")
    if mean is None:
        ax.annotate("never", (xpos, 0.0), xycoords=("data", "axes fraction"), ha="center",
                    va="bottom", color=st["color"], fontsize=7, rotation=90)  # fmt: skip
        return
    lo, hi = stat.get("ci_low"), stat.get("ci_high")
    err = [[mean - lo], [hi - mean]] if lo is not None and hi is not None else None
    ax.errorbar(xpos, mean, yerr=err, fmt="o", color=st["color"], capsize=3,
                mfc="white" if "@" in label else st["color"],
                label=_label(_base(label)) if first else None)  # fmt: skip


def monte_carlo(summary: dict[str, Any], labels: list[str], scenarios: list[str], out_dir: Path,
                dpi: int, default: str) -> list[Path]:  # fmt: skip
    """Means and confidence intervals: bias convergence time (each reading of Table 1, the
    sections' own named ``default``), outage drift (the sections' reading)."""
    groups = [(default, [lb for lb in labels if "@" not in lb])]
    for q in dict.fromkeys(lb.partition("@")[2] for lb in labels if "@" in lb):
        groups.append((f"Table 1 per {q.removeprefix('q').removesuffix('s')} s",
                       [lb for lb in labels if lb.endswith("@" + q)]))  # fmt: skip
    outs = [s for s in scenarios if s != "nominal"]
    fig, axes = plt.subplots(1, len(groups) + 1, figsize=(5.2 * (len(groups) + 1), 4.6),
                             constrained_layout=True)  # fmt: skip
    for ax, (title, members) in zip(axes, groups, strict=False):
        width = 0.8 / max(1, len(members))
        for k, label in enumerate(members):
            st = summary["stats"].get(label, {}).get("nominal", {})
            for j, (name, _) in enumerate(BIASES):
                _errorbar(ax, j + (k + 0.5) * width - 0.4, st.get(f"conv_{name}", {}), label,
                          j == 0)  # fmt: skip
        ax.set_xticks(np.arange(len(BIASES)), BIAS_TICKS)
        ax.set(title=f"Bias convergence time, {title}", ylabel="s")
        ax.set_ylim(bottom=0)
    main = groups[0][1]
    width = 0.8 / max(1, len(main))
    for k, label in enumerate(main):
        st = summary["stats"].get(label, {})
        for j, scen in enumerate(outs):
            if scen in st:
                _errorbar(axes[-1], j + (k + 0.5) * width - 0.4, st[scen].get("drift_end_m", {}),
                          label, j == 0)  # fmt: skip
    axes[-1].set_xticks(np.arange(len(outs)), outs)
    axes[-1].set_yscale("log")
    axes[-1].set(title="Horizontal error at the outage end", ylabel="m")
    for ax in axes:
        ax.grid(alpha=0.3, which="both")
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7)
    return _save(fig, out_dir, "monte_carlo", dpi)


def draw_all(
    series: Mapping[str, Mapping[str, Series]],
    summary: dict[str, Any],
    labels: list[str],
    bands: tuple[float, ...],
    out_dir: Path,
    dpi: int,
    default: str = "Table 1 per second",
) -> list[Path]:
    """Every figure; ``series[scenario][label]`` are the example run's time series;
    ``default`` names the sections' reading of Table 1."""
    plt.rcParams["svg.hashsalt"] = "navreplay"
    nominal = series["nominal"]
    paths = tracking(nominal, out_dir, dpi)
    paths += bias_estimates(nominal, bands, out_dir, dpi)
    paths += bias_errors(nominal, out_dir, dpi)
    paths += position_errors(nominal, out_dir, dpi)
    for scen, by_label in series.items():
        if scen != "nominal":
            paths += outage(by_label, scen, out_dir, dpi)
    paths += sensitivity(nominal, bands[0], out_dir, dpi, default)
    paths += monte_carlo(summary, labels, list(series), out_dir, dpi, default)
    return paths
