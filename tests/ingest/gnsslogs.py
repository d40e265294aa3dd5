"""A GnssLogger v2 text log written from a synthesized drive (tests only).

There is no GnssLogger writer outside Android; this one follows the text format of the real
logs (``../shared/data``: header lines ``# Raw,utcTimeMillis,TimeNanos,...``) and inverts
the raw convention of ``ingest.gnss.android`` so that the synthesizer's pseudoranges come back to
float precision:

- ``TimeNanos`` is a hardware clock (``HW0_NS`` at the first epoch), ``BiasNanos`` = 0.25 and
  ``FullBiasNanos`` such that ``TimeNanos - FullBiasNanos - BiasNanos`` is the epoch less
  0.25 ns (rounding to the epoch);
- ``ReceivedSvTimeNanos`` is the whole nanoseconds of the transmit time of week and
  ``TimeOffsetNanos`` carries the fraction, so the pseudorange is exact;
- injected rows: per epoch one GLONASS row, one GPS row with only code lock (time of week
  not decoded) and one GPS L5 row; they must be excluded and counted.

Accel/Gyro rows are the synthesizer's IMU in phone axes (``phone = (y, x, -z)_FRD``), on an
``elapsedRealtimeNanos`` clock that starts ``BOOT_AGO_S`` before the drive.
"""

from __future__ import annotations

from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from navreplay.ingest.gnss.ephemeris import C_MPS
from navreplay.ingest.gpstime import NS_PER_WEEK, utc_unix_ns_from_gps

HW0_NS = 21_000_000_000_000
BIAS_NS = 0.25
BOOT_AGO_S = 3600
L1_HZ, L5_HZ = "1.57542003E9", "1.17645005E9"
RAW_COLUMNS = (
    "Raw,utcTimeMillis,TimeNanos,LeapSecond,TimeUncertaintyNanos,FullBiasNanos,BiasNanos,"
    "BiasUncertaintyNanos,DriftNanosPerSecond,DriftUncertaintyNanosPerSecond,"
    "HardwareClockDiscontinuityCount,Svid,TimeOffsetNanos,State,ReceivedSvTimeNanos,"
    "ReceivedSvTimeUncertaintyNanos,Cn0DbHz,PseudorangeRateMetersPerSecond,"
    "PseudorangeRateUncertaintyMetersPerSecond,AccumulatedDeltaRangeState,"
    "AccumulatedDeltaRangeMeters,AccumulatedDeltaRangeUncertaintyMeters,CarrierFrequencyHz,"
    "CarrierCycles,CarrierPhase,CarrierPhaseUncertainty,MultipathIndicator,SnrInDb,"
    "ConstellationType,AgcDb"
)
FIX_COLUMNS = (
    "Fix,Provider,LatitudeDegrees,LongitudeDegrees,AltitudeMeters,SpeedMps,AccuracyMeters,"
    "BearingDegrees,UnixTimeMillis,SpeedAccuracyMps,BearingAccuracyDegrees"
)


def _col(table: Any, name: str) -> np.ndarray:
    return np.asarray(table.column(name).to_numpy(zero_copy_only=False))


def _raw(
    utc_ms: int,
    hw: int,
    full_bias: int,
    svid: int,
    offset: float,
    state: int,
    rx_sv: int,
    unc: float,
    cn0: float,
    prr: float,
    prr_unc: float,
    carrier: str,
    cons: int,
) -> str:
    return (
        f"Raw,{utc_ms},{hw},,,{full_bias},{BIAS_NS!r},1.0,0.0,1.0,0,{svid},{offset!r},{state},"
        f"{rx_sv},{unc!r},{cn0!r},{prr!r},{prr_unc!r},0,0.0,0.0,{carrier},,,,0,,{cons},0.0\n"
    )


