"""``metrics.json`` of one run: accuracy against truth, consistency, gating, cost.

Accuracy (architecture section 5) compares the estimate with the truth table interpolated to
the estimate's times: horizontal, vertical and 3-D position error (NED metres), velocity and
attitude error (the nav-frame rotation vector of ``C_true C_est^T``). Consistency:

- NEES of the navigation states (position, velocity, attitude: 9 dof) and of every state the
  truth table has (``nees_full``: + biases, + clock for tight coupling), time-averaged;
- NIS per stream, time-averaged, with the two-sided 95 % chi-square interval for that average
  over K updates (``K * mean ~ chi2(sum of the block dimensions)``, bad-inputs.md), and the
  fraction of blocks rejected by the gate.

Outage windows (``ins.tracks``): with ``windows``, ``outage_windows`` lists the drift
metrics of each window, against the truth or, without one, against the withheld fixes.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import pyarrow as pa

from navreplay.pipeline.estimation.core.consistency import nees, nis_by_stream
from navreplay.pipeline.estimation.core.contract import RunMetrics
from navreplay.pipeline.estimation.core.windows import Window, WindowMetricsParams
from navreplay.pipeline.estimation.ins.models import measurement as me
from navreplay.pipeline.estimation.ins.replay import RunResult
from navreplay.pipeline.estimation.ins.tracks import outage_windows
from navreplay.pipeline.estimation.ins.truth import error_states, position_truth
from navreplay.pipeline.nav.earth import F64


def _rms(a: F64) -> float | None:
    return float(np.sqrt(np.mean(np.square(a)))) if a.size else None


def nis_summary(result: RunResult) -> dict[str, dict[str, Any]]:
    """``nis_by_stream`` of an INS/GNSS run (streams ``models.measurement.STREAM_NAMES``)."""
    return nis_by_stream(result.inn_i, result.inn_f, me.STREAM_NAMES)


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
    m = RunMetrics.of(result, nis_summary(result)).to_json()
    m.update(
        {
            "compile_s": result.compile_s,
            "alignment": [a.summary() for a in result.alignments],
            "imu_noise": result.imu_noise,
            "fix_noise": result.fix_noise,
            "obs_noise": result.obs_noise,
        }
    )
    if windows:
        params = window_params or WindowMetricsParams()
        m["outage_windows"] = outage_windows(result, truth, fixes, lever_b, windows, t0_ns, params)
    if truth is None or truth.num_rows == 0 or result.t_ns.size == 0 or not position_truth(truth):
        m["truth"] = False
        return m
    inside, err, names = error_states(result, truth)
    P = result.P[inside][:, : len(names), : len(names)]
    pos_h = np.hypot(err[:, 0], err[:, 1])
    pos_3d = np.sqrt(np.sum(err[:, 0:3] ** 2, axis=1))
    sig_h = np.sqrt(P[:, 0, 0] + P[:, 1, 1])
    # The states the truth covers (a simulator's truth may lack velocity or attitude).
    have = [j for j in range(9) if err.size and np.isfinite(err[:, j]).all()]
    e_nav = nees(err[:, have], P[:, have][:, :, have])
    vel = all(j in have for j in (3, 4, 5))
    att = all(j in have for j in (6, 7, 8))
    m.update(
        {
            "truth": True,
            "pos_err_h_rms_m": _rms(pos_h),
            "pos_err_v_rms_m": _rms(err[:, 2]) if 2 in have else None,
            "pos_err_3d_rms_m": _rms(pos_3d) if 2 in have else None,
            "pos_err_3d_max_m": float(pos_3d.max()) if pos_3d.size and 2 in have else None,
            "vel_err_3d_rms_mps": _rms(np.sqrt(np.sum(err[:, 3:6] ** 2, axis=1))) if vel else None,
            "att_err_rms_rad": {a: _rms(err[:, 6 + j]) for j, a in enumerate(("n", "e", "d"))}
            if att
            else None,
            "pos_h_within_3sigma": float(np.mean(pos_h <= 3.0 * sig_h)) if pos_h.size else None,
            "nees_mean": float(e_nav.mean()) if e_nav.size else None,
            "nees_dof": len(have),
            "nees_states": [names[j] for j in have],
        }
    )
    if len(have) < 9:
        m["truth_missing"] = [n for j, n in enumerate(names[:9]) if j not in have]
    if len(names) > 9 and len(have) == 9:
        e_full = nees(err, P)
        m["nees_full_mean"] = float(e_full.mean())
        m["nees_full_dof"] = len(names)
    return m
