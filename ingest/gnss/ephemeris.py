"""GPS broadcast orbits and clocks: the IS-GPS-200 user algorithm, vectorized over satellites.

``Ephemeris`` holds the broadcast navigation elements of any number of ephemeris records as
parallel arrays (what a RINEX navigation file carries and what the synthesizer broadcasts).
``orbit`` evaluates satellite ECEF position, velocity and clock at GPS times (IS-GPS-200N
Table 20-IV, with the velocity equations of its 2013+ editions); ``transmit_state`` finds the
transmit time of a signal received at a known time and place by light-time iteration and
expresses the satellite state in the ECEF frame of the receive time (Sagnac / earth-rotation
correction), which is the convention of ``gnss_obs`` (see ``ingest.schema``).

Units: metres, seconds, radians; times are int64 GPS ``t_ns`` (``ingest.gpstime``) with an
optional float offset in seconds so that ``t - toe`` stays exact to well below a nanosecond.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt
import pymap3d

from navreplay.ingest.arrays import F64, I64
from navreplay.ingest.gpstime import NS_PER_S, NS_PER_WEEK

C_MPS = 299_792_458.0  # speed of light, m/s
MU_GPS = 3.986005e14  # WGS-84 gravitational constant used by the GPS user algorithm, m^3/s^2
OMEGA_E_GPS = 7.2921151467e-5  # WGS-84 earth rotation rate used by GPS, rad/s
F_REL = -4.442807633e-10  # relativistic clock constant F = -2 sqrt(mu) / c^2, s/m^(1/2)
F_L1_HZ = 1_575.42e6
LAMBDA_L1_M = C_MPS / F_L1_HZ
_KEPLER_TOL_RAD = 1e-14
_KEPLER_MAX_ITER = 30


class Ephemeris(NamedTuple):
    """GPS LNAV broadcast ephemeris records as parallel arrays, one element per record.

    Angles in radians (RINEX convention, not semicircles); ``omega0_rad`` is the longitude of
    the ascending node at the start of the GPS week of ``toe`` (IS-GPS-200 Omega_0);
    ``arg_perigee_rad`` is omega. ``toe_ns`` and ``toc_ns`` are full GPS times (week included).
    ``transmit_sow_s`` is the transmission time of the message in seconds of the ``toe`` week
    (may be negative, as RINEX allows). ``fit_interval_h`` 0 means the default 4 h.
    """

    prn: I64
    toc_ns: I64
    toe_ns: I64
    af0_s: F64
    af1_sps: F64
    af2_sps2: F64
    tgd_s: F64
    sqrt_a_sqrtm: F64
    e: F64
    i0_rad: F64
    idot_radps: F64
    omega0_rad: F64
    omega_dot_radps: F64
    arg_perigee_rad: F64
    m0_rad: F64
    delta_n_radps: F64
    cuc_rad: F64
    cus_rad: F64
    crc_m: F64
    crs_m: F64
    cic_rad: F64
    cis_rad: F64
    iode: I64
    iodc: I64
    health: I64
    accuracy_m: F64
    fit_interval_h: F64
    transmit_sow_s: F64

    @classmethod
    def from_columns(cls, **columns: npt.ArrayLike) -> Ephemeris:
        """Build from column arrays of equal length, cast to the field dtypes.

        Raises:
            ValueError: a field is missing or unknown, or the lengths differ.
        """
        missing = set(cls._fields) - set(columns)
        unknown = set(columns) - set(cls._fields)
        if missing or unknown:
            raise ValueError(f"ephemeris columns: missing {sorted(missing)}, unknown {unknown}")
        arrays: dict[str, Any] = {}
        for name in cls._fields:
            dtype = np.int64 if name in _INT_FIELDS else np.float64
            arrays[name] = np.atleast_1d(np.asarray(columns[name], dtype=dtype))
        if len({a.shape for a in arrays.values()}) != 1:
            raise ValueError("ephemeris columns have different lengths")
        return cls(**arrays)

    def __len__(self) -> int:
        return int(self.prn.shape[0])

    def take(self, idx: npt.ArrayLike) -> Ephemeris:
        """The records at positions ``idx`` (any integer index array)."""
        i = np.asarray(idx, dtype=np.int64)
        cols: list[Any] = [np.asarray(f)[i] for f in self]
        return Ephemeris(*cols)

    @property
    def toe_sow_s(self) -> F64:
        """toe as seconds of its GPS week (the broadcast value)."""
        return np.asarray((self.toe_ns % NS_PER_WEEK) / NS_PER_S, dtype=np.float64)

    @property
    def week(self) -> I64:
        """Continuous GPS week number of toe."""
        return np.asarray(self.toe_ns // NS_PER_WEEK, dtype=np.int64)


_INT_FIELDS = frozenset({"prn", "toc_ns", "toe_ns", "iode", "iodc", "health"})


def concat(parts: list[Ephemeris]) -> Ephemeris:
    """The records of several ``Ephemeris`` in order."""
    cols: list[Any] = [np.concatenate(c) for c in zip(*parts, strict=True)]
    return Ephemeris(*cols)


class SatState(NamedTuple):
    """Satellite states, one row per query.

    Attributes:
        pos_m: ECEF position, m, shape (n, 3).
        vel_mps: ECEF velocity (rate of the ECEF coordinates), m/s, shape (n, 3).
        clock_s: satellite clock offset incl. the relativistic term, excl. TGD, s, shape (n,).
        clock_drift_sps: its rate, s/s, shape (n,).
        tgd_s: broadcast group delay; the L1 C/A offset is ``clock_s - tgd_s``.
    """

    pos_m: F64
    vel_mps: F64
    clock_s: F64
    clock_drift_sps: F64
    tgd_s: F64


def select(eph: Ephemeris, prn: npt.ArrayLike, t_ns: npt.ArrayLike) -> I64:
    """For each query (prn, GPS time), the record to use, or -1 if none is valid.

    ``prn`` and ``t_ns`` broadcast to one shape; the result is flat, shape (n,).

    A record is valid when healthy (``health == 0``) and ``|t - toe|`` is within half its fit
    interval; among valid records the one with the nearest ``toe`` wins (the later one on a
    tie, i.e. the newer upload).
    """
    prn_q, t_q = (
        np.ravel(a)
        for a in np.broadcast_arrays(
            np.atleast_1d(np.asarray(prn, dtype=np.int64)), np.asarray(t_ns, dtype=np.int64)
        )
    )
    out = np.full(prn_q.shape, -1, dtype=np.int64)
    fit_ns = np.where(eph.fit_interval_h > 0, eph.fit_interval_h, 4.0) * 1800.0 * NS_PER_S
    for p in np.unique(prn_q):
        cand = np.flatnonzero((eph.prn == p) & (eph.health == 0))
        if cand.size == 0:
            continue
        cand = cand[np.argsort(-eph.toe_ns[cand], kind="stable")]  # newest first wins ties
        q = np.flatnonzero(prn_q == p)
        dt = np.abs(t_q[q, None] - eph.toe_ns[cand][None, :]).astype(np.float64)
        dt[dt > fit_ns[cand][None, :]] = np.inf
        best = np.argmin(dt, axis=1)
        ok = np.isfinite(dt[np.arange(q.size), best])
        out[q[ok]] = cand[best[ok]]
    return out


def _kepler(m: F64, e: F64) -> F64:
    """Eccentric anomaly E solving M = E - e sin E (Newton; |error| < 1e-14 rad)."""
    ecc = m.copy()
    for _ in range(_KEPLER_MAX_ITER):
        step = (ecc - e * np.sin(ecc) - m) / (1.0 - e * np.cos(ecc))
        ecc -= step
        if np.all(np.abs(step) < _KEPLER_TOL_RAD):
            break
    return ecc


def orbit(
    eph: Ephemeris, idx: npt.ArrayLike, t_ns: npt.ArrayLike, offset_s: npt.ArrayLike = 0.0
) -> SatState:
    """Satellite ECEF state at GPS time ``t_ns + offset_s`` from record ``idx`` of ``eph``.

    IS-GPS-200 Table 20-IV (position, clock with the relativistic term) and its velocity
    equations. ``idx``, ``t_ns`` and ``offset_s`` broadcast to one shape (n,). The position
    is in the ECEF frame of that same instant (no Sagnac rotation; see ``transmit_state``).
    """
    i = np.atleast_1d(np.asarray(idx, dtype=np.int64))
    t = np.asarray(t_ns, dtype=np.int64)
    i, t, off = np.broadcast_arrays(i, t, np.asarray(offset_s, dtype=np.float64))
    tk = (t - eph.toe_ns[i]).astype(np.float64) / NS_PER_S + off
    tc = (t - eph.toc_ns[i]).astype(np.float64) / NS_PER_S + off
    a = eph.sqrt_a_sqrtm[i] ** 2
    e = eph.e[i]
    n = np.sqrt(MU_GPS / a**3) + eph.delta_n_radps[i]
    ecc = _kepler(eph.m0_rad[i] + n * tk, e)
    se, ce = np.sin(ecc), np.cos(ecc)
    one_m_ece = 1.0 - e * ce
    sq = np.sqrt(1.0 - e * e)
    nu = np.arctan2(sq * se, ce - e)
    phi = nu + eph.arg_perigee_rad[i]
    s2, c2 = np.sin(2.0 * phi), np.cos(2.0 * phi)
    cus, cuc = eph.cus_rad[i], eph.cuc_rad[i]
    crs, crc = eph.crs_m[i], eph.crc_m[i]
    cis, cic = eph.cis_rad[i], eph.cic_rad[i]
    u = phi + cus * s2 + cuc * c2
    r = a * one_m_ece + crs * s2 + crc * c2
    inc = eph.i0_rad[i] + cis * s2 + cic * c2 + eph.idot_radps[i] * tk
    toe_sow = (eph.toe_ns[i] % NS_PER_WEEK).astype(np.float64) / NS_PER_S
    node_rate = eph.omega_dot_radps[i] - OMEGA_E_GPS
    node = eph.omega0_rad[i] + node_rate * tk - OMEGA_E_GPS * toe_sow
    su, cu = np.sin(u), np.cos(u)
    so, co = np.sin(node), np.cos(node)
    si, ci = np.sin(inc), np.cos(inc)
    xp, yp = r * cu, r * su
    pos = np.stack([xp * co - yp * ci * so, xp * so + yp * ci * co, yp * si], axis=-1)
    # velocity: derivatives of the same quantities
    edot = n / one_m_ece
    nudot = edot * sq / one_m_ece
    idot = eph.idot_radps[i] + 2.0 * nudot * (cis * c2 - cic * s2)
    udot = nudot * (1.0 + 2.0 * (cus * c2 - cuc * s2))
    rdot = e * a * edot * se + 2.0 * nudot * (crs * c2 - crc * s2)
    xpd = rdot * cu - r * udot * su
    ypd = rdot * su + r * udot * cu
    vel = np.stack(
        [
            -xp * node_rate * so
            + xpd * co
            - ypd * so * ci
            - yp * (node_rate * co * ci - idot * so * si),
            xp * node_rate * co
            + xpd * so
            + ypd * co * ci
            - yp * (node_rate * so * ci + idot * co * si),
            yp * idot * ci + ypd * si,
        ],
        axis=-1,
    )
    rel = F_REL * e * eph.sqrt_a_sqrtm[i] * se
    rel_dot = F_REL * e * eph.sqrt_a_sqrtm[i] * ce * edot
    af1, af2 = eph.af1_sps[i], eph.af2_sps2[i]
    clock = eph.af0_s[i] + af1 * tc + af2 * tc * tc + rel
    drift = af1 + 2.0 * af2 * tc + rel_dot
    return SatState(pos, vel, clock, drift, eph.tgd_s[i].copy())


def rotate_earth(vec: F64, tau_s: F64) -> F64:
    """ECEF vectors of an earlier instant expressed in the ECEF frame ``tau_s`` seconds later.

    The earth turns by ``OMEGA_E_GPS * tau`` about z meanwhile (Sagnac correction); ``vec`` is
    shape (n, 3), ``tau_s`` shape (n,).
    """
    th = OMEGA_E_GPS * tau_s
    c, s = np.cos(th), np.sin(th)
    return np.stack([c * vec[:, 0] + s * vec[:, 1], -s * vec[:, 0] + c * vec[:, 1], vec[:, 2]], -1)


class TransmitState(NamedTuple):
    """A satellite state at transmit time in the receive-time ECEF frame, and the light time.

    ``sat.pos_m``/``sat.vel_mps`` are rotated into the ECEF frame of the receive time;
    ``range_m`` is the geometric range ``|sat.pos_m - rx|`` = c * ``tau_s``.
    """

    sat: SatState
    tau_s: F64
    range_m: F64


def transmit_state(
    eph: Ephemeris,
    idx: npt.ArrayLike,
    t_rx_ns: npt.ArrayLike,
    rx_ecef_m: npt.ArrayLike,
    *,
    rx_offset_s: npt.ArrayLike = 0.0,
    tol_s: float = 1e-13,
    max_iter: int = 10,
) -> TransmitState:
    """Satellite state at the transmit time of a signal received at ``t_rx`` by ``rx``.

    Light-time iteration on the geometric range: ``tau = |R(w_e tau) r_sat(t_rx - tau) - rx|
    / c`` until tau changes by less than ``tol_s`` (1e-13 s = 30 micrometres). ``t_rx_ns``
    (GPS, plus ``rx_offset_s`` seconds), ``idx`` and ``rx_ecef_m`` (n, 3) broadcast over n.
    """
    i = np.atleast_1d(np.asarray(idx, dtype=np.int64))
    t = np.broadcast_to(np.asarray(t_rx_ns, dtype=np.int64), i.shape)
    off = np.broadcast_to(np.asarray(rx_offset_s, dtype=np.float64), i.shape)
    rx = np.broadcast_to(np.asarray(rx_ecef_m, dtype=np.float64), (*i.shape, 3))
    tau = np.full(i.shape, 0.075)
    for _ in range(max_iter):
        st = orbit(eph, i, t, off - tau)
        pos = rotate_earth(st.pos_m, tau)
        rng = np.linalg.norm(pos - rx, axis=-1)
        new_tau = rng / C_MPS
        done = np.max(np.abs(new_tau - tau), initial=0.0) < tol_s
        tau = new_tau
        if done:
            break
    st = orbit(eph, i, t, off - tau)
    sat = SatState(rotate_earth(st.pos_m, tau), rotate_earth(st.vel_mps, tau), *st[2:])
    return TransmitState(sat, tau, np.linalg.norm(sat.pos_m - rx, axis=-1))


def elevation_azimuth(rx_ecef_m: npt.ArrayLike, sat_ecef_m: npt.ArrayLike) -> tuple[F64, F64]:
    """Elevation and azimuth (rad; azimuth clockwise from north in [0, 2 pi)) of satellites.

    Measured at the receiver against the WGS-84 ellipsoid normal; inputs broadcast to (n, 3),
    outputs have shape (n,).
    """
    rx, sat = np.broadcast_arrays(
        np.atleast_2d(np.asarray(rx_ecef_m, dtype=np.float64)),
        np.atleast_2d(np.asarray(sat_ecef_m, dtype=np.float64)),
    )
    lat, lon, _ = pymap3d.ecef2geodetic(rx[..., 0], rx[..., 1], rx[..., 2], deg=False)
    d = sat - rx
    sl, cl, so, co = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)
    east = -so * d[..., 0] + co * d[..., 1]
    north = -sl * co * d[..., 0] - sl * so * d[..., 1] + cl * d[..., 2]
    up = cl * co * d[..., 0] + cl * so * d[..., 1] + sl * d[..., 2]
    el = np.arctan2(up, np.hypot(east, north))
    az = np.mod(np.arctan2(east, north), 2.0 * np.pi)
    return np.asarray(el, dtype=np.float64), np.asarray(az, dtype=np.float64)
