"""Metrics of one cascaded run: accuracy against truth, bias convergence, consistency, cost.

Truth is the filters' own state layout ``[X1, X2]`` (``truth_x``): from a closed-loop run's
simulator, or from a dataset's truth table (``truth_from_table``: position mapped into the
run's local frame, the other states from the truth table's extra columns, NaN where
absent). Definitions (architecture section 5):

- position error: estimate minus truth, East, North and horizontal, RMS and max;
- *bias convergence time* (paper 000): the first time after which the bias estimate stays
  within ``band`` of the true bias until the end of the run (``None`` when the last sample
  is outside the band: not converged);
- NIS per stream, time-averaged, with the two-sided 95 % chi-square interval of that average
  (``K * mean ~ chi2(sum of the block dimensions)``), and gate rejections;
- NEES of each filter (6 dof) against truth, time-averaged.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pyarrow as pa

from navreplay.pipeline.estimation.cascaded.cascade import STREAM_NAMES
from navreplay.pipeline.estimation.cascaded.config import ConvergenceBand
from navreplay.pipeline.estimation.cascaded.engine import CascadedResult
from navreplay.pipeline.estimation.cascaded.model import NAV_E, NAV_N, NAV_PSI, NX
from navreplay.pipeline.estimation.cascaded.outputs import STATE_COLUMNS
from navreplay.pipeline.estimation.core.consistency import nis_by_stream
from navreplay.pipeline.estimation.core.contract import RunMetrics
from navreplay.pipeline.nav.earth import F64
from navreplay.pipeline.nav.local import LocalFrame

#: the four biases: (metric name, index into [X1, X2])
BIASES: tuple[tuple[str, int], ...] = (
    ("radar_bias_mps", 2),
    ("gyro_bias_z_radps", 4),
    ("heading_bias_rad", 5),
    ("steer_bias_rad", NX + 5),
)


def convergence_time_s(t_s: F64, est: F64, true: F64, band: float) -> float | None:
    """First time after which ``|est - true| <= band`` holds to the end; None if the last
    sample is outside (or the arrays are empty)."""
    out = ~(np.abs(est - true) <= band)
    if out.size == 0 or out[-1]:
        return None
    bad = np.flatnonzero(out)
    return float(t_s[0] if bad.size == 0 else t_s[bad[-1] + 1])


def bias_convergence(
    t_s: F64, x: F64, truth_x: F64, band: ConvergenceBand
) -> dict[str, float | None]:
    """Convergence time of each bias (``BIASES`` names), s from the first sample."""
    rel = t_s - t_s[0] if t_s.size else t_s
    return {
        name: convergence_time_s(rel, x[:, i], truth_x[:, i], b)
        for (name, i), b in zip(BIASES, band.values(), strict=True)
    }


def truth_from_table(truth: pa.Table, frame: LocalFrame, t_ns: np.ndarray) -> F64:
    """``[X1, X2]`` truth interpolated to ``t_ns`` (K, 12); NaN outside the truth's span or
    where the truth table lacks the state."""
    tt = np.asarray(truth.column("t_ns").to_numpy(), dtype=np.int64).astype(np.float64)
    t = np.asarray(t_ns, dtype=np.float64)
    inside = (t >= tt[0]) & (t <= tt[-1])

    def col(name: str) -> F64 | None:
        if name not in truth.column_names:
            return None
        v = np.asarray(truth.column(name).to_numpy(zero_copy_only=False), dtype=np.float64)
        out = np.interp(t, tt, v)
        out[~inside] = np.nan
        return out

    out = np.full((t.size, 2 * NX), np.nan)
    lat, lon, alt = col("lat_deg"), col("lon_deg"), col("alt_m")
    if lat is not None and lon is not None:
        north, east, _ = frame.to_ned(lat, lon, alt if alt is not None else frame.alt_m)
        out[:, NAV_E], out[:, NAV_N] = east, north
    yaw = col("yaw_rad")
    if yaw is not None:
        v = np.asarray(truth.column("yaw_rad").to_numpy(zero_copy_only=False), dtype=np.float64)
        out[:, NAV_PSI] = np.interp(t, tt, np.unwrap(v))
        out[~inside, NAV_PSI] = np.nan
    for i, name, _ in STATE_COLUMNS:
        if i not in (NAV_E, NAV_N, NAV_PSI):
            c = col(name)
            if c is not None:
                out[:, i] = c
    return out


def _rms(a: F64) -> float | None:
    a = a[np.isfinite(a)]
    return float(np.sqrt(np.mean(np.square(a)))) if a.size else None


def nis_summary(result: CascadedResult) -> dict[str, dict[str, Any]]:
    """``metrics.nis_by_stream`` of a cascaded run (``cascade.STREAM_NAMES``)."""
    return nis_by_stream(result.inn_i, result.inn_f, STREAM_NAMES)


def _nees(err: F64, P: F64) -> float | None:
    ok = np.isfinite(err).all(axis=1)
    if not ok.any():
        return None
    sol = np.linalg.solve(P[ok], err[ok][:, :, None])[:, :, 0]
    return float(np.mean(np.sum(err[ok] * sol, axis=1)))


def compute_metrics(
    result: CascadedResult, truth_x: F64 | None, band: ConvergenceBand
) -> dict[str, Any]:
    """The metrics of one run (module docstring); accuracy needs ``truth_x`` (K, 12)."""
    m = RunMetrics.of(result, nis_summary(result)).to_json()
    if truth_x is None or result.t_ns.size == 0:
        m["truth"] = False
        return m
    x = result.x
    err = x - truth_x
    e_h = np.hypot(err[:, NAV_E], err[:, NAV_N])
    t_s = (result.t_ns - result.t_ns[0]) * 1e-9
    finite_h = e_h[np.isfinite(e_h)]
    m.update(
        {
            "truth": True,
            "pos_err_e_rms_m": _rms(err[:, NAV_E]),
            "pos_err_n_rms_m": _rms(err[:, NAV_N]),
            "pos_err_h_rms_m": _rms(e_h),
            "pos_err_h_max_m": float(finite_h.max()) if finite_h.size else None,
            "heading_err_rms_rad": _rms(err[:, NAV_PSI]),
            "bias_final": {name: float(x[-1, i]) for name, i in BIASES},
            "bias_err_final": {
                name: float(err[-1, i]) if math.isfinite(err[-1, i]) else None for name, i in BIASES
            },
            "bias_convergence_s": bias_convergence(t_s, x, truth_x, band),
            "convergence_band": dict(zip((n for n, _ in BIASES), band.values(), strict=True)),
            "nees_nav_mean": _nees(err[:, :NX], result.P[:, 0]),
            "nees_ctl_mean": _nees(err[:, NX:], result.P[:, 1]),
            "nees_dof": NX,
        }
    )
    return m
