"""The measurements of the robustness sweep (``robustness_sweep``), on one run's arrays.

- ``fix_reference``, ``spp_reference``: the horizontal error of the raw fixes (loose
  coupling's reference) and of epoch-by-epoch single-point positioning on the filters' own
  observables (``ingest.gnss.spp`` on ``inputs.prepare_obs``: the same corrections, elevation
  mask and pseudorange sigmas as weights; tight coupling's reference), both against the
  truth's antenna position (the IMU's plus the lever arm rotated by the true attitude);
- ``run_errors``: a run's horizontal error and 1-sigma at its output epochs
  (``ins.truth.error_states``);
- ``recovery``: after a window without GNSS, the first returning epoch (1 = the first one
  back) at which the run's innovation log has an accepted block of the stream, and whether the
  stream was reset (a ``gate_reset`` event) before it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pyarrow as pa
from scipy.spatial.transform import Rotation

from navreplay.ingest.gnss import spp
from navreplay.pipeline.estimation.core.tables import Event, truth_at
from navreplay.pipeline.estimation.core.windows import ned_error
from navreplay.pipeline.estimation.ins.config import GnssNoiseParams
from navreplay.pipeline.estimation.ins.inputs import prepare_obs
from navreplay.pipeline.estimation.ins.models import measurement as me
from navreplay.pipeline.estimation.ins.replay import RunResult
from navreplay.pipeline.estimation.ins.truth import error_states
from navreplay.pipeline.nav import earth
from navreplay.pipeline.nav.earth import F64, I64


@dataclass(frozen=True)
class Track:
    """Horizontal errors by time: ``t_ns`` (K,), ``err_h_m`` (K,) and, for a filter run, its
    horizontal 1-sigma ``sigma_h_m`` (K,) (``sqrt(P_nn + P_ee)``; NaN for a reference)."""

    t_ns: I64
    err_h_m: F64
    sigma_h_m: F64

    def rms_between(self, t0_ns: int, t1_ns: int) -> float:
        """Horizontal RMS over the epochs in ``[t0_ns, t1_ns]`` (NaN without any)."""
        sel = (self.t_ns >= t0_ns) & (self.t_ns <= t1_ns) & np.isfinite(self.err_h_m)
        return float(np.sqrt(np.mean(self.err_h_m[sel] ** 2))) if sel.any() else float("nan")

    def max_sigma_ratio(self, t0_ns: int, t1_ns: int) -> float:
        """Largest ``err_h / (3 sigma_h)`` in ``[t0_ns, t1_ns)`` (NaN without epochs)."""
        sel = (self.t_ns >= t0_ns) & (self.t_ns < t1_ns)
        if not sel.any():
            return float("nan")
        with np.errstate(divide="ignore", invalid="ignore"):
            r = self.err_h_m[sel] / (3.0 * self.sigma_h_m[sel])
        return float(np.nanmax(np.where(np.isnan(r), np.inf, r)))


def antenna_errors(
    truth: pa.Table, t_ns: I64, lat_rad: F64, lon_rad: F64, h_m: F64, lever_b: Sequence[float]
) -> Track:
    """Horizontal distance of antenna positions from the truth's antenna at ``t_ns`` (epochs
    outside the truth's span, or without a position, are left out)."""
    ok = np.isfinite(lat_rad) & np.isfinite(lon_rad) & np.isfinite(h_m)
    inside, tr = truth_at(truth, t_ns[ok])
    t = t_ns[ok][inside]
    lat, lon, h = lat_rad[ok][inside], lon_rad[ok][inside], h_m[ok][inside]
    att = Rotation.from_euler(
        "ZYX", np.column_stack([tr["yaw_rad"], tr["pitch_rad"], tr["roll_rad"]])
    )
    lever_n = att.apply(np.asarray(lever_b, dtype=np.float64))
    t_lat, t_lon = np.radians(tr["lat_deg"]), np.radians(tr["lon_deg"])
    err = ned_error(t_lat, t_lon, tr["alt_m"], lat, lon, h) - lever_n
    return Track(t, np.hypot(err[:, 0], err[:, 1]), np.full(t.size, np.nan))


