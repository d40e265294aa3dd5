"""Paper 004 on seoul_campus: where the fuzzy fading helps and where it hurts.

GNSS faults of ``docs/bad-inputs.md`` as data transformations of the ``gnss`` table (seeded),
then four filters on the same tables:

- ``lc_ekf``: the project's loosely coupled EKF as configured (its GNSS model learns the fix
  errors' correlation time from the log, ``estimation.ins.fixnoise``, and carries them as
  Gauss-Markov states);
- ``lc_ekf_white``: the same EKF with paper 004's GNSS model (white fix errors,
  ``GnssNoiseParams.white``), i.e. the FWEKF with alpha fixed at 1: the difference to
  ``fwekf`` is the fuzzy weighting alone;
- ``fwekf``: the fuzzy-adaptive weighted EKF on the paper's white model (params.yaml gives
  the user's ``fwekf`` lc_ekf's model);
- ``iae_ekf``: the standard adaptive alternative, ``lc_ekf`` with the white part of its fix
  variances re-estimated from its innovations (``estimation.ins.iae``, Mohamed and Schwarz).

Scenarios:

- ``nominal``: the synthesized fixes;
- ``F7`` multipath burst: in a 30 s window, 10 % of the fixes get N(0, 20 m) errors per axis;
- ``F8`` optimistic accuracy: every fix gets extra white noise so that its total error is
  about 5 m per axis while the receiver still reports 0.5 m (eph/epv);
- ``outages``: periodic complete outages (no fixes) of ``outage_s`` every ``period_s``.

Per scenario and filter: horizontal RMS and max error over the drive and inside the fault or
outage windows, mean NIS of the position stream, gate rejections and resets, and the alpha the
fuzzy system chose (median, 95th percentile), or the IAE's multiplier of the declared
horizontal fix variance (median).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from typing import Any

import numpy as np
import pyarrow as pa

from navreplay.ingest.meta import SensorMeta
from navreplay.pipeline.estimation.config import FiltersParams
from navreplay.pipeline.estimation.core.contract import Backend
from navreplay.pipeline.estimation.ins.config import InsFilterParams
from navreplay.pipeline.estimation.ins.metrics import nis_summary
from navreplay.pipeline.estimation.ins.replay import run_filter
from navreplay.pipeline.estimation.ins.truth import error_states
from navreplay.pipeline.experiments.gnss_outages import (
    Window,
    drop_fixes,
    in_windows,
    periodic_windows,
)
from navreplay.pipeline.nav.earth import radii

FILTERS = ("lc_ekf", "lc_ekf_white", "fwekf", "iae_ekf")


def _col(t: pa.Table, name: str) -> np.ndarray:
    return np.array(t.column(name).to_numpy(zero_copy_only=False), dtype=np.float64)


def _perturb(g: pa.Table, rows: np.ndarray, sigma_m: float, rng: np.random.Generator) -> pa.Table:
    lat, lon, alt = _col(g, "lat_deg"), _col(g, "lon_deg"), _col(g, "alt_m")
    rm, rn = radii(np.radians(np.nanmean(lat)))
    d = rng.standard_normal((int(rows.sum()), 3)) * sigma_m
    lat[rows] += np.degrees(d[:, 0] / rm)
    lon[rows] += np.degrees(d[:, 1] / (rn * np.cos(np.radians(np.nanmean(lat)))))
    alt[rows] -= d[:, 2]
    for name, val in (("lat_deg", lat), ("lon_deg", lon), ("alt_m", alt)):
        g = g.set_column(g.column_names.index(name), name, pa.array(val, pa.float64()))
    return g


def multipath_burst(
    tables: Mapping[str, pa.Table], window: Window, rng: np.random.Generator,
    fraction: float = 0.1, sigma_m: float = 20.0,
) -> dict[str, pa.Table]:  # fmt: skip
    """F7: ``fraction`` of the fixes inside ``window`` get N(0, sigma_m) errors per axis."""
    g = tables["gnss"]
    t = np.asarray(g.column("t_ns").to_numpy(), dtype=np.int64)
    inside = np.flatnonzero(in_windows(t, [window]))
    pick = rng.choice(inside, size=max(1, round(fraction * inside.size)), replace=False)
    rows = np.zeros(t.size, bool)
    rows[pick] = True
    return {**tables, "gnss": _perturb(g, rows, sigma_m, rng)}


def optimistic_accuracy(
    tables: Mapping[str, pa.Table], rng: np.random.Generator,
    true_sigma_m: float = 5.0, reported_m: float = 0.5,
) -> dict[str, pa.Table]:  # fmt: skip
    """F8: white noise up to ``true_sigma_m`` per axis while ``reported_m`` is reported."""
    g = tables["gnss"]
    have = float(np.nanmean(_col(g, "h_acc_m")))
    extra = float(np.sqrt(max(true_sigma_m**2 - have**2, 0.0)))
    g = _perturb(g, np.ones(g.num_rows, bool), extra, rng)
    for name, val in (("h_acc_m", reported_m), ("v_acc_m", 1.5 * reported_m)):
        g = g.set_column(g.column_names.index(name), name, pa.array(np.full(g.num_rows, val)))
    return {**tables, "gnss": g}


def scenarios(
    tables: Mapping[str, pa.Table], seed: int, *, burst_start_s: float = 300.0,
    outage: tuple[float, float, float] = (200.0, 150.0, 30.0),
) -> dict[str, tuple[dict[str, pa.Table], list[Window]]]:  # fmt: skip
    """The four scenarios: name -> (tables, the windows to evaluate inside)."""
    t = np.asarray(tables["gnss"].column("t_ns").to_numpy(), dtype=np.int64)
    burst = (int(t[0]) + round(burst_start_s * 1e9), int(t[0]) + round((burst_start_s + 30) * 1e9))
    rng = np.random.default_rng(np.random.SeedSequence([seed, 4, 7]))
    windows = periodic_windows(t, *outage)
    return {
        "nominal": (dict(tables), []),
        "F7_multipath_burst": (multipath_burst(tables, burst, rng), [burst]),
        "F8_optimistic_accuracy": (optimistic_accuracy(tables, rng), []),
        "outages": (drop_fixes(tables, windows, ("gnss",)), windows),
    }


def _filter(filters: FiltersParams, name: str) -> tuple[str, InsFilterParams]:
    """(filter kind name, its section) of one of ``FILTERS``."""
    if name == "lc_ekf_white":
        return "lc_ekf", replace(filters.get("lc_ekf"), gnss=filters.get("fwekf").gnss.white())
    if name == "fwekf":  # the paper's: its fuzzy weighting judges white fix errors
        return name, replace(filters.fwekf, gnss=filters.fwekf.gnss.white())
    return name, filters.get(name)


def fault_rows(
    tables: Mapping[str, pa.Table], sensors: SensorMeta | None, filters: FiltersParams,
    seed: int, backend: Backend = "numba",
) -> list[dict[str, Any]]:  # fmt: skip
    """One row per scenario and filter (see the module docstring)."""
    rows = []
    for scen, (tabs, windows) in scenarios(tables, seed).items():
        for name in FILTERS:
            res = run_filter(tabs, sensors, *_filter(filters, name), backend=backend)
            inside, err, _ = error_states(res, tables["truth"])
            h = np.hypot(err[:, 0], err[:, 1])
            t = res.t_ns[inside]
            win = in_windows(t, windows) if windows else np.zeros(t.size, bool)
            nis = nis_summary(res).get("gnss_pos", {})
            alpha = res.extra.get("alpha", np.ones(1))
            rows.append({
                "scenario": scen, "filter": name,
                "pos_h_rms_m": float(np.sqrt(np.mean(h**2))),
                "pos_h_max_m": float(h.max()),
                "pos_h_rms_in_window_m": (
                    float(np.sqrt(np.mean(h[win] ** 2))) if win.any() else None
                ),
                "pos_h_max_in_window_m": float(h[win].max()) if win.any() else None,
                "nis_pos_mean": nis.get("nis_mean"),
                "nis_pos_consistent": nis.get("consistent"),
                "gate_rejections": sum(1 for e in res.events if e.kind == "gate_reject"),
                "gate_resets": sum(1 for e in res.events if e.kind == "gate_reset"),
                "alpha_median": float(np.median(alpha)),
                "alpha_p95": float(np.percentile(alpha, 95)),
                "r_scale_median": (
                    float(np.median(res.extra["r_scale"])) if "r_scale" in res.extra else None
                ),
            })  # fmt: skip
    return rows