def write_gnsslogger(path: Path, synth: Any, *, imu: bool = True) -> dict[str, int]:
    """Write the log; returns the counts of rows written per kind."""
    obs, fix = synth.tables["gnss_obs"], synth.tables["gnss"]
    t = _col(obs, "t_ns").astype(np.int64)
    sv = [str(s) for s in obs.column("sv").to_pylist()]
    pr, cn0 = _col(obs, "pseudorange_m"), _col(obs, "cn0_dbhz")
    prr, pr_std = _col(obs, "pseudorange_rate_mps"), _col(obs, "pseudorange_std_m")
    prr_std = _col(obs, "pseudorange_rate_std_mps")
    t0 = int(t[0])
    lines = [
        "# \n",
        "# Header Description:\n",
        "# \n",
        "# Version: v2.0.4.2 Platform: 10 Manufacturer: navreplay Model: test\n",
        "# \n",
        f"# {RAW_COLUMNS}\n",
        "# \n",
        "# Accel,utcTimeMillis,elapsedRealtimeNanos,AccelXMps2,AccelYMps2,AccelZMps2\n",
        "# \n",
        "# Gyro,utcTimeMillis,elapsedRealtimeNanos,GyroXRadPerSec,GyroYRadPerSec,GyroZRadPerSec\n",
        "# \n",
        f"# {FIX_COLUMNS}\n",
        "# \n",
        "# Status,UnixTimeMillis,SignalCount,SignalIndex,ConstellationType,Svid\n",
        "# \n",
    ]
    counts = {"gps": 0, "glonass": 0, "tow_not_decoded": 0, "l5": 0, "fix": 0, "status": 0}
    body: list[tuple[int, int, str]] = []  # (t_ns on GPS, order, line)
    for k in range(t.size):
        hw = HW0_NS + int(t[k] - t0)
        full_bias = hw - int(t[k])  # TimeNanos - FullBiasNanos - BiasNanos = t - 0.25 ns
        utc_ms = int(utc_unix_ns_from_gps(int(t[k]))) // 1_000_000
        d_ns = pr[k] / C_MPS * 1e9
        whole = int(np.floor(d_ns))
        rx_sv = int(t[k] % NS_PER_WEEK) - whole
        offset = float(d_ns - whole + BIAS_NS)
        unc = float(pr_std[k] / C_MPS * 1e9)
        svid = int(sv[k][1:])
        raw = partial(_raw, utc_ms, hw, full_bias)  # the epoch's clock fields
        cn0_k, prr_k, prr_std_k = float(cn0[k]), float(prr[k]), float(prr_std[k])
        line = raw(svid, offset, 16399, rx_sv, unc, cn0_k, prr_k, prr_std_k, L1_HZ, 1)
        body.append((int(t[k]), 0, line))
        counts["gps"] += 1
        if k == t.size - 1 or t[k + 1] != t[k]:  # once per epoch, after its GPS rows
            glonass = raw(7, 0.0, 16399, rx_sv, 10.0, 30.0, 1.0, 0.1, "1.60256250E9", 3)
            no_tow = raw(30, 0.0, 1, 123, 10.0, 30.0, 1.0, 0.1, L1_HZ, 1)
            l5 = raw(svid, offset, 16399, rx_sv, unc, 40.0, 1.0, 0.1, L5_HZ, 1)
            body += [(int(t[k]), order, x) for order, x in enumerate([glonass, no_tow, l5], 1)]
            counts["glonass"] += 1
            counts["tow_not_decoded"] += 1
            counts["l5"] += 1
            body.append((int(t[k]), 4, f"Status,{utc_ms},1,0,1,{svid}\n"))
            counts["status"] += 1
    ft = _col(fix, "t_ns").astype(np.int64)
    for k in range(ft.size):
        utc_ms = int(utc_unix_ns_from_gps(int(ft[k]))) // 1_000_000
        lat, lon, alt = (float(_col(fix, c)[k]) for c in ("lat_deg", "lon_deg", "alt_m"))
        vn, ve = float(_col(fix, "vel_n_mps")[k]), float(_col(fix, "vel_e_mps")[k])
        speed, bearing = float(np.hypot(vn, ve)), float(np.degrees(np.arctan2(ve, vn)) % 360.0)
        acc = float(_col(fix, "h_acc_m")[k]) * 1.5096
        body.append(
            (
                int(ft[k]),
                5,
                f"Fix,GPS,{lat!r},{lon!r},{alt!r},{speed!r},{acc!r},{bearing!r},{utc_ms},0.1,1.0\n",
            )
        )
        body.append(
            (int(ft[k]), 6, f"Fix,FLP,{lat!r},{lon!r},{alt!r},0.0,5.0,0.0,{utc_ms},0.1,1.0\n")
        )
        counts["fix"] += 1
    if imu:
        table = synth.tables["imu"]
        ti = _col(table, "t_ns").astype(np.int64)
        boot = int(ti[0]) - BOOT_AGO_S * 10**9
        for kind, names in (("Accel", "acc_{}_mps2"), ("Gyro", "gyro_{}_radps")):
            x, y, z = (_col(table, names.format(a)).tolist() for a in "xyz")
            for k in range(ti.size):
                utc_ms = int(utc_unix_ns_from_gps(int(ti[k]))) // 1_000_000
                elapsed = int(ti[k]) - boot
                body.append(
                    (
                        int(ti[k]),
                        7 if kind == "Accel" else 8,
                        f"{kind},{utc_ms},{elapsed},{y[k]!r},{x[k]!r},{-z[k]!r}\n",
                    )
                )
        counts["imu"] = ti.size
    body.sort(key=lambda r: (r[0], r[1]))
    path.write_text("".join(lines) + "".join(line for _, _, line in body))
    return counts
