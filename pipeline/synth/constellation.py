"""The nominal 24-slot GPS constellation as broadcast ephemerides.

Slots: GPS SPS Performance Standard (4th ed., 2008, Table 3.1-1; identical in the 2001 edition,
Table 3-1): six planes A-F, four slots each, given as right ascension of the ascending node
(RAAN) and argument of latitude at the defined epoch 0000Z 1 July 1993, when the Greenwich hour
angle was 18 h 36 m 14.4 s. Reference orbit: semi-major axis 26,559.7 km, inclination 55 deg,
eccentricity 0.00-0.02.

The slots fix the constellation's geometry relative to the rotating earth at the defined epoch
(node longitude = RAAN - Greenwich hour angle). We place that geometry at 00:00 (GPS) of the
dataset's day and propagate two-body motion with J2 nodal regression from there, so the same
satellites rise over the same places at the same time of every synthesized day. Ephemerides are
"uploaded" every ``upload_interval_s`` (toe on multiples of it, 4 h fit interval) for the
span needed; consecutive uploads describe the same orbit, so positions are continuous across
them. Every broadcast value is rounded to the 13 significant digits a RINEX navigation file
holds, so the file written from these records reproduces exactly the orbits the synthesizer
used.
"""

from __future__ import annotations

import math

import numpy as np

from navreplay.ingest.gnss.ephemeris import MU_GPS, OMEGA_E_GPS, Ephemeris
from navreplay.ingest.gpstime import NS_PER_S, NS_PER_WEEK
from navreplay.pipeline.synth.seoul_params import ConstellationParams

# (slot, RAAN deg, argument of latitude deg) at 0000Z 1 July 1993 (SPS PS 2008, Table 3.1-1)
SLOTS: tuple[tuple[str, float, float], ...] = (
    ("A1", 272.847, 268.126),
    ("A2", 272.847, 161.786),
    ("A3", 272.847, 11.676),
    ("A4", 272.847, 41.806),
    ("B1", 332.847, 80.956),
    ("B2", 332.847, 173.336),
    ("B3", 332.847, 309.976),
    ("B4", 332.847, 204.376),
    ("C1", 32.847, 111.876),
    ("C2", 32.847, 11.796),
    ("C3", 32.847, 339.666),
    ("C4", 32.847, 241.556),
    ("D1", 92.847, 135.226),
    ("D2", 92.847, 265.446),
    ("D3", 92.847, 35.156),
    ("D4", 92.847, 167.356),
    ("E1", 152.847, 197.046),
    ("E2", 152.847, 302.596),
    ("E3", 152.847, 66.066),
    ("E4", 152.847, 333.686),
    ("F1", 212.847, 238.886),
    ("F2", 212.847, 345.226),
    ("F3", 212.847, 105.206),
    ("F4", 212.847, 135.346),
)
GHA_EPOCH_DEG = (18.0 + 36.0 / 60.0 + 14.4 / 3600.0) * 15.0
SEMI_MAJOR_AXIS_M = 26_559_700.0
INCLINATION_DEG = 55.0
J2 = 1.08262668e-3
R_EARTH_M = 6_378_137.0
FIT_INTERVAL_H = 4.0
URA_M = 2.0


def rinex_round(x: np.ndarray) -> np.ndarray:
    """Values rounded to 13 significant digits, i.e. exactly what a D19.12 field holds."""
    return np.array([float(f"{v:.12E}") for v in np.asarray(x, dtype=np.float64).ravel()])


def nodal_rate_radps(a_m: float, e: float, incl_rad: float) -> float:
    """Secular J2 regression of the node, rad/s (-7.8e-9 for GPS; SPS PS: -4.49e-7 deg/s)."""
    n = math.sqrt(MU_GPS / a_m**3)
    p = a_m * (1.0 - e * e)
    return -1.5 * n * J2 * (R_EARTH_M / p) ** 2 * math.cos(incl_rad)


