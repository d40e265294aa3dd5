"""Accuracy of a vehicle-filter run against truth, overall and per speed band.

Errors are truth minus estimate at the estimate's times (truth interpolated): horizontal
position (local north/east of the run's map), heading and course (wrapped), speed, and the
sideslip where the truth has ``slip_angle_rad``. Speed bands are by true speed (``speed_mps``,
or the horizontal truth velocity).
"""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np
import pyarrow as pa

from navreplay.pipeline.estimation.core.consistency import nis_by_stream
from navreplay.pipeline.estimation.core.contract import RunMetrics
from navreplay.pipeline.estimation.core.tables import truth_at
from navreplay.pipeline.estimation.vehicle import kernel as kv
from navreplay.pipeline.estimation.vehicle import model as vm
from navreplay.pipeline.estimation.vehicle.replay import VehicleRunResult
from navreplay.pipeline.nav.earth import F64


def _wrap(a: F64) -> F64:
    return np.asarray(np.angle(np.exp(1j * a)))


def errors(result: VehicleRunResult, truth: pa.Table) -> dict[str, F64]:
    """Per-output errors (truth - estimate) and the true speed; rows without truth dropped.

    Returns:
        ``t_ns``, ``pos_h_m``, ``pos_n_m``, ``pos_e_m``, ``heading_rad``, ``course_rad``,
        ``speed_mps``, ``true_speed_mps`` and, if the truth has it, ``slip_rad``.
    """
    inside, tr = truth_at(truth, result.t_ns)
    x = result.x[inside]
    n, e, _ = result.origin.to_ned(tr["lat_deg"], tr["lon_deg"], result.origin.alt_m)
    dn, de = n - x[:, vm.X_N], e - x[:, vm.X_E]
    v_true = tr["speed_mps"] if "speed_mps" in tr else np.hypot(tr["vel_n_mps"], tr["vel_e_mps"])
    course_true = np.arctan2(tr["vel_e_mps"], tr["vel_n_mps"]) if "vel_n_mps" in tr else None
    out: dict[str, F64] = {
        "t_ns": result.t_ns[inside],
        "pos_n_m": dn,
        "pos_e_m": de,
        "pos_h_m": np.hypot(dn, de),
        "speed_mps": v_true - x[:, vm.X_V],
        "true_speed_mps": v_true,
    }
    if "yaw_rad" in tr:
        out["heading_rad"] = _wrap(tr["yaw_rad"] - x[:, vm.X_PSI])
    if course_true is not None:
        out["course_rad"] = _wrap(course_true - x[:, vm.X_PSI] - x[:, vm.X_BETA])
    if "slip_angle_rad" in tr:
        out["slip_rad"] = tr["slip_angle_rad"] - x[:, vm.X_BETA]
    return out


def _rms(a: F64) -> float | None:
    a = a[np.isfinite(a)]
    return float(np.sqrt(np.mean(np.square(a)))) if a.size else None


def summarize(err: dict[str, F64], mask: np.ndarray | None = None) -> dict[str, Any]:
    """RMS of each error (and the max horizontal error) over the rows in ``mask``."""
    sel = np.ones(err["t_ns"].size, bool) if mask is None else np.asarray(mask, bool)
    out: dict[str, Any] = {"samples": int(sel.sum())}
    for key in ("pos_h_m", "heading_rad", "course_rad", "slip_rad", "speed_mps"):
        if key in err:
            out[f"{key.rsplit('_', 1)[0]}_rms_{key.rsplit('_', 1)[1]}"] = _rms(err[key][sel])
    h = err["pos_h_m"][sel]
    out["pos_h_max_m"] = float(h.max()) if h.size else None
    return out


def per_band(
    err: dict[str, F64], edges: tuple[float, ...], mask: F64 | None = None
) -> list[dict[str, Any]]:
    """``summarize`` per true-speed band ``[edges[i], edges[i+1])``."""
    v = err["true_speed_mps"]
    base = np.ones(v.size, bool) if mask is None else np.asarray(mask, bool)
    rows = []
    for lo, hi in itertools.pairwise(edges):
        row = {"band_lo_mps": lo, "band_hi_mps": hi}
        row.update(summarize(err, base & (v >= lo) & (v < hi)))
        rows.append(row)
    return rows


def nis_summary(result: VehicleRunResult) -> dict[str, dict[str, Any]]:
    """``metrics.nis_by_stream`` of a vehicle-filter run (``vehicle.kernel.STREAM_NAMES``)."""
    return nis_by_stream(result.inn_i, result.inn_f, kv.STREAM_NAMES)


def compute_metrics(result: VehicleRunResult, truth: pa.Table | None) -> dict[str, Any]:
    """``metrics.json`` of a vehicle-filter run."""
    m = RunMetrics.of(result, nis_summary(result)).to_json()
    m["steer_source"] = result.steer_source
    m["init"] = result.init
    m["dynamic_share"] = float(np.mean(result.aux)) if result.aux.size else None
    if truth is None or truth.num_rows == 0 or result.t_ns.size == 0:
        m["truth"] = False
        return m
    err = errors(result, truth)
    m["truth"] = True
    s = summarize(err)
    m["pos_err_h_rms_m"] = s["pos_h_rms_m"]
    m["pos_err_h_max_m"] = s["pos_h_max_m"]
    m.update({k: v for k, v in s.items() if k not in ("pos_h_rms_m", "pos_h_max_m")})
    return m