def fix_reference(gnss: pa.Table, truth: pa.Table, lever_b: Sequence[float]) -> Track:
    """The raw fixes' horizontal errors (the fixes are antenna positions)."""
    t = np.asarray(gnss.column("t_ns").to_numpy(), dtype=np.int64)
    lat, lon, h = (
        np.asarray(gnss.column(c).to_numpy(zero_copy_only=False), dtype=np.float64)
        for c in ("lat_deg", "lon_deg", "alt_m")
    )
    return antenna_errors(truth, t, np.radians(lat), np.radians(lon), h, lever_b)


def spp_reference(
    obs_table: pa.Table, gnss: GnssNoiseParams, truth: pa.Table, lever_b: Sequence[float]
) -> Track:
    """Epoch-by-epoch SPP from the tight filters' own observables (``prepare_obs`` with
    their ``gnss`` section), weighted by the inverse pseudorange variances, against the
    truth."""
    od = prepare_obs(obs_table, gnss)
    n_ep = od.epoch_t_ns.size
    epoch = np.repeat(np.arange(n_ep), np.diff(od.start))
    ok = od.obs[:, me.OB_PR_OK] > 0
    fix = spp.solve(
        np.ascontiguousarray(od.obs[ok, me.OB_SAT : me.OB_SAT + 3]),
        np.ascontiguousarray(od.obs[ok, me.OB_PR]),
        epoch[ok],
        n_ep,
        weight=1.0 / od.obs[ok, me.OB_SIG_PR] ** 2,
    )
    geo = np.full((n_ep, 3), np.nan)
    for e in np.flatnonzero(fix.solved):
        geo[e] = earth.ecef_to_geodetic(*(float(v) for v in fix.ecef_m[e]))
    return antenna_errors(truth, od.epoch_t_ns, geo[:, 0], geo[:, 1], geo[:, 2], lever_b)


def run_errors(result: RunResult, truth: pa.Table) -> Track:
    """A run's horizontal error (IMU position against the truth's) and 1-sigma at its output
    epochs."""
    inside, err, _ = error_states(result, truth)
    P = result.P[inside]
    return Track(
        result.t_ns[inside],
        np.hypot(err[:, 0], err[:, 1]),
        np.sqrt(np.clip(P[:, 0, 0] + P[:, 1, 1], 0.0, None)),
    )


@dataclass(frozen=True)
class Recovery:
    """How a stream came back after a window: ``epochs`` is the first returning epoch with an
    accepted block (1 = the first epoch back; None: none before the next window or the end),
    ``reset`` whether the stream was reset on the way, ``returned`` the epochs back."""

    epochs: int | None
    reset: bool
    returned: int


def recovery(
    inn_i: I64,
    events: Sequence[Event],
    epochs_t_ns: I64,
    stream: int,
    end_ns: int,
    until_ns: int,
) -> Recovery:
    """The recovery of ``stream`` (a ``models.measurement`` stream code) after a window
    ending at ``end_ns``, from a run's innovation rows (``RunResult.inn_i``: t_ns, stream,
    sv, dim, accepted) and events, over the input's epochs ``epochs_t_ns`` in
    ``[end_ns, until_ns)`` (the next window's start, or past the end)."""
    back = np.unique(epochs_t_ns[(epochs_t_ns >= end_ns) & (epochs_t_ns < until_ns)])
    rows = (inn_i[:, 1] == stream) & (inn_i[:, 4] == 1)
    accepted = np.isin(back, inn_i[rows, 0])
    first = int(np.argmax(accepted)) if accepted.any() else None
    last_ns = int(back[first]) if first is not None else until_ns
    name = me.STREAM_NAMES[stream]
    reset = any(
        e.kind == "gate_reset" and e.stream == name and end_ns <= e.t_ns <= last_ns for e in events
    )
    return Recovery(None if first is None else first + 1, reset, int(back.size))
