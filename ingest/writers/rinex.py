"""RINEX 3.04 writers: GPS observation files from ``gnss_obs`` and navigation files from
``ingest.gnss.ephemeris.Ephemeris``.

Observation file: one signal, GPS L1 C/A, with ``C1C`` (pseudorange, m), ``D1C`` (Doppler,
Hz, ``-pseudorange_rate_mps / LAMBDA_L1_M``, positive when the range shrinks) and ``S1C``
(C/N0, dB-Hz); each value F14.3 followed by the loss-of-lock indicator (blank) and the signal
strength indicator 1-9 derived from C/N0. Epochs are GPS time; no receiver clock offset is
written (it is in the pseudoranges).

Navigation file: one LNAV record per ephemeris, every value in D19.12 (13 significant
digits). Elements already rounded to that precision (``pipeline.synth.constellation`` does so)
are reproduced exactly by any reader.

Headers carry no wall-clock time: the "date of file creation" is the first epoch, so the
same input gives byte-identical files.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa

from navreplay.ingest.atomic import atomic_write_text
from navreplay.ingest.gnss.ephemeris import LAMBDA_L1_M, Ephemeris
from navreplay.ingest.gpstime import NS_PER_S, calendar_from_gps, leap_seconds, week_and_seconds
from navreplay.ingest.tables import package_version

RINEX_VERSION = "3.04"
OBS_TYPES = ("C1C", "D1C", "S1C")


@dataclass(frozen=True)
class Station:
    """Header facts about the receiver.

    Attributes:
        marker: marker name (the dataset id).
        approx_ecef_m: approximate antenna position, ECEF m.
        marker_type: RINEX marker type (``GROUND_CRAFT`` for a car).
        receiver: receiver type; antenna: antenna type.
        agency: observer agency.
    """

    marker: str
    approx_ecef_m: tuple[float, float, float]
    marker_type: str = "GROUND_CRAFT"
    receiver: str = "navreplay synthetic"
    antenna: str = "navreplay synthetic"
    agency: str = "navreplay"


def _line(content: str, label: str) -> str:
    if len(content) > 60:
        raise ValueError(f"RINEX header field too long for {label!r}: {content!r}")
    return f"{content:<60}{label:<20}".rstrip() + "\n"


def _calendar(t_ns: int) -> tuple[int, int, int, int, int, float]:
    """(year, month, day, hour, minute, seconds) of a GPS t_ns, on the GPS scale."""
    stamp = calendar_from_gps(t_ns)
    day = stamp.astype("datetime64[D]")
    y, m, d = (int(x) for x in str(day).split("-"))
    ns_of_day = int((stamp - day).astype("timedelta64[ns]").astype(np.int64))
    hour, rem = divmod(ns_of_day, 3600 * NS_PER_S)
    minute, rem = divmod(rem, 60 * NS_PER_S)
    return y, m, d, hour, minute, rem / NS_PER_S


def _pgm_line(t_ns: int) -> str:
    y, m, d, hh, mm, ss = _calendar(int(t_ns - leap_seconds(t_ns) * NS_PER_S))
    stamp = f"{y:04d}{m:02d}{d:02d} {hh:02d}{mm:02d}{int(ss):02d} UTC"
    return _line(
        f"{'navreplay ' + package_version():<20}{'navreplay':<20}{stamp:<20}", "PGM / RUN BY / DATE"
    )


def _time_line(t_ns: int, label: str) -> str:
    y, m, d, hh, mm, ss = _calendar(t_ns)
    return _line(f"{y:6d}{m:6d}{d:6d}{hh:6d}{mm:6d}{ss:13.7f}     GPS", label)


def _ssi(cn0_dbhz: float) -> str:
    """RINEX signal strength indicator: 1 (< 12 dB-Hz) ... 9 (>= 54 dB-Hz); blank if unknown."""
    if not math.isfinite(cn0_dbhz):
        return " "
    return str(min(9, max(1, math.floor((cn0_dbhz - 12.0) / 6.0) + 2)))


def _obs_field(value: float, ssi: str) -> str:
    return f"{value:14.3f} {ssi}" if math.isfinite(value) else " " * 16


def write_obs(path: str | Path, gnss_obs: pa.Table, station: Station, interval_s: float) -> None:
    """Write a GPS ``gnss_obs`` table (GPS time base) as a RINEX 3.04 observation file.

    Raises:
        ValueError: a satellite is not GPS or the table is empty.
    """
    t = gnss_obs.column("t_ns").to_numpy()
    if t.size == 0:
        raise ValueError("no observations to write")
    sv = [str(s) for s in gnss_obs.column("sv").to_pylist()]
    if any(not s.startswith("G") for s in sv):
        raise ValueError("only GPS satellites can be written")
    pr = _floats(gnss_obs, "pseudorange_m")
    dop = -_floats(gnss_obs, "pseudorange_rate_mps") / LAMBDA_L1_M
    cn0 = _floats(gnss_obs, "cn0_dbhz")
    x, y, z = station.approx_ecef_m
    head = [
        _line(
            f"{RINEX_VERSION:>9}{'':11}{'OBSERVATION DATA':<20}{'G':<20}", "RINEX VERSION / TYPE"
        ),
        _pgm_line(int(t[0])),
        _line(station.marker, "MARKER NAME"),
        _line(station.marker_type, "MARKER TYPE"),
        _line(f"{'navreplay':<20}{station.agency:<40}", "OBSERVER / AGENCY"),
        _line(f"{'0':<20}{station.receiver:<20}{package_version():<20}", "REC # / TYPE / VERS"),
        _line(f"{'0':<20}{station.antenna:<20}", "ANT # / TYPE"),
        _line(f"{x:14.4f}{y:14.4f}{z:14.4f}", "APPROX POSITION XYZ"),
        _line(f"{0.0:14.4f}{0.0:14.4f}{0.0:14.4f}", "ANTENNA: DELTA H/E/N"),
        _line(
            f"G  {len(OBS_TYPES):3d}" + "".join(f" {o}" for o in OBS_TYPES), "SYS / # / OBS TYPES"
        ),
        _line("DBHZ", "SIGNAL STRENGTH UNIT"),
        _line(f"{interval_s:10.3f}", "INTERVAL"),
        _time_line(int(t[0]), "TIME OF FIRST OBS"),
        _time_line(int(t[-1]), "TIME OF LAST OBS"),
        _line("G", "SYS / PHASE SHIFT"),
        _line(f"{int(leap_seconds(int(t[0]))):6d}", "LEAP SECONDS"),
        _line("", "END OF HEADER"),
    ]
    body: list[str] = []
    starts = np.concatenate(([0], np.flatnonzero(np.diff(t)) + 1, [t.size]))
    for a, b in itertools.pairwise(starts):
        yr, mo, dy, hh, mm, ss = _calendar(int(t[a]))
        body.append(f"> {yr:4d} {mo:02d} {dy:02d} {hh:02d} {mm:02d}{ss:11.7f}  0{b - a:3d}\n")
        for i in range(a, b):
            ssi = _ssi(cn0[i])
            fields = _obs_field(pr[i], ssi) + _obs_field(dop[i], ssi) + _obs_field(cn0[i], " ")
            body.append(f"{sv[i]}{fields}".rstrip() + "\n")
    atomic_write_text(path, "".join(head) + "".join(body))


def _floats(table: pa.Table, name: str) -> np.ndarray:
    if name not in table.column_names:
        return np.full(table.num_rows, np.nan)
    return np.asarray(table.column(name).to_numpy(zero_copy_only=False), dtype=np.float64)


def _d19(values: Sequence[float]) -> str:
    return "".join(f"{v: .12E}" for v in values)


def write_nav(path: str | Path, eph: Ephemeris) -> None:
    """Write GPS LNAV ephemerides as a RINEX 3.04 navigation file (records in given order).

    Raises:
        ValueError: there are no records.
    """
    if len(eph) == 0:
        raise ValueError("no ephemerides to write")
    first = int(np.min(eph.toc_ns))
    head = [
        _line(
            f"{RINEX_VERSION:>9}{'':11}{'N: GNSS NAV DATA':<20}{'G: GPS':<20}",
            "RINEX VERSION / TYPE",
        ),
        _pgm_line(first),
        _line(f"{int(leap_seconds(first)):6d}", "LEAP SECONDS"),
        _line("", "END OF HEADER"),
    ]
    body: list[str] = []
    sow = eph.toe_sow_s
    for k in range(len(eph)):
        yr, mo, dy, hh, mm, ss = _calendar(int(eph.toc_ns[k]))
        week, _ = week_and_seconds(int(eph.toe_ns[k]))
        body.append(
            f"G{int(eph.prn[k]):02d} {yr:4d} {mo:02d} {dy:02d} {hh:02d} {mm:02d} {int(ss):02d}"
            + _d19([eph.af0_s[k], eph.af1_sps[k], eph.af2_sps2[k]])
            + "\n"
        )
        orbits = (
            (float(eph.iode[k]), eph.crs_m[k], eph.delta_n_radps[k], eph.m0_rad[k]),
            (eph.cuc_rad[k], eph.e[k], eph.cus_rad[k], eph.sqrt_a_sqrtm[k]),
            (sow[k], eph.cic_rad[k], eph.omega0_rad[k], eph.cis_rad[k]),
            (eph.i0_rad[k], eph.crc_m[k], eph.arg_perigee_rad[k], eph.omega_dot_radps[k]),
            (eph.idot_radps[k], 1.0, float(week), 0.0),
            (eph.accuracy_m[k], float(eph.health[k]), eph.tgd_s[k], float(eph.iodc[k])),
            (eph.transmit_sow_s[k], eph.fit_interval_h[k]),
        )
        body.extend("    " + _d19(row) + "\n" for row in orbits)
    atomic_write_text(path, "".join(head) + "".join(body))
