"""RINEX observation reading: ingest's parser vs georinex on the same files.

GPS observation files of N epochs x 12 satellites (C1C D1C S1C, 1 Hz) are written as RINEX
3.04 (``ingest.writers.rinex``) and as RINEX 2.11 (two lines per satellite, GLONASS rows
mixed in: ``tests.ingest.gnssfiles``). ``ingest.gnss.rinexobs.read_obs`` (all GPS rows into
arrays) is timed against ``georinex.load`` of the same observation types (an xarray Dataset),
whose epoch-by-epoch concatenation makes it cost ~3.5 ms per epoch. Both give the same
values (``tests/ingest/test_rinex_reader.py``). The navigation file, parsed by georinex in
ingest, is timed alone.
"""

from __future__ import annotations

import argparse
import tempfile
import warnings
from functools import partial
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np

from benchmarks._table import print_table, timed
from navreplay.ingest.damage import DamageLog
from navreplay.ingest.gnss.rinexobs import from_georinex, read_obs, signals
from navreplay.ingest.gnss.rinextext import open_lines, read_header
from navreplay.ingest.gpstime import gps_from_calendar
from navreplay.ingest.schema import from_columns
from navreplay.ingest.writers import rinex


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--rinex-epochs",
        type=int,
        nargs="+",
        default=[900, 3600],
        help="epochs (1 Hz) of the observation files (default 900 3600: 15 min and 1 h)",
    )


def _drive(n_epochs: int, n_sats: int = 12) -> Any:
    t0 = gps_from_calendar("2026-11-18T02:30:00")
    t = np.repeat(t0 + np.arange(n_epochs, dtype=np.int64) * 10**9, n_sats)
    sv = np.tile(np.array([f"G{p:02d}" for p in range(1, n_sats + 1)]), n_epochs)
    rng = np.random.default_rng(0)
    obs = {
        "t_ns": t,
        "sv": sv,
        "pseudorange_m": np.round(2.0e7 + rng.random(t.size) * 5e6, 3),
        "pseudorange_rate_mps": np.round(rng.normal(0, 300, t.size), 3),
        "cn0_dbhz": np.round(35 + 10 * rng.random(t.size), 3),
        **{f"sat_{a}_m": np.zeros(t.size) for a in "xyz"},
    }
    gnss = {
        "t_ns": t[:1],
        "lat_deg": [37.46],
        "lon_deg": [126.95],
        "alt_m": [60.0],
        "fix_type": np.array([3], np.int8),
    }
    return SimpleNamespace(
        tables={"gnss_obs": from_columns("gnss_obs", obs), "gnss": from_columns("gnss", gnss)}
    )


def _ours(path: Path) -> int:
    _, _, _, chunks = read_obs(path, "obs", DamageLog(path, strict=False))
    return sum(len(c) for c in chunks)


def _georinex(path: Path) -> int:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with open_lines(path, "obs") as lines:
            head = read_header(path, lines)
        return len(from_georinex(path, head, signals(path, head)))


def run(options: argparse.Namespace) -> None:
    from tests.ingest.gnssfiles import station, write_obs2

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for n in options.rinex_epochs:
            synth = _drive(n)
            v3, v2 = Path(tmp) / f"v3_{n}.obs", Path(tmp) / f"v2_{n}.obs"
            rinex.write_obs(v3, synth.tables["gnss_obs"], station(synth), interval_s=1.0)
            write_obs2(v2, synth)
            for label, path in ((f"RINEX 3.04, {n} epochs", v3), (f"RINEX 2.11, {n} epochs", v2)):
                n_ours, n_ref = _ours(path), _georinex(path)
                assert n_ours == n_ref, (n_ours, n_ref)
                ours, ref = timed(partial(_ours, path)), timed(partial(_georinex, path))
                rows.append([label, n_ours, ref.seconds, ours.seconds, ref.seconds / ours.seconds])
    print_table(["file", "GPS rows", "georinex s", "ingest s", "ratio"], rows)
