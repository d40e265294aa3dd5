"""Paper 003 experiment: error of each vehicle filter per speed band, with and without outages.

``band_table`` runs the four vehicle filters (``vehicle_kinematic``, ``vehicle_dynamic``,
``vehicle_switched``, ``vehicle_imm``) over one dataset, nominally and with periodic GNSS
outages, and tabulates per true-speed band the RMS horizontal position, heading, sideslip and
speed errors. Whether the switched and IMM filters are as good as the better single model is a
paired Monte Carlo over noise realizations (``vehicle_paired``). ``band_figure`` draws the
horizontal RMS per band (one panel per scenario).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from navreplay.pipeline.estimation.config import FiltersParams
from navreplay.pipeline.estimation.core.contract import Backend
from navreplay.pipeline.estimation.vehicle.config import VEHICLE_FILTERS
from navreplay.pipeline.estimation.vehicle.metrics import errors, per_band
from navreplay.pipeline.estimation.vehicle.replay import run_vehicle_filter
from navreplay.pipeline.experiments.gnss_outages import drop_fixes, in_windows, periodic_windows

SPEED_EDGES_MPS = (0.0, 2.5, 5.0, 10.0, 15.0, 20.0, 25.0, 35.0)


def band_table(
    tables: Mapping[str, pa.Table],
    filters: FiltersParams,
    *,
    edges: tuple[float, ...] = SPEED_EDGES_MPS,
    outage: tuple[float, float, float] = (20.0, 30.0, 10.0),
    backend: Backend = "numba",
    names: tuple[str, ...] = VEHICLE_FILTERS,
) -> list[dict[str, Any]]:
    """Rows (scenario, filter, band, RMS errors) for the nominal and outage runs.

    Args:
        tables: ``vehicle``, ``gnss`` and ``truth`` tables.
        filters: the ``filters`` params (the four vehicle sections).
        edges: speed band edges, m/s (true speed).
        outage: (start, period, length) of the periodic outages, s.
        names: the vehicle filters to run (default all four).
    """
    g = np.asarray(tables["gnss"].column("t_ns").to_numpy(), dtype=np.int64)
    windows = periodic_windows(g, *outage)
    scenarios = {"nominal": (dict(tables), []), "outages": (drop_fixes(tables, windows), windows)}
    rows: list[dict[str, Any]] = []
    for scen, (tabs, win) in scenarios.items():
        for name in names:
            res = run_vehicle_filter(tabs, name, filters.vehicle(name), backend=backend)
            err = errors(res, tables["truth"])
            masks: dict[str, np.ndarray | None] = {"all": None}
            if win:
                masks["in_outage"] = in_windows(err["t_ns"], win)
            for subset, mask in masks.items():
                for row in per_band(err, edges, mask):
                    rows.append(
                        {"scenario": scen, "filter": name, "subset": subset, **row,
                         "dynamic_share": float(np.mean(res.aux))}
                    )  # fmt: skip
    return rows


def band_figure(rows: list[dict[str, Any]], path: Path, dpi: int = 110) -> None:
    """Horizontal RMS error per speed band and filter (log scale), one panel per scenario."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scen = sorted({r["scenario"] for r in rows})
    fig, axes = plt.subplots(1, len(scen), figsize=(6 * len(scen), 4), squeeze=False)
    for ax, s in zip(axes[0], scen, strict=True):
        sel = [r for r in rows if r["scenario"] == s and r["subset"] == "all"]
        los = sorted({r["band_lo_mps"] for r in sel})
        width = 0.8 / len(VEHICLE_FILTERS)
        for k, f in enumerate(VEHICLE_FILTERS):
            by_lo = {r["band_lo_mps"]: r["pos_h_rms_m"] for r in sel if r["filter"] == f}
            vals = [by_lo[lo] for lo in los]
            ax.bar(np.arange(len(los)) + k * width, [v or np.nan for v in vals], width, label=f)
        his = [next(r["band_hi_mps"] for r in sel if r["band_lo_mps"] == lo) for lo in los]
        ax.set_xticks(np.arange(len(los)) + 0.4 - width / 2)
        ax.set_xticklabels([f"{lo:g}-{hi:g}" for lo, hi in zip(los, his, strict=True)])
        ax.set_yscale("log")
        ax.set_xlabel("true speed band, m/s")
        ax.set_ylabel("horizontal RMS error, m")
        ax.set_title(f"car_speed_ramp, {s}")
        ax.grid(True, which="both", alpha=0.3)
    axes[0][0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=dpi, metadata={"Software": None})
    plt.close(fig)
