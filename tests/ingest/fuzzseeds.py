"""Small valid logs of every format navreplay reads, for the bad-input fuzzer
(``test_fuzz_readers``), each written with the format's own writer or the project's fixture
writers: pymavlink packets (tlog), struct-packed DataFlash and ULog records, mcap's and
rosbags' writers (MCAP, ROS 1 bag, rosbag2 sqlite3 and MCAP), the project's RINEX 3.04
writer over a nominal GPS constellation, pynmeagps sentences (NMEA), plain text (CSV,
libRSF, GnssLogger) and NumPy arrays (a comma2k19 segment).

A seed is ``Seed(target, logs)``: ``target`` is the file the fuzzer damages (the storage
file of a rosbag2 directory), ``logs`` what is given to ``ingest`` (a RINEX observation file
comes with its navigation file, and the navigation file is damaged in the ``rinex_nav``
seed). Every seed ingests cleanly and takes well under a second.
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pyarrow as pa
import pymap3d
from pynmeagps import GET, NMEAMessage

from navreplay.ingest.gnss.ephemeris import LAMBDA_L1_M, orbit
from navreplay.ingest.gpstime import NS_PER_S, gps_from_calendar
from navreplay.ingest.schema import from_columns
from navreplay.ingest.writers import rinex

from .mavlogs import DriveSpec, df_drive, tlog_drive, ulog_drive
from .roslogs import fix_stream, imu_data, imu_stream, write_bag1, write_bag2, write_mcap


@dataclass(frozen=True)
class Seed:
    """A valid log: the file to damage and the paths to ingest."""

    target: Path
    logs: tuple[Path, ...]


def _tlog(d: Path) -> Seed:
    p = tlog_drive(DriveSpec(seconds=2.0)).write(d / "flight.tlog")
    return Seed(p, (p,))


def _dataflash(d: Path) -> Seed:
    p = df_drive(seconds=2.0).save(d / "flight.bin")
    return Seed(p, (p,))


def _ulog(d: Path) -> Seed:
    p = d / "flight.ulg"
    p.write_bytes(ulog_drive(seconds=1.0).bytes())
    return Seed(p, (p,))


def _ros_streams(ros1: bool = False) -> list:  # type: ignore[type-arg]
    return [imu_stream(imu_data(200), ros1=ros1), fix_stream(10, ros1=ros1)]


def _mcap(d: Path) -> Seed:
    p = write_mcap(d / "drive.mcap", _ros_streams(), chunk_size=4096)
    return Seed(p, (p,))


def _ros1bag(d: Path) -> Seed:
    p = write_bag1(d / "drive.bag", _ros_streams(ros1=True), chunk_threshold=4096)
    return Seed(p, (p,))


def _ros2bag(storage: str) -> Callable[[Path], Seed]:
    def make(d: Path) -> Seed:
        bag = write_bag2(d / "drive_bag", _ros_streams(), storage=storage)
        (target,) = (p for p in bag.iterdir() if p.suffix in (".db3", ".mcap"))
        return Seed(target, (bag,))

    return make


def _imu_csv(d: Path) -> Seed:
    """navreplay's own CSV export form: canonical column names, no mapping needed."""
    data = imu_data(200)
    lines = ["t_ns,acc_x_mps2,acc_y_mps2,acc_z_mps2,gyro_x_radps,gyro_y_radps,gyro_z_radps"]
    for t, a, g in zip(data.t_ns.tolist(), data.acc, data.gyro, strict=True):
        lines.append(f"{t},{a[0]:.6f},{a[1]:.6f},{a[2]:.6f},{g[0]:.7f},{g[1]:.7f},{g[2]:.7f}")
    p = d / "imu.csv"
    p.write_text("\n".join(lines) + "\n")
    return Seed(p, (p,))


T0_GPS_NS = gps_from_calendar("2026-11-18T02:30:00")
RX_LLA = (37.5, 127.0, 80.0)


def _sky() -> tuple[Any, pa.Table, np.ndarray]:
    """A nominal GPS constellation, 10 epochs of observations of every satellite above 10 deg
    from ``RX_LLA`` (1 Hz), and the receiver's ECEF position."""
    from navreplay.pipeline.synth.constellation import nominal_gps
    from navreplay.pipeline.synth.seoul_params import ConstellationParams

    cst = ConstellationParams(0.01, 0.0, 7200, 1e-4, 1e-12, 5e-9)
    eph = nominal_gps(T0_GPS_NS, T0_GPS_NS + 60 * NS_PER_S, cst, np.random.default_rng(5))
    rx = np.array(pymap3d.geodetic2ecef(*RX_LLA))
    names = ("t_ns", "sv", "pseudorange_m", "pseudorange_rate_mps", "cn0_dbhz")
    rows: dict[str, list[Any]] = {n: [] for n in (*names, "sat_x_m", "sat_y_m", "sat_z_m")}
    first = {int(p): i for i, p in reversed(list(enumerate(eph.prn.tolist())))}
    for k in range(10):
        t = T0_GPS_NS + k * NS_PER_S
        for prn, i in sorted(first.items()):
            pos = np.asarray(orbit(eph, i, t).pos_m).reshape(3)
            _, el, rng = pymap3d.ecef2aer(*pos, *RX_LLA)
            if el < 10.0:
                continue
            rows["t_ns"].append(t)
            rows["sv"].append(f"G{prn:02d}")
            rows["pseudorange_m"].append(round(float(rng) + 1234.5, 3))
            rows["pseudorange_rate_mps"].append(-round(100.0 * prn, 3) * LAMBDA_L1_M)
            rows["cn0_dbhz"].append(45.0)
            for axis, v in zip("xyz", pos.tolist(), strict=True):
                rows[f"sat_{axis}_m"].append(v)
    n = len(rows["t_ns"])
    rows["pseudorange_std_m"] = [3.0] * n
    rows["pseudorange_rate_std_mps"] = [0.1] * n
    return eph, from_columns("gnss_obs", {k: np.asarray(v) for k, v in rows.items()}), rx


