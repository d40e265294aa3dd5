"""The vehicle's own estimate as a reference: how far each replayed run is from it.

A flight log carries the navigation solution the vehicle computed in flight (ArduPilot's
EKF2/EKF3 NKF1/XKF1, PX4's vehicle_global_position and vehicle_attitude, MAVLink
GLOBAL_POSITION_INT and ATTITUDE): the dataset's ``estimator`` table. It is not truth: it
fused the same fixes with its own model. But it kept GNSS through the outages navreplay
injects, so inside an outage window a replayed filter's difference from it is that filter's
drift against an estimate that kept GNSS.

Differences are onboard minus replayed, at the onboard estimate's times inside the run (the
replayed estimate interpolated linearly between its samples; a gap longer than
``MAX_GAP_S`` is not bridged): position in local NED metres (the replayed latitude and height
set the radii of curvature), NED velocity in m/s, and roll, pitch and yaw in degrees (each
wrapped to +-180 deg).

``comparison_rows`` gives one row per run over the whole run (``scope`` ``run``), and one per
outage window (``scope`` ``window``): the 3-D and horizontal difference at the last onboard
sample inside the window, its maximum and mean there, and the drift as a percentage of the
distance the onboard track travelled in the window where that is over ``MIN_DISTANCE_M``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pyarrow as pa

from navreplay.ingest.schema import ESTIMATOR_INNOVATIONS, ESTIMATOR_TEST_RATIOS
from navreplay.pipeline.nav.earth import F64
from navreplay.pipeline.report.inputs import DatasetInputs, Run, column, times_ns
from navreplay.pipeline.report.series import local_en, ned_difference
from navreplay.pipeline.report.tables import MIN_DISTANCE_M

Row = dict[str, Any]
MAX_GAP_S = 1.0  # a replayed estimate's gap longer than this is not interpolated across
REFERENCE = "onboard"

#: the report's table of these rows (``tables/<name>``)
CSV_NAME = "onboard_comparison.csv"
COLUMNS = ("filter", "scenario", "scope", "window", "start_s", "duration_s", "samples",
           "pos_h_rms_m", "pos_h_max_m", "pos_v_rms_m", "vel_3d_rms_mps", "roll_rms_deg",
           "pitch_rms_deg", "yaw_rms_deg", "pos_3d_end_m", "pos_h_end_m", "pos_3d_max_m",
           "pos_3d_mean_m", "distance_m", "drift_pct_distance", "reference")  # fmt: skip

_ATTITUDE = ("roll_rad", "pitch_rad", "yaw_rad")
_VELOCITY = ("vel_n_mps", "vel_e_mps", "vel_d_mps")


@dataclass(frozen=True)
class Difference:
    """Onboard minus replayed at the onboard times ``t_ns`` (see the module docstring).

    Attributes:
        pos_ned_m: (K, 3) NED metres; vel_ned_mps: (K, 3) m/s (NaN where either lacks it);
        att_deg: (K, 3) roll, pitch, yaw in degrees, wrapped (NaN where either lacks it);
        onboard_en_m: (K, 2) east and north of the onboard track from its first sample.
    """

    t_ns: np.ndarray
    pos_ned_m: F64
    vel_ned_mps: F64
    att_deg: F64
    onboard_en_m: F64

    @property
    def pos_h_m(self) -> F64:
        return np.asarray(np.hypot(self.pos_ned_m[:, 0], self.pos_ned_m[:, 1]))

    @property
    def pos_3d_m(self) -> F64:
        return np.asarray(np.sqrt(np.sum(self.pos_ned_m**2, axis=1)))


def _bridged(t_est: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Which times ``t`` lie inside the estimate's span and not inside a gap of it."""
    inside = (t >= t_est[0]) & (t <= t_est[-1])
    j = np.clip(np.searchsorted(t_est, t), 1, max(t_est.size - 1, 1))
    gap = (t_est[j] - t_est[j - 1]) / 1e9 if t_est.size > 1 else np.zeros(t.size)
    return np.asarray(inside & (gap <= MAX_GAP_S))


def _wrap_deg(x: F64) -> F64:
    return np.asarray(np.degrees(np.angle(np.exp(1j * x))))


def difference(estimate: pa.Table, onboard: pa.Table) -> Difference | None:
    """The onboard estimate minus ``estimate`` at the onboard times inside the estimate's span;
    None when they do not overlap."""
    if estimate.num_rows < 2 or onboard.num_rows == 0:
        return None
    t_est, t_ob = times_ns(estimate), times_ns(onboard)
    pos = ("lat_deg", "lon_deg", "alt_m")
    ok = _bridged(t_est, t_ob)
    for c in pos:
        ok &= np.isfinite(column(onboard, c))
    if not ok.any():
        return None
    t = t_ob[ok]
    te, tf = t_est.astype(np.float64), t.astype(np.float64)

    def at(name: str, *, angle: bool = False) -> F64:
        v = column(estimate, name)
        if angle:
            v = np.unwrap(v)
        return np.asarray(np.interp(tf, te, v))

    ob = {c: column(onboard, c)[ok] for c in (*pos, *_VELOCITY, *_ATTITUDE)}
    ours = {c: at(c, angle=c == "lon_deg") for c in pos}
    ours["lon_deg"] = np.degrees(np.angle(np.exp(1j * np.radians(ours["lon_deg"]))))
    d_pos = ned_difference(ours["lat_deg"], ours["lon_deg"], ours["alt_m"], ob)
    d_vel = np.column_stack([ob[c] - at(c) for c in _VELOCITY])
    d_att = np.column_stack([_wrap_deg(ob[c] - at(c, angle=True)) for c in _ATTITUDE])
    e, n = local_en(ob["lat_deg"], ob["lon_deg"], float(ob["lat_deg"][0]), float(ob["lon_deg"][0]))
    return Difference(t, d_pos, d_vel, d_att, np.column_stack([e, n]))


