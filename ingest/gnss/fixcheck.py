"""Cross-stream check of a merged dataset: do the receiver's fixes and the raw observations
tell the same story at the same times? (catalogue case 36)

Files of one drive are put on one time base by ``ingest.timebase.reconcile``, but nothing in
the files proves that their clocks were what they claim: a ROS bag stamped in GPS time while
declaring UTC, or a RINEX file written in UTC, is off by the leap seconds (18 s) and merges
without complaint. This check solves a position per observation epoch from ``gnss_obs``
(``ingest.gnss.spp``, the table's own satellite states and corrections, plus a standard
troposphere) and compares it with the ``gnss`` fixes interpolated at the epoch shifted by a
lag L (median horizontal distance), for every L in +-``max_lag_s`` in steps of the fix
interval. With the receiver moving,
a wrong lag costs the distance driven in it; the best lag is reported and, when it is not 0
and fits clearly better than 0, flagged as a time offset between the two streams. A
receiver that stays within ``min_motion_m`` cannot tell lags apart: the check then only
compares places and says it is inconclusive about time.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pyarrow as pa
import pymap3d

from navreplay.ingest.arrays import F64, I64
from navreplay.ingest.gnss import spp

MAX_LAG_S = 60.0
MIN_MOTION_M = 50.0
_MIN_EPOCHS = 10
_MAX_RMS_M = 30.0
_CLEAR_FACTOR = 3.0
_CLEAR_MARGIN_M = 20.0


@dataclass(frozen=True)
class GnssCheck:
    """Outcome of ``check``.

    Attributes:
        status: ``consistent``, ``offset`` (a time offset found), ``positions_disagree``
            (static receiver, places far apart), ``inconclusive`` (too few epochs or no
            motion to tell lags apart).
        lag_s: the best lag (fix time minus observation time at the same place), s.
        median_m_at_lag, median_m_at_zero: median horizontal distance fix - solved position,
            m (horizontal because a standard troposphere leaves metres in the vertical).
        epochs: observation epochs compared; motion_m: extent of the fix track, m.
    """

    status: str
    lag_s: float | None
    median_m_at_lag: float | None
    median_m_at_zero: float | None
    epochs: int
    motion_m: float

    def to_json(self) -> dict[str, Any]:
        return dict(self.__dict__)

    def message(self, obs: str, fix: str) -> str:
        if self.status == "offset":
            assert self.lag_s is not None
            leap = " (the GPS - UTC leap seconds: one stream is on the wrong time base)"
            hint = leap if 17.0 <= abs(self.lag_s) <= 19.0 else ""
            return (
                f"the fixes ({fix}) and gnss_obs ({obs}) are offset in time by "
                f"{self.lag_s:+.2f} s: "
                f"positions solved from the observations match the fixes "
                f"{self.lag_s:+.2f} s later (median {self.median_m_at_lag:.1f} m) and not at "
                f"the same time (median {self.median_m_at_zero:.1f} m){hint}"
            )
        if self.status == "positions_disagree":
            return (
                f"the fixes ({fix}) and gnss_obs ({obs}) disagree on the place: median distance "
                f"{self.median_m_at_zero:.0f} m between fixes and solved positions"
            )
        return f"gnss and gnss_obs: {self.status}"


def solved_positions(obs: pa.Table) -> tuple[I64, F64]:
    """(epoch times, ECEF positions) solved from a ``gnss_obs`` table; unsolved epochs and
    epochs with a post-fit RMS above 30 m are left out."""
    t = obs.column("t_ns").to_numpy()
    sat = np.stack([_f(obs, f"sat_{a}_m") for a in "xyz"], axis=1)
    corr = _f(obs, "pseudorange_m") + _f(obs, "sat_clock_m", 0.0)
    corr -= _f(obs, "iono_delay_m", 0.0)
    if "tropo_delay_m" in obs.column_names:
        corr -= _f(obs, "tropo_delay_m", 0.0)
    else:
        corr -= spp.tropo_delay_m(np.radians(_f(obs, "elevation_deg", 90.0)), np.zeros(t.size))
    epoch, starts = spp.epoch_index(t)
    fix = spp.solve(sat, corr, epoch, starts.size)
    good = fix.solved & (fix.rms_m < _MAX_RMS_M)
    return t[starts][good], fix.ecef_m[good]


def check(obs: pa.Table, fixes: pa.Table, *, max_lag_s: float = MAX_LAG_S) -> GnssCheck:
    """Compare ``gnss_obs`` with ``gnss`` (both on the dataset's time base)."""
    t_obs, pos = solved_positions(obs)
    t_fix = fixes.column("t_ns").to_numpy()
    lat, lon, alt = (_f(fixes, c) for c in ("lat_deg", "lon_deg", "alt_m"))
    ok = np.isfinite(lat) & np.isfinite(lon) & np.isfinite(alt)
    t_fix = t_fix[ok]
    xyz = np.stack(pymap3d.geodetic2ecef(lat[ok], lon[ok], alt[ok]), axis=1)
    if t_obs.size < _MIN_EPOCHS or t_fix.size < 2:
        return GnssCheck("inconclusive", None, None, None, int(t_obs.size), 0.0)
    motion = float(np.max(np.linalg.norm(xyz - xyz[0], axis=1)))
    step_s = max(float(np.median(np.diff(t_fix))) * 1e-9, 0.05)
    lags = np.arange(-np.floor(max_lag_s / step_s), np.floor(max_lag_s / step_s) + 1) * step_s
    up = xyz[0] / np.linalg.norm(xyz[0])  # near enough to the local vertical for this
    medians = np.array([_median_distance(t_obs, pos, t_fix, xyz, up, lag) for lag in lags])
    zero = float(medians[np.argmin(np.abs(lags))])
    n_zero = _matched(t_obs, t_fix, 0.0)
    if n_zero < _MIN_EPOCHS:
        return GnssCheck("inconclusive", None, None, None, n_zero, motion)
    if motion < MIN_MOTION_M:
        status = "positions_disagree" if zero > 100.0 else "inconclusive"
        return GnssCheck(status, None, None, zero, n_zero, motion)
    best = int(np.nanargmin(medians))
    lag, at_lag = float(lags[best]), float(medians[best])
    clear = zero > max(_CLEAR_FACTOR * at_lag, at_lag + _CLEAR_MARGIN_M)
    status = "offset" if lag != 0.0 and clear else "consistent"
    return GnssCheck(status, lag, at_lag, zero, n_zero, motion)


def _matched(t_obs: I64, t_fix: I64, lag_s: float) -> int:
    q = t_obs + round(lag_s * 1e9)
    return int(np.count_nonzero((q >= t_fix[0]) & (q <= t_fix[-1])))


def _median_distance(t_obs: I64, pos: F64, t_fix: I64, xyz: F64, up: F64, lag_s: float) -> float:
    """Median horizontal distance between the fixes at ``t + lag`` and the positions."""
    q = t_obs + round(lag_s * 1e9)
    inside = (q >= t_fix[0]) & (q <= t_fix[-1])
    if np.count_nonzero(inside) < _MIN_EPOCHS:
        return float("nan")
    tq = (q[inside] - t_fix[0]).astype(np.float64)
    tf = (t_fix - t_fix[0]).astype(np.float64)
    at = np.stack([np.interp(tq, tf, xyz[:, k]) for k in range(3)], axis=1)
    d = at - pos[inside]
    d -= (d @ up)[:, None] * up  # horizontal: the vertical carries the troposphere's error
    return float(np.median(np.linalg.norm(d, axis=1)))


def _f(table: pa.Table, name: str, fill: float = np.nan) -> F64:
    if name not in table.column_names:
        return np.full(table.num_rows, fill)
    col = table.column(name)
    values = np.asarray(col.to_numpy(zero_copy_only=False), dtype=np.float64)
    if col.null_count:
        values = np.where(np.asarray(col.is_null().to_numpy(zero_copy_only=False)), fill, values)
    return values
