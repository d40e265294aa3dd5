"""The position errors of an INS run against its reference, for the outage-window metrics
(``estimation.core.windows``): against the truth at the estimate's times (``truth_track``, the
error states of ``truth.error_states``), or, on a real log without truth, against the GNSS
fixes the scenario withheld (``fixes_track``: the estimate moved to the antenna by the lever
arm and the estimated attitude).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import pyarrow as pa

from navreplay.pipeline.estimation.core.tables import fix_epochs, truth_at
from navreplay.pipeline.estimation.core.windows import (
    ErrorTrack,
    Origin,
    Window,
    WindowMetricsParams,
    local_ned,
    ned_error,
    window_metrics,
)
from navreplay.pipeline.estimation.ins.models import ins
from navreplay.pipeline.estimation.ins.replay import RunResult
from navreplay.pipeline.estimation.ins.truth import error_states
from navreplay.pipeline.nav.rotations import quat_to_dcm


def truth_track(result: RunResult, truth: pa.Table, origin: Origin | None = None) -> ErrorTrack:
    """Errors against the truth table at the estimate's times (``truth.error_states``);
    reference positions relative to ``origin`` (default: the first)."""
    inside, err, _ = error_states(result, truth)
    t = result.t_ns[inside]
    _, tr = truth_at(truth, t)
    sig = np.sqrt(np.clip(np.diagonal(result.P[inside], axis1=1, axis2=2)[:, :3], 0.0, None))
    ref, org = local_ned(np.radians(tr["lat_deg"]), np.radians(tr["lon_deg"]), tr["alt_m"], origin)
    # a truth without height (a simulator's state message) measures the horizontal error only
    axes = 3 if np.isfinite(err[:, 2]).all() else 2
    return ErrorTrack(t, err[:, :3], sig, ref, "truth", org, axes=axes)


def fixes_track(
    result: RunResult, fixes: pa.Table, lever_b: Sequence[float], origin: Origin | None = None
) -> ErrorTrack:
    """Errors against GNSS fixes (antenna positions) at the fix epochs inside the run
    (``inputs.fix_epochs``: their stamps less a latency the table gives).

    The estimate is interpolated linearly to each fix time and moved to the antenna by the
    lever arm (body FRD, rotated by the estimated attitude).
    """
    t_fix = fix_epochs(fixes)
    cols = {}
    for name in ("lat_deg", "lon_deg", "alt_m"):
        c = fixes.column(name)
        cols[name] = np.asarray(c.to_numpy(zero_copy_only=False), dtype=np.float64)
    ok = np.isfinite(cols["lat_deg"]) & np.isfinite(cols["lon_deg"]) & np.isfinite(cols["alt_m"])
    if result.t_ns.size:
        ok &= (t_fix >= result.t_ns[0]) & (t_fix <= result.t_ns[-1])
    else:
        ok[:] = False
    t = t_fix[ok]
    te, x = result.t_ns.astype(np.float64), result.x
    lat = np.interp(t, te, x[:, ins.X_LAT])
    lon = np.interp(t, te, np.unwrap(x[:, ins.X_LON]))
    h = np.interp(t, te, x[:, ins.X_H])
    near = np.clip(np.searchsorted(result.t_ns, t), 0, max(result.t_ns.size - 1, 0))
    lever = np.asarray(lever_b, dtype=np.float64)
    arm = np.array([quat_to_dcm(x[j, ins.X_Q : ins.X_Q + 4]) @ lever for j in near]).reshape(-1, 3)
    f_lat, f_lon = np.radians(cols["lat_deg"][ok]), np.radians(cols["lon_deg"][ok])
    err = ned_error(lat, lon, h, f_lat, f_lon, cols["alt_m"][ok]) - arm
    P = result.P[near] if result.P.size else np.zeros((0, 3, 3))
    sig = np.sqrt(np.clip(np.diagonal(P, axis1=1, axis2=2)[:, :3], 0.0, None))
    ref, org = local_ned(f_lat, f_lon, cols["alt_m"][ok], origin)
    return ErrorTrack(t, err, sig, ref, "withheld_fixes", org)


def ins_track(
    result: RunResult, truth: pa.Table | None, fixes: pa.Table | None, lever_b: Sequence[float]
) -> ErrorTrack | None:
    """An INS run's errors against the truth, else against the fixes; None without either."""
    if result.t_ns.size == 0:
        return None
    if truth is not None and truth.num_rows:
        return truth_track(result, truth)
    if fixes is not None and fixes.num_rows:
        return fixes_track(result, fixes, lever_b)
    return None


def outage_windows(
    result: RunResult,
    truth: pa.Table | None,
    fixes: pa.Table | None,
    lever_b: Sequence[float],
    windows: Sequence[Window],
    t0_ns: int,
    params: WindowMetricsParams,
) -> list[dict[str, Any]]:
    """Window metrics against the truth, else against the (withheld) fixes; [] without any."""
    track = ins_track(result, truth, fixes, lever_b) if windows else None
    return [] if track is None else window_metrics(track, windows, t0_ns, params)
