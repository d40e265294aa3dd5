"""Write a ``SynthResult`` as the files of a dataset's ``raw/`` folder.

Layout of ``out_dir`` (replaced as a whole, atomically):

- ``<id>.mcap``: ROS 2 MCAP (``ingest.writers.ros``), when there is an IMU;
- ``<id>.bag``: the same as a ROS 1 bag;
- ``<id>.obs`` / ``<id>.nav``: RINEX 3.04 observations and navigation (``ingest.writers.rinex``),
  when there are raw observables and ephemerides;
- ``reference/<table>.parquet`` and ``reference/meta.json``: the synthesizer's own canonical
  tables and sensor metadata, against which the ingest of the log files is checked.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from navreplay.ingest.atomic import atomic_directory
from navreplay.ingest.meta import DatasetMeta, SourceRecord, write_meta
from navreplay.ingest.tables import Provenance, sha256_file, write_table
from navreplay.ingest.typed import to_plain
from navreplay.ingest.writers import rinex, ros
from navreplay.pipeline.nav import earth
from navreplay.pipeline.synth import SynthResult
from navreplay.pipeline.synth.output import SYNTH_LOG_SUFFIXES

log = logging.getLogger(__name__)
REFERENCE_DIR = "reference"


def _imu_rate_hz(result: SynthResult) -> float:
    t = result.tables["imu"].column("t_ns").to_numpy()
    return 1e9 / float(np.median(np.diff(t))) if t.size > 1 else 0.0


def write_result(name: str, result: SynthResult, out_dir: Path, *, params: Any) -> list[Path]:
    """Write every file of dataset ``name`` into ``out_dir``; returns their final paths."""
    out_dir = Path(out_dir)
    tables = result.tables
    written: list[tuple[str, str]] = []  # (file name, format)
    with atomic_directory(out_dir, extra_suffixes=SYNTH_LOG_SUFFIXES) as tmp:
        if "imu" in tables:
            noise = result.sensors.imu_noise
            rate = _imu_rate_hz(result)
            opts = ros.RosOptions(
                time_base="gps" if result.time_base == "gps" else "utc",
                accel_var_m2ps4=(noise.accel_noise_mps2_rthz**2 * rate) if noise else 0.0,
                gyro_var_rad2ps2=(noise.gyro_noise_radps_rthz**2 * rate) if noise else 0.0,
            )
            ros_tables = {k: tables[k] for k in ("imu", "gnss", "truth") if k in tables}
            ros.write_mcap(tmp / f"{name}.mcap", ros_tables, opts)
            ros.write_bag(tmp / f"{name}.bag", ros_tables, opts)
            written += [(f"{name}.mcap", "mcap"), (f"{name}.bag", "rosbag1")]
        if "gnss_obs" in tables and result.ephemeris is not None:
            rinex.write_obs(
                tmp / f"{name}.obs",
                tables["gnss_obs"],
                _station(name, tables),
                interval_s=_interval_s(tables["gnss_obs"]),
            )
            rinex.write_nav(tmp / f"{name}.nav", result.ephemeris)
            written += [(f"{name}.obs", "rinex_obs"), (f"{name}.nav", "rinex_nav")]
        sources = tuple(SourceRecord(f, sha256_file(tmp / f), fmt) for f, fmt in written)
        ref = tmp / REFERENCE_DIR
        plain = to_plain(params)
        for tname, table in sorted(tables.items()):
            prov = Provenance.create(tname, params=plain, extra={"synthesizer": name})
            write_table(ref / f"{tname}.parquet", tname, table, prov)
        write_meta(
            ref,
            DatasetMeta(
                dataset=name,
                time_base=result.time_base,
                sources=sources,
                tables={k: v.num_rows for k, v in sorted(tables.items())},
                sensors=result.sensors,
            ),
        )
    log.info("synthesized %s: %s", name, ", ".join(f for f, _ in written))
    return [out_dir / f for f, _ in written] + [out_dir / REFERENCE_DIR]


def _interval_s(obs: Any) -> float:
    t = np.unique(obs.column("t_ns").to_numpy())
    return float(np.median(np.diff(t))) / 1e9 if t.size > 1 else 0.0


def _station(name: str, tables: Mapping[str, Any]) -> rinex.Station:
    g = tables["gnss"]
    lat = np.asarray(g.column("lat_deg").to_numpy(zero_copy_only=False), dtype=np.float64)
    lon = np.asarray(g.column("lon_deg").to_numpy(zero_copy_only=False), dtype=np.float64)
    alt = np.asarray(g.column("alt_m").to_numpy(zero_copy_only=False), dtype=np.float64)
    k = int(np.flatnonzero(np.isfinite(lat))[0]) if np.isfinite(lat).any() else 0
    xyz = earth.geodetic_to_ecef(math.radians(lat[k]), math.radians(lon[k]), float(alt[k]))
    return rinex.Station(marker=name, approx_ecef_m=(float(xyz[0]), float(xyz[1]), float(xyz[2])))
