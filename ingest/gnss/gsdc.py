"""Google Smartphone Decimeter Challenge (GSDC) measurement CSVs -> ``gnss_obs`` columns.

The GSDC ``*_derived.csv`` (2021) and ``device_gnss.csv`` (2022) files carry, per signal,
the raw pseudorange and the satellite state and corrections Google computed for it, so no
ephemeris is needed. Mapping (2021 name / 2022 name -> ``gnss_obs``):

- ``rawPrM`` / ``RawPseudorangeMeters`` - ``isrbM`` / ``IsrbMeters`` -> ``pseudorange_m``:
  the inter-signal range bias (a receiver bias of each non-GPS-L1 signal relative to GPS L1)
  is removed, so every pseudorange is on the GPS L1 clock the filters estimate; the ISRB is
  kept in the extra column ``isrb_m``. Google's corrected pseudorange ``raw + satClkBias -
  isrb - iono - tropo`` is then the ``gnss_obs`` one, ``pseudorange_m + sat_clock_m -
  iono_delay_m - tropo_delay_m``;
- ``satClkBiasM`` / ``SvClockBiasMeters`` -> ``sat_clock_m``; ``satClkDriftMps`` /
  ``SvClockDriftMetersPerSecond`` -> ``sat_clock_drift_mps``; ``ionoDelayM`` /
  ``IonosphericDelayMeters`` -> ``iono_delay_m``; ``tropoDelayM`` / ``TroposphericDelayMeters``
  -> ``tropo_delay_m``; ``rawPrUncM`` / ``RawPseudorangeUncertaintyMeters`` ->
  ``pseudorange_std_m``; 2022 only: ``PseudorangeRateMetersPerSecond``, ``Cn0DbHz``,
  ``SvElevationDegrees``, ``SvAzimuthDegrees`` (2021 has no rate nor C/N0: null);
- the satellite position and velocity are given "in an ECEF frame at the time of
  transmission" (GSDC data description): they are rotated into the receive-time frame of
  ``gnss_obs`` by ``w_e * |s - r| / c`` (``ingest.gnss.ephemeris.rotate_earth``), ``r`` being the
  receiver position (2022: ``WlsPosition*EcefMeters``; 2021: solved here, ``ingest.gnss.spp``).
  Without it a position solved from the table is off by tens of metres.

Satellite ids: Android ``ConstellationType`` + ``Svid`` -> RINEX style (``G05``, ``R12``,
``E11``, ``C20``, QZSS ``J01`` from Svid 193, SBAS ``S20`` from 120). One signal per satellite
and epoch (the table's key): the L1-band one (GPS L1, GLONASS G1, Galileo E1, BeiDou B1I,
QZSS J1); L5/E5a/B2a rows are excluded and counted per signal type.

Time: 2022 epochs are ``TimeNanos - FullBiasNanos - BiasNanos`` (Google's raw convention,
as for GnssLogger logs). The 2021 ``millisSinceGpsEpoch`` of the derived files is one epoch
late (competition hosts' note, applied by gnss_lib_py as "map each derived timestamp to the
previous one"); here each epoch is re-stamped from its own measurements: the reception time
they imply, ``receivedSvTimeInGpsNanos + rawPrM / c``, is compared with the stamp and the
stamp moved back by that difference rounded to whole seconds (the phones log at 1 Hz). This
also works for excerpts that skip epochs, where "the previous stamp" does not.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from navreplay.ingest.arrays import F64, I64, Bools
from navreplay.ingest.gnss import spp
from navreplay.ingest.gnss.ephemeris import C_MPS, elevation_azimuth, rotate_earth
from navreplay.ingest.gpstime import NS_PER_S

PRIMARY_SIGNALS = ("GPS_L1", "GLO_G1", "GAL_E1", "BDS_B1I", "QZS_J1", "BDS_B1C")
_LETTER = {1: "G", 2: "S", 3: "R", 4: "J", 5: "C", 6: "E", 7: "I"}
_OFFSET = {2: 100, 4: 192}
MIN_RANGE_M, MAX_RANGE_M = 1.0e7, 4.5e7


def sv_ids(constellation: I64, svid: I64) -> npt.NDArray[np.str_]:
    """RINEX-style satellite ids from Android constellation type and svid (``?`` unknown)."""
    out = [
        f"{_LETTER.get(int(c), '?')}{int(s) - _OFFSET.get(int(c), 0):02d}"
        for c, s in zip(constellation, svid, strict=True)
    ]
    return np.asarray(out, dtype=str)


@dataclass(frozen=True)
class Signals:
    """GSDC rows as arrays, one per CSV row (before selection)."""

    t_ns: I64
    sv: npt.NDArray[np.str_]
    signal: npt.NDArray[np.str_]
    raw_pr_m: F64
    raw_pr_std_m: F64
    isrb_m: F64
    sat_pos_m: F64  # (n, 3), ECEF at transmit time
    sat_vel_mps: F64
    sat_clock_m: F64
    sat_clock_drift_mps: F64
    iono_m: F64
    tropo_m: F64
    prr_mps: F64 | None = None
    prr_std_mps: F64 | None = None
    cn0_dbhz: F64 | None = None
    rx_ecef_m: F64 | None = None  # (n, 3): the file's receiver position, if any


def select(sig: Signals) -> tuple[I64, dict[str, int]]:
    """Rows kept (sorted by (t, sv)) and rows excluded per reason."""
    excluded: dict[str, int] = {}
    ok = np.ones(sig.t_ns.size, dtype=bool)

    def drop(mask: npt.ArrayLike, reason: str) -> None:
        hit = ok & np.asarray(mask, dtype=bool)
        if hit.any():
            excluded[reason] = excluded.get(reason, 0) + int(hit.sum())
        ok[hit] = False

    drop(~np.isfinite(sig.sat_pos_m).all(axis=1), "no_satellite_state")
    for name in np.unique(sig.signal[~np.isin(sig.signal, PRIMARY_SIGNALS)]):
        drop(sig.signal == name, f"signal_{name or 'unknown'}")
    drop(np.char.startswith(sig.sv, "?"), "constellation_unknown")
    corr = sig.raw_pr_m - sig.isrb_m
    drop(~((corr > MIN_RANGE_M) & (corr < MAX_RANGE_M)), "pseudorange_out_of_range")
    rows = np.flatnonzero(ok)
    rows = rows[np.lexsort((sig.sv[rows], sig.t_ns[rows]))]
    if rows.size > 1:  # two L1-band signals of one satellite (B1I and B1C): keep the first
        dup = (sig.t_ns[rows][1:] == sig.t_ns[rows][:-1]) & (sig.sv[rows][1:] == sig.sv[rows][:-1])
        if dup.any():
            excluded["second_signal_of_satellite"] = int(dup.sum())
            rows = rows[np.concatenate(([True], ~dup))]
    return rows, excluded


def restamp_2021(millis: I64, received_sv_ns: F64, raw_pr_m: F64) -> tuple[I64, I64]:
    """(epoch ``t_ns``, shift applied in whole seconds) per row of a 2021 derived file."""
    stamp = millis * 1_000_000
    arrival = received_sv_ns + raw_pr_m / C_MPS * NS_PER_S
    shift = np.zeros(millis.size, dtype=np.int64)
    for t in np.unique(stamp):
        rows = np.flatnonzero(stamp == t)
        late = np.nanmedian(t - arrival[rows])
        if np.isfinite(late):
            shift[rows] = round(late / NS_PER_S)
    return stamp - shift * NS_PER_S, shift


def columns(sig: Signals, rows: I64) -> tuple[dict[str, np.ndarray], dict[str, Bools], int]:
    """``gnss_obs`` columns of ``rows`` (sorted by time), their null masks, and the number
    of epochs whose receiver position had to be solved here."""
    t = sig.t_ns[rows]
    pos, vel = sig.sat_pos_m[rows], sig.sat_vel_mps[rows]
    epoch, starts = spp.epoch_index(t)
    solved = 0
    if sig.rx_ecef_m is not None and np.isfinite(sig.rx_ecef_m[rows]).all():
        rx = sig.rx_ecef_m[rows]
    else:
        rx, solved = _solve_receiver(sig, rows, epoch, starts.size)
    tau = np.linalg.norm(pos - rx, axis=1) / C_MPS
    # without a receiver position, the light time of the corrected pseudorange (which also
    # holds the phone's small clock error)
    fallback = (sig.raw_pr_m[rows] - sig.isrb_m[rows] + sig.sat_clock_m[rows]) / C_MPS
    tau = np.where(np.isfinite(tau), tau, fallback)
    pos_r, vel_r = rotate_earth(pos, tau), rotate_earth(vel, tau)
    n = rows.size
    out: dict[str, np.ndarray] = {
        "t_ns": t,
        "sv": sig.sv[rows],
        "pseudorange_m": sig.raw_pr_m[rows] - sig.isrb_m[rows],
        "pseudorange_rate_mps": _or_nan(sig.prr_mps, rows),
        "cn0_dbhz": _or_nan(sig.cn0_dbhz, rows),
        "sat_x_m": pos_r[:, 0],
        "sat_y_m": pos_r[:, 1],
        "sat_z_m": pos_r[:, 2],
        "sat_vx_mps": vel_r[:, 0],
        "sat_vy_mps": vel_r[:, 1],
        "sat_vz_mps": vel_r[:, 2],
        "sat_clock_m": sig.sat_clock_m[rows],
        "sat_clock_drift_mps": sig.sat_clock_drift_mps[rows],
        "pseudorange_std_m": sig.raw_pr_std_m[rows],
        "pseudorange_rate_std_mps": _or_nan(sig.prr_std_mps, rows),
        "iono_delay_m": sig.iono_m[rows],
        "tropo_delay_m": sig.tropo_m[rows],
        "isrb_m": sig.isrb_m[rows],
    }
    el, az = elevation_azimuth(rx, pos_r)
    out["elevation_deg"], out["azimuth_deg"] = np.degrees(el), np.degrees(az)
    nulls = {
        "pseudorange_rate_mps": np.full(n, sig.prr_mps is None),
        "cn0_dbhz": np.full(n, sig.cn0_dbhz is None),
        "pseudorange_rate_std_mps": np.full(n, sig.prr_std_mps is None),
    }
    return out, nulls, solved


def _or_nan(values: F64 | None, rows: I64) -> F64:
    return np.full(rows.size, np.nan) if values is None else values[rows]


def _solve_receiver(sig: Signals, rows: I64, epoch: I64, n_ep: int) -> tuple[F64, int]:
    """Receiver position per row: solved with the satellites as given, then again after
    rotating them with that first position (the rotation moves them by ~30 m)."""
    corr = (
        sig.raw_pr_m[rows] - sig.isrb_m[rows] + sig.sat_clock_m[rows] - sig.iono_m[rows]
    ) - sig.tropo_m[rows]
    pos = sig.sat_pos_m[rows]
    fix = spp.solve(pos, corr, epoch, n_ep)
    for _ in range(2):
        x0 = np.column_stack([np.nan_to_num(fix.ecef_m), np.nan_to_num(fix.clock_m)])
        rx = x0[epoch, :3]
        tau = np.linalg.norm(pos - rx, axis=1) / C_MPS
        fix = spp.solve(rotate_earth(pos, tau), corr, epoch, n_ep, x0=x0)
    good = np.flatnonzero(fix.solved)
    if not good.size:  # nothing solvable: no receiver position (NaN)
        return np.full(pos.shape, np.nan), 0
    # an epoch with < 4 satellites takes the nearest solved epoch's place
    near = good[np.abs(good[None, :] - np.arange(n_ep)[:, None]).argmin(axis=1)]
    return fix.ecef_m[near][epoch], int(good.size)
