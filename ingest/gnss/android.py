"""Android raw GNSS measurements (``android.location.GnssMeasurement`` / ``GnssClock``) ->
GPS pseudoranges, following Google's "raw" convention (gps-measurement-tools,
``ProcessGnssMeas``; the EUSPA white paper "Using GNSS raw measurements on Android devices").

The receiver's estimate of GPS time at the measurement (ns since the GPS epoch) is

    t_rx = TimeNanos + TimeOffsetNanos - (FullBiasNanos + BiasNanos)

and a GPS satellite's ``ReceivedSvTimeNanos`` is its transmit time in ns of the GPS week, so

    pseudorange = c * ((t_rx mod week) - ReceivedSvTimeNanos)

(a week boundary between the two is unwrapped). The integer fields are combined in int64
and only the sub-nanosecond ``BiasNanos``/``TimeOffsetNanos`` in float, so nothing is lost to
the 2^53 limit of a double (``FullBiasNanos`` is about -1.3e18). ``FullBiasNanos`` is taken
per row (the phone's clock estimate at each epoch), so ``t_ns`` stays within the phone's
clock error of GPS time; when the phone re-estimates it, the pseudoranges and the epoch move
together (a receiver clock jump, counted).

Validity (rows failing are excluded and counted by reason, never silently): GPS only (other
constellations need orbit models this package does not have); ``FullBiasNanos`` present and
non-zero (no GPS time without it); ``State`` with code lock (bit 0) and the time of week
decoded or known (bits 3 or 14: ``ReceivedSvTimeNanos`` is a full time of week);
``ReceivedSvTimeUncertaintyNanos`` at most 500 ns; the L1 band (``CarrierFrequencyHz``
within 1 MHz of 1575.42 MHz, or absent as in logs before Android O); a pseudorange between
10,000 and 40,000 km (anything else is a wrong millisecond or week in the time of week).

``pseudorange_std_m`` is ``c * ReceivedSvTimeUncertaintyNanos``; the pseudorange rate is
``PseudorangeRateMetersPerSecond`` as reported (uncorrected: it carries the receiver and
satellite clock drifts, as ``gnss_obs`` wants), its sigma
``PseudorangeRateUncertaintyMetersPerSecond``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from navreplay.ingest.arrays import F64, I64, Bools
from navreplay.ingest.gnss.ephemeris import C_MPS, F_L1_HZ
from navreplay.ingest.gpstime import NS_PER_WEEK

STATE_CODE_LOCK = 1 << 0
STATE_TOW_DECODED = 1 << 3
STATE_TOW_KNOWN = 1 << 14
MAX_TOW_UNCERTAINTY_NS = 500.0
MIN_RANGE_M = 1.0e7  # GPS ranges are 20,000-26,000 km; the phone's clock error is small
MAX_RANGE_M = 4.0e7
CONSTELLATIONS = {
    0: "unknown",
    1: "GPS",
    2: "SBAS",
    3: "GLONASS",
    4: "QZSS",
    5: "BeiDou",
    6: "Galileo",
    7: "NavIC",
}


@dataclass(frozen=True)
class RawColumns:
    """The ``Raw`` fields used, one element per row (NaN / 0 where the log left them empty).

    Integer fields are int64; ``full_bias_present`` says where ``FullBiasNanos`` was given.
    """

    time_nanos: I64
    full_bias_nanos: I64
    full_bias_present: Bools
    bias_nanos: F64
    time_offset_nanos: F64
    received_sv_time_nanos: I64
    received_sv_time_unc_nanos: F64
    state: I64
    svid: I64
    constellation: I64
    carrier_hz: F64
    cn0_dbhz: F64
    prr_mps: F64
    prr_unc_mps: F64


@dataclass(frozen=True)
class Pseudoranges:
    """GPS rows that pass the checks, in input order.

    Attributes:
        rows: indices of those rows in the input.
        t_ns: epoch, GPS ``t_ns`` (``TimeNanos - FullBiasNanos - BiasNanos``, rounded to ns).
        prn, pseudorange_m, pseudorange_std_m: per row.
        excluded: rows excluded per reason (a row counts under its first failing check).
    """

    rows: I64
    t_ns: I64
    prn: I64
    pseudorange_m: F64
    pseudorange_std_m: F64
    excluded: dict[str, int]


def pseudoranges(raw: RawColumns) -> Pseudoranges:
    """GPS L1 pseudoranges of the valid rows (see the module docstring)."""
    n = raw.time_nanos.size
    ok = np.ones(n, dtype=bool)
    excluded: dict[str, int] = {}

    def drop(mask: Bools, reason: str) -> None:
        hit = ok & mask
        if hit.any():
            excluded[reason] = excluded.get(reason, 0) + int(hit.sum())
        ok[hit] = False

    for code, name in CONSTELLATIONS.items():
        if code != 1:
            drop(raw.constellation == code, f"constellation_{name}")
    drop(~np.isin(raw.constellation, list(CONSTELLATIONS)), "constellation_unknown")
    drop(~raw.full_bias_present | (raw.full_bias_nanos == 0), "no_full_bias")
    drop((raw.state & STATE_CODE_LOCK) == 0, "no_code_lock")
    drop((raw.state & (STATE_TOW_DECODED | STATE_TOW_KNOWN)) == 0, "tow_not_decoded")
    drop(~(raw.received_sv_time_unc_nanos <= MAX_TOW_UNCERTAINTY_NS), "tow_uncertain")
    off_l1 = np.isfinite(raw.carrier_hz) & (np.abs(raw.carrier_hz - F_L1_HZ) > 1e6)
    drop(off_l1, "not_l1")
    rows = np.flatnonzero(ok)
    pr, t_ns = _ranges(raw, rows)
    bad = ~((pr > MIN_RANGE_M) & (pr < MAX_RANGE_M))  # a wrong millisecond or week
    if bad.any():
        excluded["pseudorange_out_of_range"] = int(bad.sum())
        rows, pr, t_ns = rows[~bad], pr[~bad], t_ns[~bad]
    return Pseudoranges(
        rows,
        t_ns,
        raw.svid[rows],
        pr,
        raw.received_sv_time_unc_nanos[rows] * 1e-9 * C_MPS,
        excluded,
    )


def _ranges(raw: RawColumns, rows: I64) -> tuple[F64, I64]:
    """(pseudorange m, epoch t_ns) of ``rows``."""
    t_int = raw.time_nanos[rows] - raw.full_bias_nanos[rows]  # exact, int64
    frac = np.nan_to_num(raw.time_offset_nanos[rows]) - np.nan_to_num(raw.bias_nanos[rows])
    d_ns = (t_int % NS_PER_WEEK) - raw.received_sv_time_nanos[rows]
    d_ns = np.where(d_ns < -NS_PER_WEEK // 2, d_ns + NS_PER_WEEK, d_ns)  # week boundary
    pr = (d_ns.astype(np.float64) + frac) * 1e-9 * C_MPS
    t_ns = t_int - np.round(np.nan_to_num(raw.bias_nanos[rows])).astype(np.int64)
    return pr, t_ns
