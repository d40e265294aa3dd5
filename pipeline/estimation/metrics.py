"""``metrics.json`` of one run: accuracy against truth, consistency, gating, cost.

Accuracy (architecture section 5) compares the estimate with the truth table interpolated to
the estimate's times: horizontal, vertical and 3-D position error (NED metres), velocity and
attitude error (the nav-frame rotation vector of ``C_true C_est^T``). Consistency:

- NEES of the navigation states (position, velocity, attitude: 9 dof) and of every state the
  truth table has (``nees_full``: + biases, + clock for tight coupling), time-averaged;
- NIS per stream, time-averaged, with the two-sided 95 % chi-square interval for that average
  over K updates (``K * mean ~ chi2(sum of the block dimensions)``, bad-inputs.md), and the
  fraction of blocks rejected by the gate.

Outage windows (``outage_metrics``): with ``windows``, ``outage_windows`` lists the drift
metrics of each window, against the truth or, without one, against the withheld fixes.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt
import pyarrow as pa
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from pipeline.estimation.models import ins
from pipeline.estimation.models import measurement as me
from pipeline.estimation.outage_metrics import outage_windows
from pipeline.estimation.outputs import BIAS_COLUMNS, CLOCK_COLUMNS
from pipeline.estimation.replay import RunResult
from pipeline.nav.earth import E2, F64, A
from pipeline.scenarios.config import WindowMetricsParams
from pipeline.scenarios.windows import Window

_NAV_TRUTH = ("lat_deg", "lon_deg", "alt_m", "vel_n_mps", "vel_e_mps", "vel_d_mps")
_ANGLES = ("roll_rad", "pitch_rad", "yaw_rad")


def _rms(a: F64) -> float | None:
    return float(np.sqrt(np.mean(np.square(a)))) if a.size else None


def truth_at(truth: pa.Table, t_ns: np.ndarray) -> tuple[np.ndarray, dict[str, F64]]:
    """Truth columns interpolated to ``t_ns`` (only times inside the truth's span).

    Returns:
        (boolean mask of the usable times, column name -> values at those times); angles
        are interpolated unwrapped.
    """
    tt = np.asarray(truth.column("t_ns").to_numpy(), dtype=np.int64)
    inside = (t_ns >= tt[0]) & (t_ns <= tt[-1])
    t = t_ns[inside].astype(np.float64)
    ttf = tt.astype(np.float64)
    out: dict[str, F64] = {}
    for name in truth.column_names:
        if name == "t_ns":
            continue
        col = truth.column(name)
        if col.null_count == len(col):
            continue
        v = np.asarray(col.to_numpy(zero_copy_only=False), dtype=np.float64)
        if name in _ANGLES:
            out[name] = np.angle(np.exp(1j * np.interp(t, ttf, np.unwrap(v))))
        else:
            out[name] = np.interp(t, ttf, v)
    return inside, out


def error_states(result: RunResult, truth: pa.Table) -> tuple[np.ndarray, F64, list[str]]:
    """Truth-minus-estimate in the filter's error coordinates (``models.ins``).

    Returns:
        (mask of the estimate rows with truth, errors (K, k), names of the k states covered:
        position, velocity, attitude always; biases and clock when the truth has them).
    """
    inside, tr = truth_at(truth, result.t_ns)
    x = result.x[inside]
    lat, h = x[:, ins.X_LAT], x[:, ins.X_H]
    s2 = np.sin(lat) ** 2
    rn = A / np.sqrt(1.0 - E2 * s2)
    rm = rn * (1.0 - E2) / (1.0 - E2 * s2)
    dlon = np.angle(np.exp(1j * (np.radians(tr["lon_deg"]) - x[:, ins.X_LON])))
    cols = [
        (np.radians(tr["lat_deg"]) - lat) * (rm + h),
        dlon * (rn + h) * np.cos(lat),
        -(tr["alt_m"] - h),
    ]
    names = ["pos_n", "pos_e", "pos_d"]
    for j, axis in enumerate("ned"):
        cols.append(tr[f"vel_{axis}_mps"] - x[:, ins.X_VEL + j])
        names.append(f"vel_{axis}")
    r_true = Rotation.from_euler("ZYX", np.column_stack([tr[a] for a in _ANGLES[::-1]]))
    q = x[:, ins.X_Q : ins.X_Q + 4]
    r_est = Rotation.from_quat(q[:, [1, 2, 3, 0]])
    att = (r_true * r_est.inv()).as_rotvec()
    cols += [att[:, 0], att[:, 1], att[:, 2]]
    names += ["att_n", "att_e", "att_d"]
    extra = BIAS_COLUMNS + (CLOCK_COLUMNS if result.n > ins.N_LOOSE else ())
    if all(c[0] in tr for c in extra):
        for col, xi, _, _ in extra:
            cols.append(tr[col] - x[:, xi])
            names.append(col)
    return inside, np.column_stack(cols) if cols else np.zeros((0, 0)), names


def nees(err: F64, P: F64) -> F64:
    """Per-row NEES ``e^T P^-1 e`` for errors (K, k) and covariances (K, k, k)."""
    sol = np.linalg.solve(P, err[:, :, None])[:, :, 0]
    return np.asarray(np.sum(err * sol, axis=1))


def nis_by_stream(
    inn_i: npt.NDArray[np.int64], inn_f: F64, stream_names: Sequence[str]
) -> dict[str, dict[str, Any]]:
    """Per stream of an innovation log (columns t_ns, stream, sv, dim, accepted / nis, ...):
    count, mean NIS, mean dof, the 95 % interval of the mean, rejections.

    Shared by every filter family (INS, vehicle, cascaded): stream codes index
    ``stream_names``; streams without a block are left out.
    """
    out: dict[str, dict[str, Any]] = {}
    for code, name in enumerate(stream_names):
        sel = inn_i[:, 1] == code
        k = int(sel.sum())
        if k == 0:
            continue
        dof = int(inn_i[sel, 3].sum())
        mean = float(inn_f[sel, 0].mean())
        lo, hi = chi2.ppf(0.025, dof) / k, chi2.ppf(0.975, dof) / k
        out[name] = {
            "count": k,
            "nis_mean": mean,
            "dof_mean": dof / k,
            "nis_bounds_95": [float(lo), float(hi)],
            "consistent": bool(lo <= mean <= hi),
            "rejected": int((inn_i[sel, 4] == 0).sum()),
        }
    return out


def nis_summary(result: RunResult) -> dict[str, dict[str, Any]]:
    """``nis_by_stream`` of an INS/GNSS run (streams ``models.measurement.STREAM_NAMES``)."""
    return nis_by_stream(result.inn_i, result.inn_f, me.STREAM_NAMES)


def _full_truth(truth: pa.Table) -> bool:
    """Whether the truth has position, velocity and attitude (a simulator's may lack some)."""
    cols = (*_NAV_TRUTH, *_ANGLES)
    return all(c in truth.column_names and truth.column(c).null_count < len(truth) for c in cols)


def compute_metrics(
    result: RunResult,
    truth: pa.Table | None,
    *,
    windows: Sequence[Window] = (),
    t0_ns: int = 0,
    window_params: WindowMetricsParams | None = None,
    fixes: pa.Table | None = None,
    lever_b: Sequence[float] = (0.0, 0.0, 0.0),
) -> dict[str, Any]:
    """The metrics of one run (see the module docstring); error metrics need ``truth``.

    ``windows`` (from ``t0_ns``) add ``outage_windows``; ``fixes`` (the unmodified GNSS fixes)
    are their reference when there is no truth, with the antenna ``lever_b``.
    """
    kinds: dict[str, int] = {}
    for e in result.events:
        kinds[e.kind] = kinds.get(e.kind, 0) + 1
    nis = nis_summary(result)
    m: dict[str, Any] = {
        "filter": result.filter,
        "backend": result.backend,
        "status": result.status,
        "failure": result.failure,
        "runtime_s": result.runtime_s,
        "compile_s": result.compile_s,
        "duration_s": result.duration_s,
        "realtime_factor": result.duration_s / result.runtime_s if result.runtime_s else None,
        "epochs": int(result.t_ns.size),
        "nis": nis,
        "nis_mean": {k: v["nis_mean"] for k, v in nis.items()},
        "gate_rejections": int(sum(v["rejected"] for v in nis.values())),
        "gate_resets": kinds.get("gate_reset", 0),
        "cov_repairs": kinds.get("cov_repair", 0),
        "events": kinds,
        "alignment": [a.summary() for a in result.alignments],
        "imu_noise": result.imu_noise,
    }
    if windows:
        params = window_params or WindowMetricsParams()
        m["outage_windows"] = outage_windows(result, truth, fixes, lever_b, windows, t0_ns, params)
    if truth is None or truth.num_rows == 0 or result.t_ns.size == 0 or not _full_truth(truth):
        m["truth"] = False
        return m
    inside, err, names = error_states(result, truth)
    P = result.P[inside][:, : len(names), : len(names)]
    pos_h = np.hypot(err[:, 0], err[:, 1])
    pos_3d = np.sqrt(np.sum(err[:, 0:3] ** 2, axis=1))
    sig_h = np.sqrt(P[:, 0, 0] + P[:, 1, 1])
    e_nav = nees(err[:, :9], P[:, :9, :9])
    m.update(
        {
            "truth": True,
            "pos_err_h_rms_m": _rms(pos_h),
            "pos_err_v_rms_m": _rms(err[:, 2]),
            "pos_err_3d_rms_m": _rms(pos_3d),
            "pos_err_3d_max_m": float(pos_3d.max()) if pos_3d.size else None,
            "vel_err_3d_rms_mps": _rms(np.sqrt(np.sum(err[:, 3:6] ** 2, axis=1))),
            "att_err_rms_rad": {a: _rms(err[:, 6 + j]) for j, a in enumerate(("n", "e", "d"))},
            "pos_h_within_3sigma": float(np.mean(pos_h <= 3.0 * sig_h)) if pos_h.size else None,
            "nees_mean": float(e_nav.mean()) if e_nav.size else None,
            "nees_dof": 9,
            "nees_states": names[:9],
        }
    )
    if len(names) > 9:
        e_full = nees(err, P)
        m["nees_full_mean"] = float(e_full.mean())
        m["nees_full_dof"] = len(names)
    return m