def nominal_gps(
    t_start_ns: int, t_end_ns: int, params: ConstellationParams, rng: np.random.Generator
) -> Ephemeris:
    """Broadcast ephemerides of the 24 nominal slots covering ``[t_start_ns, t_end_ns]``.

    PRN k+1 flies slot ``SLOTS[k]``. Satellite clocks (af0, af1; af2 = 0) and TGD are drawn
    from ``rng``. Records are ordered by toe, then PRN; IODE = IODC counts the uploads.
    """
    step_ns = params.upload_interval_s * NS_PER_S
    t_ref = (t_start_ns // (86_400 * NS_PER_S)) * 86_400 * NS_PER_S
    first = -(-(t_start_ns - step_ns // 2) // step_ns)
    last = (t_end_ns + step_ns // 2) // step_ns
    toes = np.arange(first, last + 1, dtype=np.int64) * step_ns
    nsat = len(SLOTS)
    af0 = rng.normal(0.0, params.af0_sigma_s, nsat)
    af1 = rng.normal(0.0, params.af1_sigma_sps, nsat)
    tgd = np.round(rng.normal(0.0, params.tgd_sigma_s, nsat) * 2.0**31) / 2.0**31
    a, e = SEMI_MAJOR_AXIS_M, params.eccentricity
    inc = math.radians(INCLINATION_DEG)
    n = math.sqrt(MU_GPS / a**3)
    node_rate = nodal_rate_radps(a, e, inc)
    omega = math.radians(params.arg_perigee_deg)
    raan = np.radians([s[1] for s in SLOTS])
    arg_lat = np.radians([s[2] for s in SLOTS])
    prn = np.arange(1, nsat + 1, dtype=np.int64)
    cols: dict[str, list[np.ndarray]] = {name: [] for name in Ephemeris._fields}
    for k, toe in enumerate(toes):
        dt = (toe - t_ref) / NS_PER_S
        toe_sow = (toe % NS_PER_WEEK) / NS_PER_S
        node_lon = raan - math.radians(GHA_EPOCH_DEG) + (node_rate - OMEGA_E_GPS) * dt
        omega0 = _wrap(node_lon + OMEGA_E_GPS * toe_sow)
        m0 = _wrap(arg_lat - omega + n * dt)
        ones = np.ones(nsat)
        values = {
            "prn": prn,
            "toc_ns": np.full(nsat, toe),
            "toe_ns": np.full(nsat, toe),
            "af0_s": af0 + af1 * dt,
            "af1_sps": af1,
            "af2_sps2": 0.0 * ones,
            "tgd_s": tgd,
            "sqrt_a_sqrtm": math.sqrt(a) * ones,
            "e": e * ones,
            "i0_rad": inc * ones,
            "idot_radps": 0.0 * ones,
            "omega0_rad": omega0,
            "omega_dot_radps": node_rate * ones,
            "arg_perigee_rad": omega * ones,
            "m0_rad": m0,
            "delta_n_radps": 0.0 * ones,
            "cuc_rad": 0.0 * ones,
            "cus_rad": 0.0 * ones,
            "crc_m": 0.0 * ones,
            "crs_m": 0.0 * ones,
            "cic_rad": 0.0 * ones,
            "cis_rad": 0.0 * ones,
            "iode": np.full(nsat, (first + k) % 256),
            "iodc": np.full(nsat, (first + k) % 256),
            "health": np.zeros(nsat, dtype=np.int64),
            "accuracy_m": URA_M * ones,
            "fit_interval_h": FIT_INTERVAL_H * ones,
            "transmit_sow_s": (toe_sow - params.upload_interval_s) * ones,
        }
        for name, v in values.items():
            arr = np.asarray(v)
            cols[name].append(arr if arr.dtype.kind == "i" else rinex_round(arr))
    return Ephemeris.from_columns(**{k: np.concatenate(v) for k, v in cols.items()})


def _wrap(x: np.ndarray) -> np.ndarray:
    return np.asarray(np.mod(x + np.pi, 2.0 * np.pi) - np.pi, dtype=np.float64)