def _rinex_pair(d: Path) -> tuple[Path, Path]:
    """``drive.obs`` (the project's RINEX 3.04 writer) and ``drive.nav``."""
    eph, obs, rx = _sky()
    station = rinex.Station("fuzz", (float(rx[0]), float(rx[1]), float(rx[2])))
    obs_path, nav_path = d / "drive.obs", d / "drive.nav"
    rinex.write_obs(obs_path, obs, station, interval_s=1.0)
    rinex.write_nav(nav_path, eph)
    return obs_path, nav_path


def _gnsslogger(d: Path) -> Seed:
    from .gnsslogs import write_gnsslogger

    eph, obs, _ = _sky()
    t = np.arange(5, dtype=np.int64) * 2 * NS_PER_S + T0_GPS_NS
    ones = np.ones(len(t))
    cols = {"t_ns": t, "lat_deg": RX_LLA[0] * ones, "lon_deg": RX_LLA[1] * ones}
    cols |= {"alt_m": RX_LLA[2] * ones, "vel_n_mps": 0 * ones, "vel_e_mps": 0 * ones}
    cols |= {"vel_d_mps": 0 * ones, "h_acc_m": 3 * ones, "fix_type": np.full(len(t), 3)}
    fix = from_columns("gnss", cols)
    log = d / "gnss_log.txt"
    write_gnsslogger(log, SimpleNamespace(tables={"gnss_obs": obs, "gnss": fix}), imu=False)
    nav = d / "brdc.nav"
    rinex.write_nav(nav, eph)
    return Seed(log, (log, nav))


def _gsdc(d: Path) -> Seed:
    """A 2022 GSDC ground_truth.csv (the competition's header, 1 Hz)."""
    lines = [
        "MessageType,Provider,LatitudeDegrees,LongitudeDegrees,AltitudeMeters,SpeedMps,"
        "AccuracyMeters,BearingDegrees,UnixTimeMillis"
    ]
    for k in range(20):
        lat = 37.4 + 1e-5 * k
        lines.append(f"Fix,GT,{lat:.8f},-122.1,10.5,1.1,0.1,0.0,{1_600_000_000_000 + 1000 * k}")
    p = d / "ground_truth.csv"
    p.write_text("\n".join(lines) + "\n")
    return Seed(p, (p,))


def _rinex_obs(d: Path) -> Seed:
    obs, nav = _rinex_pair(d)
    return Seed(obs, (obs, nav))


def _rinex_nav(d: Path) -> Seed:
    obs, nav = _rinex_pair(d)
    return Seed(nav, (obs, nav))


def _nmea(d: Path) -> Seed:
    start = dt.datetime(2020, 2, 7, 23, 59, 50)
    out: list[bytes] = []
    for k in range(20):
        when = start + dt.timedelta(seconds=k)
        lat, lon, _ = pymap3d.ned2geodetic(7.0 * k, 7.0 * k, 0.0, 37.4263937, -122.0936525, 0.0)
        where = {"lat": float(lat), "NS": "N", "lon": abs(float(lon)), "EW": "W"}
        speed_kn = 9.9 / (1852.0 / 3600.0)
        rmc = NMEAMessage(
            "GN", "RMC", GET, time=when.time(), status="A", **where, spd=speed_kn, cog=45.0,
            date=when.date(), posMode="A",
        )  # fmt: skip
        gga = NMEAMessage(
            "GN", "GGA", GET, time=when.time(), **where, quality=1, numSV=12, HDOP=0.7,
            alt=4.4, altUnit="M", sep=-30.0, sepUnit="M",
        )  # fmt: skip
        out += [rmc.serialize(), gga.serialize()]
    p = d / "drive.nmea"
    p.write_bytes(b"".join(out))
    return Seed(p, (p,))


def _librsf(d: Path) -> Seed:
    lines = []
    for k in range(20):
        t = 0.2 * k
        lines.append(f"odom3 {t:.14g} 5.0 0 0 0 0 0.1 0.0025 0.0009 0.0009 4e-06 4e-06 4e-06")
        x, y, z = pymap3d.geodetic2ecef(52.507, 13.374 + 1e-5 * k, 77.0)
        lines.append(f"point3 {t:.14g} {x:.3f} {y:.3f} {z:.3f}" + " 0" * 9)
    p = d / "run.txt"
    p.write_text("\n".join(lines) + "\n")
    return Seed(p, (p,))


def _comma2k19(d: Path) -> Seed:
    from .test_comma2k19 import write_segment

    seg = write_segment(d / "segment", seconds=2.0)
    return Seed(seg / "processed_log" / "IMU" / "accelerometer" / "value", (seg,))


SEEDS: dict[str, Callable[[Path], Seed]] = {
    "tlog": _tlog,
    "dataflash": _dataflash,
    "ulog": _ulog,
    "mcap": _mcap,
    "ros1bag": _ros1bag,
    "ros2bag_sqlite3": _ros2bag("sqlite3"),
    "ros2bag_mcap": _ros2bag("mcap"),
    "csv": _imu_csv,
    "rinex_obs": _rinex_obs,
    "rinex_nav": _rinex_nav,
    "gnsslogger": _gnsslogger,
    "gsdc": _gsdc,
    "nmea": _nmea,
    "librsf": _librsf,
    "comma2k19": _comma2k19,
}
