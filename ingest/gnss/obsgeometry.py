"""Satellite states of raw observations from the broadcast ephemeris, as ``gnss_obs`` columns.

Given pseudoranges stamped at receiver epochs (RINEX observations, Android raw measurements)
and GPS broadcast ephemerides (``ingest.gnss.ephemeris.Ephemeris``), ``observation_geometry``
fills the satellite columns of ``gnss_obs`` with the conventions of ``ingest.schema``:

- the satellite state at the transmit time of the signal, in the ECEF frame of the receive
  time (Sagnac), from ``ingest.gnss.ephemeris.transmit_state``: light-time iteration on the
  geometric range from the receiver;
- the epoch is the receiver's clock reading (RINEX 3.04 section 5.7; Android's
  ``TimeNanos - FullBiasNanos - BiasNanos``), so the signal arrived at ``t - dt_r`` in GPS
  time, ``dt_r`` being the receiver clock offset that the pseudoranges also carry; that
  instant is the one used (a receiver 1 ms off would otherwise put every satellite ~3 m
  along its track, ~0.8 m in range);
- ``sat_clock_m`` = c (clock offset with the relativistic term - TGD): the L1 C/A user's
  correction; ``sat_clock_drift_mps`` = c x its rate;
- elevation and azimuth at the receiver; ``iono_delay_m`` from the broadcast Klobuchar model
  when the navigation file carries its coefficients.

The receiver position and clock come from ``ingest.gnss.spp`` solved together with the satellite
states (each depends on the other; three or four rounds converge to well below a millimetre
in the satellite states). An epoch with fewer than four usable satellites borrows the
position of the nearest solved epoch and solves its clock alone; with no solved epoch at all,
the approximate position given (RINEX header, a fix) is used. A satellite position error
from a receiver position error ``d`` is about ``1.3e-5 d`` (the light time changes by
``d / c``), so metre-level receiver positions give sub-millimetre satellite states.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import pymap3d

from navreplay.ingest.arrays import F64, I64, Bools
from navreplay.ingest.gnss import spp
from navreplay.ingest.gnss.ephemeris import (
    C_MPS,
    Ephemeris,
    elevation_azimuth,
    select,
    transmit_state,
)
from navreplay.ingest.gpstime import NS_PER_S, NS_PER_WEEK

_ROUNDS = 8
_CONVERGED_M = 1e-5

Klobuchar = tuple[tuple[float, float, float, float], tuple[float, float, float, float]]


class Geometry(NamedTuple):
    """Result of ``observation_geometry``.

    Attributes:
        keep: rows that got a satellite state (an ephemeris and a receiver position), (n,).
        columns: ``gnss_obs`` columns for the kept rows (satellite state, clocks, elevation,
            azimuth, and ``iono_delay_m`` when Klobuchar coefficients were given).
        epoch_t_ns: the epochs of the kept rows, (E,).
        receiver: per-epoch receiver solution (``ingest.gnss.spp.EpochFix``).
        counters: rows dropped per reason (``no_ephemeris``, ``no_receiver_position``) and
            epochs solved / borrowed.
    """

    keep: Bools
    columns: dict[str, F64]
    epoch_t_ns: I64
    receiver: spp.EpochFix
    counters: dict[str, int]


def observation_geometry(
    eph: Ephemeris,
    t_ns: I64,
    prn: I64,
    pseudorange_m: F64,
    *,
    approx_ecef_m: F64 | None = None,
    klobuchar: Klobuchar | None = None,
) -> Geometry:
    """Satellite states for GPS observations sorted by ``t_ns`` (see the module docstring).

    Args:
        eph: GPS broadcast ephemerides.
        t_ns: receiver epoch of each row, GPS time base, sorted, shape (n,).
        prn: GPS PRN of each row, shape (n,).
        pseudorange_m: measured pseudoranges, m, shape (n,).
        approx_ecef_m: approximate receiver position, used to start and when no epoch can
            be solved; None for the earth's centre.
        klobuchar: broadcast (alpha, beta) ionospheric coefficients, or None.
    """
    t_all = np.asarray(t_ns, dtype=np.int64)
    idx_all = select(eph, prn, t_all) if len(eph) else np.full(t_all.shape, -1, np.int64)
    keep = (idx_all >= 0) & np.isfinite(pseudorange_m)
    counters = {"no_ephemeris": int(np.count_nonzero(idx_all < 0))}
    rows = np.flatnonzero(keep)
    t, idx, pr = t_all[rows], idx_all[rows], np.asarray(pseudorange_m, np.float64)[rows]
    epoch, starts = spp.epoch_index(t)
    n_ep = starts.size
    approx = _approx(approx_ecef_m)
    x = np.zeros((n_ep, 4))
    if approx is not None:
        x[:, :3] = approx
    iono = np.zeros(t.size)
    fix = spp.EpochFix(x[:, :3], x[:, 3], np.zeros(n_ep, bool), np.full(n_ep, np.nan), keep[rows])
    for _ in range(_ROUNDS):
        st = transmit_state(eph, idx, t, x[epoch, :3], rx_offset_s=-x[epoch, 3] / C_MPS)
        sat_clock_m = C_MPS * (st.sat.clock_s - st.sat.tgd_s)
        pr_corr = pr + sat_clock_m - iono
        fix = spp.solve(st.sat.pos_m, pr_corr, epoch, n_ep, x0=x)
        new = _complete(fix, x, st.sat.pos_m, pr_corr, epoch, t[starts], approx)
        if klobuchar is not None:
            placed = np.isfinite(new[epoch, :3]).all(axis=1)
            iono = np.zeros(t.size)
            iono[placed] = _iono(klobuchar, new[epoch[placed], :3], st.sat.pos_m[placed], t[placed])
        step = np.nan_to_num(np.abs(new - x), nan=np.inf).max(initial=0.0)
        x = new
        if step < _CONVERGED_M:
            break
    located: Bools = np.asarray(np.isfinite(x).all(axis=1), dtype=bool)
    counters["no_receiver_position"] = int(np.count_nonzero(~located[epoch]))
    counters["epochs_solved"] = int(np.count_nonzero(fix.solved))
    counters["epochs_position_borrowed"] = int(np.count_nonzero(located & ~fix.solved))
    rx, clock = np.nan_to_num(x[epoch, :3]), np.nan_to_num(x[epoch, 3])
    st = transmit_state(eph, idx, t, rx, rx_offset_s=-clock / C_MPS)
    good = located[epoch]
    keep[rows[~good]] = False
    sel = np.flatnonzero(good)
    el, az = elevation_azimuth(x[epoch[sel], :3], st.sat.pos_m[sel])
    columns: dict[str, F64] = {
        "sat_x_m": st.sat.pos_m[sel, 0],
        "sat_y_m": st.sat.pos_m[sel, 1],
        "sat_z_m": st.sat.pos_m[sel, 2],
        "sat_vx_mps": st.sat.vel_mps[sel, 0],
        "sat_vy_mps": st.sat.vel_mps[sel, 1],
        "sat_vz_mps": st.sat.vel_mps[sel, 2],
        "sat_clock_m": C_MPS * (st.sat.clock_s[sel] - st.sat.tgd_s[sel]),
        "sat_clock_drift_mps": C_MPS * st.sat.clock_drift_sps[sel],
        "elevation_deg": np.degrees(el),
        "azimuth_deg": np.degrees(az),
    }
    if klobuchar is not None:
        columns["iono_delay_m"] = iono[sel]
    return Geometry(keep, columns, t[starts], fix, counters)


def _approx(approx_ecef_m: F64 | None) -> F64 | None:
    if approx_ecef_m is None:
        return None
    a = np.asarray(approx_ecef_m, dtype=np.float64).reshape(3)
    # RINEX writes 0 0 0 for an unknown position; anything inside the earth is no help.
    return a if np.isfinite(a).all() and np.linalg.norm(a) > 6.0e6 else None


def _complete(
    fix: spp.EpochFix,
    x: F64,
    sat_m: F64,
    pr_corr: F64,
    epoch: I64,
    epoch_t: I64,
    approx: F64 | None,
) -> F64:
    """[position, clock] per epoch: the solution, else the nearest solved epoch's position
    (or ``approx``) with the clock solved alone from the epoch's rows."""
    out = np.full(x.shape, np.nan)
    out[fix.solved, :3] = fix.ecef_m[fix.solved]
    out[fix.solved, 3] = fix.clock_m[fix.solved]
    missing = np.flatnonzero(~fix.solved)
    if not missing.size:
        return out
    solved = np.flatnonzero(fix.solved)
    if solved.size:
        st = epoch_t[solved]
        k = np.clip(np.searchsorted(st, epoch_t[missing]), 1, max(solved.size - 1, 1))
        lo = np.clip(k - 1, 0, solved.size - 1)
        hi = np.clip(k, 0, solved.size - 1)
        near = np.where(
            np.abs(st[lo] - epoch_t[missing]) <= np.abs(st[hi] - epoch_t[missing]), lo, hi
        )
        out[missing, :3] = fix.ecef_m[solved[near]]
    elif approx is not None:
        out[missing, :3] = approx
    rows_missing = np.isin(epoch, missing)
    rng = np.linalg.norm(sat_m - out[epoch, :3], axis=1)
    resid = np.where(rows_missing, pr_corr - rng, np.nan)
    for e in missing.tolist():
        r = resid[epoch == e]
        r = r[np.isfinite(r)]
        if r.size:
            out[e, 3] = float(np.median(r))
    out[~np.isfinite(out[:, :3]).all(axis=1)] = np.nan
    return out


def _iono(klobuchar: Klobuchar, rx_m: F64, sat_m: F64, t_ns: I64) -> F64:
    lat, lon, _ = pymap3d.ecef2geodetic(rx_m[:, 0], rx_m[:, 1], rx_m[:, 2], deg=False)
    el, az = elevation_azimuth(rx_m, sat_m)
    tow = (t_ns % NS_PER_WEEK) / NS_PER_S
    alpha, beta = klobuchar
    return spp.klobuchar_delay_m(lat, lon, el, az, tow, alpha, beta)
