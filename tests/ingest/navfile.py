"""Test helper: a RINEX GPS navigation file read by georinex, as an
``ingest.gnss.ephemeris.Ephemeris``.

georinex is the independent parser here (the project's own RINEX reader is not involved, only its
names of georinex's variables, ``GEORINEX_FIELDS``), so
tests of the orbit code and of the RINEX writer compare against a third party's reading.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import georinex
import numpy as np

from navreplay.ingest.gnss.ephemeris import Ephemeris
from navreplay.ingest.gnss.rinexnav import GEORINEX_FIELDS
from navreplay.ingest.gpstime import GPS_EPOCH, NS_PER_S, NS_PER_WEEK


def read_gps_nav(path: Path) -> Ephemeris:
    """Every GPS record of a RINEX 2/3 navigation file (georinex), in file order by toc."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)  # georinex vs newer xarray, harmless
        ds = georinex.load(path)
    cols: dict[str, list[float]] = {name: [] for name in Ephemeris._fields}
    rename = {**GEORINEX_FIELDS, "fit_interval_h": "FitIntvl"}
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