def _rms(x: F64) -> float | None:
    finite = x[np.isfinite(x)]
    return float(np.sqrt(np.mean(finite**2))) if finite.size else None


def _max(x: F64) -> float | None:
    finite = x[np.isfinite(x)]
    return float(finite.max()) if finite.size else None


def _run_row(r: Run, d: Difference, t0_ns: int) -> Row:
    return {
        "filter": r.filter,
        "scenario": r.scenario,
        "scope": "run",
        "window": None,
        "start_s": (int(d.t_ns[0]) - t0_ns) / 1e9,
        "duration_s": (int(d.t_ns[-1]) - int(d.t_ns[0])) / 1e9,
        "samples": int(d.t_ns.size),
        "pos_h_rms_m": _rms(d.pos_h_m),
        "pos_h_max_m": _max(d.pos_h_m),
        "pos_v_rms_m": _rms(d.pos_ned_m[:, 2]),
        "vel_3d_rms_mps": _rms(np.sqrt(np.sum(d.vel_ned_mps**2, axis=1))),
        "roll_rms_deg": _rms(d.att_deg[:, 0]),
        "pitch_rms_deg": _rms(d.att_deg[:, 1]),
        "yaw_rms_deg": _rms(d.att_deg[:, 2]),
        "reference": REFERENCE,
    }


def _window_row(r: Run, d: Difference, i: int, t0_ns: int) -> Row:
    w = r.windows[i]
    sel = (d.t_ns >= w.start_ns) & (d.t_ns <= w.end_ns)
    row: Row = {
        "filter": r.filter,
        "scenario": r.scenario,
        "scope": "window",
        "window": i,
        "start_s": (w.start_ns - t0_ns) / 1e9,
        "duration_s": w.duration_s,
        "samples": int(sel.sum()),
        "reference": REFERENCE,
    }
    if not sel.any():
        return row
    p3, ph = d.pos_3d_m[sel], d.pos_h_m[sel]
    en = d.onboard_en_m[sel]
    distance = float(np.sum(np.hypot(np.diff(en[:, 0]), np.diff(en[:, 1]))))
    row |= {
        "pos_3d_end_m": float(p3[-1]),
        "pos_h_end_m": float(ph[-1]),
        "pos_3d_max_m": float(p3.max()),
        "pos_3d_mean_m": float(p3.mean()),
        "distance_m": distance,
        "drift_pct_distance": 100.0 * float(p3[-1]) / distance
        if distance > MIN_DISTANCE_M
        else None,
    }
    return row


def differences(data: DatasetInputs) -> dict[tuple[str, str], Difference]:
    """The difference of every run that ran from the dataset's onboard estimate."""
    out: dict[tuple[str, str], Difference] = {}
    if data.onboard is None:
        return out
    for r in data.runs:
        if r.ran and r.estimate is not None:
            d = difference(r.estimate, data.onboard)
            if d is not None:
                out[(r.filter, r.scenario)] = d
    return out


def comparison_rows(data: DatasetInputs, diffs: dict[tuple[str, str], Difference]) -> list[Row]:
    """Per run: its row over the whole run, then one per outage window (module docstring)."""
    rows: list[Row] = []
    t0 = data.t0_ns()
    for r in data.runs:
        d = diffs.get((r.filter, r.scenario))
        if d is None:
            continue
        rows.append(_run_row(r, d, t0))
        rows.extend(_window_row(r, d, i, t0) for i in range(len(r.windows)))
    return [{c: row.get(c) for c in COLUMNS} for row in rows]


def _column_rows(
    data: DatasetInputs, names: tuple[str, ...], key: str, prefix: str, stats: Any
) -> list[Row]:
    """A row per column of the onboard estimate that has finite values: its name without
    ``prefix`` under ``key``, the sample count, and ``stats(values)``."""
    if data.onboard is None:
        return []
    rows = []
    for name in names:
        v = column(data.onboard, name)
        v = v[np.isfinite(v)]
        if v.size:
            rows.append({key: name.removeprefix(prefix), "samples": int(v.size), **stats(v)})
    return rows


def test_ratio_rows(data: DatasetInputs) -> list[Row]:
    """The onboard EKF's innovation test ratios where the log has them (``ingest.schema``
    ``ESTIMATOR_TEST_RATIOS``): per measurement kind, the samples, mean, maximum and the
    fraction above 1 (the onboard EKF rejected the measurement there)."""
    return _column_rows(data, ESTIMATOR_TEST_RATIOS, "measurement", "test_ratio_", lambda v: {
        "mean": float(v.mean()),
        "max": float(v.max()),
        "above_1_frac": float(np.mean(v > 1.0)),
    })  # fmt: skip


def innovation_rows(data: DatasetInputs) -> list[Row]:
    """The onboard EKF's velocity and position innovations where the log has them
    (``ingest.schema.ESTIMATOR_INNOVATIONS``): per component, the samples, mean, standard
    deviation, RMS and largest magnitude. A mean far from zero against the deviation is a
    bias between the EKF's prediction and that measurement (a lever arm, a late fix, a
    height source drifting)."""
    return _column_rows(data, ESTIMATOR_INNOVATIONS, "component", "innov_", lambda v: {
        "mean": float(v.mean()),
        "std": float(v.std()),
        "rms": float(np.sqrt(np.mean(v * v))),
        "max_abs": float(np.abs(v).max()),
    })  # fmt: skip
