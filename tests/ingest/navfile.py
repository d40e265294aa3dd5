"""Test helper: a RINEX GPS navigation file read by georinex, as an
``ingest.gnss.ephemeris.Ephemeris``.

georinex is the independent parser here (the project's own RINEX reader is not involved), so
tests of the orbit code and of the RINEX writer compare against a third party's reading.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import georinex
import numpy as np

from navreplay.ingest.gnss.ephemeris import Ephemeris
from navreplay.ingest.gpstime import GPS_EPOCH, NS_PER_S, NS_PER_WEEK


def read_gps_nav(path: Path) -> Ephemeris:
    """Every GPS record of a RINEX 2/3 navigation file (georinex), in file order by toc."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)  # georinex vs newer xarray, harmless
        ds = georinex.load(path)
    cols: dict[str, list[float]] = {name: [] for name in Ephemeris._fields}
    rename = {
        "af0_s": "SVclockBias",
        "af1_sps": "SVclockDrift",
        "af2_sps2": "SVclockDriftRate",
        "tgd_s": "TGD",
        "sqrt_a_sqrtm": "sqrtA",
        "e": "Eccentricity",
        "i0_rad": "Io",
        "idot_radps": "IDOT",
        "omega0_rad": "Omega0",
        "omega_dot_radps": "OmegaDot",
        "arg_perigee_rad": "omega",
        "m0_rad": "M0",
        "delta_n_radps": "DeltaN",
        "cuc_rad": "Cuc",
        "cus_rad": "Cus",
        "crc_m": "Crc",
        "crs_m": "Crs",
        "cic_rad": "Cic",
        "cis_rad": "Cis",
        "iode": "IODE",
        "iodc": "IODC",
        "health": "health",
        "accuracy_m": "SVacc",
        "fit_interval_h": "FitIntvl",
        "transmit_sow_s": "TransTime",
    }
    times = ds["time"].values
    for sv in ds["sv"].values:
        if not str(sv).startswith("G"):
            continue
        sub = ds.sel(sv=sv)
        for k, toc in enumerate(times):
            if np.isnan(sub["sqrtA"].values[k]):
                continue
            cols["prn"].append(int(str(sv)[1:]))
            cols["toc_ns"].append(int((toc - GPS_EPOCH).astype("timedelta64[ns]").astype(np.int64)))
            week = int(sub["GPSWeek"].values[k])
            toe = float(sub["Toe"].values[k])
            cols["toe_ns"].append(week * NS_PER_WEEK + round(toe * NS_PER_S))
            for ours, theirs in rename.items():
                cols[ours].append(float(sub[theirs].values[k]))
    return Ephemeris.from_columns(**cols)
