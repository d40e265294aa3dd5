"""The ``fwekf_reference`` datasets: paper 004's reference motion (eq. 33), IMU and GPS, as tlogs.

Paper 004 (section 5) gives the true position, velocity and acceleration along one axis of its
navigation frame, after a 20 s alignment at rest, with ``c = 20/pi``::

    r = 3/4 (t^2 - c^2 sin^2(t/c)),   v = 3/2 (t - c/2 sin(2t/c)),   a = 3 sin^2(t/c)   (eq. 33)

(``t`` counted from the end of the alignment; the three are consistent: v = r', a = v'). The
paper does not say which axis its second component is, nor where on the earth, nor the sensor
rates. Interpretation, all in ``synth.fwekf_reference``:

- the vehicle moves along a rhumb line with constant track ``track_deg`` (default 0: north,
  reading the paper's frame as East-North-Up, whose second axis is North), level, its body x
  axis along the track, at constant ellipsoidal height above an origin (default: KARI, Daejeon);
- ``accel_amplitude_mps2`` is eq. 33's 3 m/s^2 and ``accel_period_s`` the 20 s period of
  ``sin^2(t/c)`` (``c = accel_period_s / pi``);
- latitude and longitude are integrated along the track (RK4 at the IMU rate with the exact
  speed), and the IMU is derived from the motion with ``pipeline.nav.mechanization
  .imu_from_motion`` (WGS-84 normal gravity, earth rotation, transport rate), so forward
  integration of the noise-free IMU reproduces the truth;
- IMU at ``imu_rate_hz`` (default 100 Hz) with white noise sigma_omega, sigma_a per sample;
  GPS fixes at ``gnss_rate_hz`` (default 10 Hz; with sigma_r = 10 m a filter needs ~400 fixes
  to average position below the paper's 0.5 m, which 1 Hz cannot give in 40 s) with white
  noise sigma_r on each of N, E, D and sigma_v on each velocity component. No biases: the
  paper's two cases are noise-free and sigma_omega 0.0003 rad/s, sigma_a 0.003 m/s^2,
  sigma_r 10 m, sigma_v 0.2 m/s.

Two dataset ids: ``fwekf_reference`` (the noisy case) and ``fwekf_reference_noise_free``.
The log is a MAVLink tlog (HIGHRES_IMU, GPS_RAW_INT, SIMSTATE/SIM_STATE truth); its resolution
(1e-7 deg ~ 1.1 cm, 1 cm/s, float32 IMU) is the floor of the "noise-free" case.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pyarrow as pa

from navreplay.ingest.config import ImuNoise
from navreplay.ingest.meta import SensorMeta
from navreplay.ingest.schema import FixType, from_columns
from navreplay.ingest.typed import FieldError
from navreplay.ingest.writers.mavlink import (
    MAV_TYPE_FIXED_WING,
    as_logged_gnss,
    as_logged_imu,
    write_tlog,
)
from navreplay.pipeline.nav.earth import radii
from navreplay.pipeline.nav.local import LocalFrame
from navreplay.pipeline.nav.mechanization import NAV_DIM, imu_from_motion
from navreplay.pipeline.nav.rotations import euler_to_quat
from navreplay.pipeline.synth import SynthResult, SynthSection
from navreplay.pipeline.synth.checks import require_non_negative
from navreplay.pipeline.synth.columns import NED, axis_columns, imu_table
from navreplay.pipeline.synth.output import (
    check_dataset,
    dataset_rng,
    synth_params,
    write_dataset_dir,
)

F64 = npt.NDArray[np.float64]

DATASET = "fwekf_reference"
NOISE_FREE_DATASET = "fwekf_reference_noise_free"


@dataclass(frozen=True)
class FwekfNoise:
    """White noise, 1 sigma per sample (per axis / per component)."""

    gyro_radps: float = 0.0003
    accel_mps2: float = 0.003
    pos_m: float = 10.0
    vel_mps: float = 0.2

    def __post_init__(self) -> None:
        require_non_negative(self)


NO_NOISE = FwekfNoise(0.0, 0.0, 0.0, 0.0)


@dataclass(frozen=True)
class FwekfReferenceParams:
    """``synth.fwekf_reference`` (see the module docstring for the interpretation).

    Attributes:
        imu_rate_hz: IMU and truth rate.
        gnss_rate_hz: GPS fix rate; must divide the IMU rate.
        alignment_s: time at rest before the motion (paper: 20 s).
        motion_s: duration of the eq. 33 motion after the alignment.
        accel_amplitude_mps2: peak acceleration (paper: 3).
        accel_period_s: period of sin^2(t/c), i.e. pi c (paper: 20 s).
        track_deg: direction of the motion, clockwise from north.
        noise: the noisy case's sensor noise (the noise-free dataset uses none).
        origin: start point.
        start_unix_s: UNIX time of the first sample.
    """

    imu_rate_hz: int = 100
    gnss_rate_hz: int = 10
    alignment_s: float = 20.0
    motion_s: float = 60.0
    accel_amplitude_mps2: float = 3.0
    accel_period_s: float = 20.0
    track_deg: float = 0.0
    noise: FwekfNoise = field(default_factory=FwekfNoise)
    origin: LocalFrame = field(default_factory=lambda: LocalFrame(36.374, 127.358, 100.0))
    start_unix_s: int = 1795341600

    def __post_init__(self) -> None:
        if self.imu_rate_hz <= 0 or 1_000_000 % self.imu_rate_hz:
            raise FieldError("imu_rate_hz", "must be > 0 and divide 1e6 us evenly")
        if self.gnss_rate_hz <= 0 or self.imu_rate_hz % self.gnss_rate_hz:
            raise FieldError("gnss_rate_hz", "must be > 0 and divide imu_rate_hz")
        if self.alignment_s < 0 or self.motion_s <= 0:
            raise FieldError("motion_s", "alignment_s >= 0 and motion_s > 0 are required")
        if self.accel_period_s <= 0:
            raise FieldError("accel_period_s", "must be > 0")

    @property
    def c_s(self) -> float:
        """Eq. 33's ``c`` (paper: 20/pi)."""
        return self.accel_period_s / math.pi


def motion(params: FwekfReferenceParams, t_s: F64) -> tuple[F64, F64, F64]:
    """Distance (m), speed (m/s) and acceleration (m/s^2) along the track at ``t_s`` (eq. 33).

    ``t_s`` counts from the first sample; the vehicle rests until ``alignment_s``.
    """
    a0, c = params.accel_amplitude_mps2, params.c_s
    tau = np.maximum(np.asarray(t_s, dtype=np.float64) - params.alignment_s, 0.0)
    s = np.sin(tau / c)
    dist = a0 / 4.0 * (tau**2 - c**2 * s**2)
    speed = a0 / 2.0 * (tau - c / 2.0 * np.sin(2.0 * tau / c))
    accel = a0 * s**2
    return dist, speed, accel


def _geodetic_track(params: FwekfReferenceParams, t_s: F64) -> tuple[F64, F64]:
    """Latitude and longitude (rad) along the rhumb line, RK4 with the exact speed."""
    chi = math.radians(params.track_deg)
    cx, sx = math.cos(chi), math.sin(chi)
    h = params.origin.alt_m

    def rate(lat: float, speed: float) -> tuple[float, float]:
        rm, rn = radii(lat)
        return speed * cx / (rm + h), speed * sx / ((rn + h) * math.cos(lat))

    n = t_s.size
    lat = np.empty(n)
    lon = np.empty(n)
    lat[0], lon[0] = math.radians(params.origin.lat_deg), math.radians(params.origin.lon_deg)
    mid = 0.5 * (t_s[:-1] + t_s[1:])
    _, v_nodes, _ = motion(params, t_s)
    _, v_mid, _ = motion(params, mid)
    for i in range(n - 1):
        dt = t_s[i + 1] - t_s[i]
        p, q = lat[i], lon[i]
        k1 = rate(p, v_nodes[i])
        k2 = rate(p + 0.5 * dt * k1[0], v_mid[i])
        k3 = rate(p + 0.5 * dt * k2[0], v_mid[i])
        k4 = rate(p + dt * k3[0], v_nodes[i + 1])
        lat[i + 1] = p + dt / 6.0 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
        lon[i + 1] = q + dt / 6.0 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
    return lat, lon


def trajectory(params: FwekfReferenceParams) -> dict[str, F64]:
    """Truth and the error-free IMU at every IMU sample.

    Returns:
        ``t_s``, ``lat_rad``, ``lon_rad``, ``alt_m``, ``vel_ned_mps`` (n, 3), ``q_wxyz`` (n, 4),
        ``yaw_rad``, ``dist_m``, ``acc_mps2`` (n, 3) and ``gyro_radps`` (n, 3), body FRD.
    """
    n = round((params.alignment_s + params.motion_s) * params.imu_rate_hz) + 1
    t_s = np.arange(n) / params.imu_rate_hz
    dist, speed, accel = motion(params, t_s)
    lat, lon = _geodetic_track(params, t_s)
    chi = math.radians(params.track_deg)
    direction = np.array([math.cos(chi), math.sin(chi), 0.0])
    vel = speed[:, None] * direction
    q = euler_to_quat(0.0, 0.0, chi)
    acc = np.empty((n, 3))
    gyro = np.empty((n, 3))
    x = np.empty(NAV_DIM)
    x[2] = params.origin.alt_m
    x[6:10] = q
    no_rotation = np.zeros(3)
    for i in range(n):
        x[0], x[1] = lat[i], lon[i]
        x[3:6] = vel[i]
        acc[i], gyro[i] = imu_from_motion(x, accel[i] * direction, no_rotation)
    return {
        "t_s": t_s,
        "lat_rad": lat,
        "lon_rad": lon,
        "alt_m": np.full(n, params.origin.alt_m),
        "vel_ned_mps": vel,
        "q_wxyz": np.tile(q, (n, 1)),
        "yaw_rad": np.full(n, (chi + math.pi) % (2 * math.pi) - math.pi),
        "dist_m": dist,
        "acc_mps2": acc,
        "gyro_radps": gyro,
    }


def _t_ns(params: FwekfReferenceParams, t_s: F64) -> npt.NDArray[np.int64]:
    step_us = 1_000_000 // params.imu_rate_hz
    k = np.rint(t_s * params.imu_rate_hz).astype(np.int64)
    out: npt.NDArray[np.int64] = (params.start_unix_s * 1_000_000 + k * step_us) * 1000
    return out


def raw_tables(
    params: FwekfReferenceParams, seed: int, *, noise_free: bool = False
) -> dict[str, pa.Table]:
    """Canonical tables at full precision, before logging: imu, gnss, truth, truth_imu.

    ``truth_imu`` is the error-free IMU at the truth samples (for the tlog's truth messages).
    """
    noise = NO_NOISE if noise_free else params.noise
    rng = dataset_rng(seed, NOISE_FREE_DATASET if noise_free else DATASET)
    tr = trajectory(params)
    n = tr["t_s"].size
    t_ns = _t_ns(params, tr["t_s"])
    acc = tr["acc_mps2"] + noise.accel_mps2 * rng.standard_normal((n, 3))
    gyro = tr["gyro_radps"] + noise.gyro_radps * rng.standard_normal((n, 3))

    idx = np.arange(0, n, params.imu_rate_hz // params.gnss_rate_hz)
    m = idx.size
    dpos = noise.pos_m * rng.standard_normal((m, 3))
    dvel = noise.vel_mps * rng.standard_normal((m, 3))
    lat = tr["lat_rad"][idx]
    h = tr["alt_m"][idx]
    rm, rn = np.vectorize(radii)(lat)
    gnss = from_columns(
        "gnss",
        {
            "t_ns": t_ns[idx],
            "lat_deg": np.degrees(lat + dpos[:, 0] / (rm + h)),
            "lon_deg": np.degrees(tr["lon_rad"][idx] + dpos[:, 1] / ((rn + h) * np.cos(lat))),
            "alt_m": h - dpos[:, 2],
            "vel_n_mps": tr["vel_ned_mps"][idx, 0] + dvel[:, 0],
            "vel_e_mps": tr["vel_ned_mps"][idx, 1] + dvel[:, 1],
            "vel_d_mps": tr["vel_ned_mps"][idx, 2] + dvel[:, 2],
            "h_acc_m": np.full(m, max(noise.pos_m, 0.01)),
            "v_acc_m": np.full(m, max(noise.pos_m, 0.01)),
            "speed_acc_mps": np.full(m, max(noise.vel_mps, 0.01)),
            "fix_type": np.full(m, FixType.FIX_3D, dtype=np.int8),
            "num_sats": pa.nulls(m, pa.int16()),
        },
    )
    vel = tr["vel_ned_mps"]
    truth = from_columns(
        "truth",
        {
            "t_ns": t_ns,
            "lat_deg": np.degrees(tr["lat_rad"]),
            "lon_deg": np.degrees(tr["lon_rad"]),
            "alt_m": tr["alt_m"],
            **axis_columns("vel_{}_mps", vel, NED),
            "roll_rad": np.zeros(n),
            "pitch_rad": np.zeros(n),
            "yaw_rad": tr["yaw_rad"],
            "track_distance_m": tr["dist_m"],
        },
    )
    return {
        "imu": imu_table(t_ns, acc, gyro),
        "gnss": gnss,
        "truth": truth,
        "truth_imu": imu_table(t_ns, tr["acc_mps2"], tr["gyro_radps"]),
    }


def sensor_meta(params: FwekfReferenceParams, *, noise_free: bool = False) -> SensorMeta:
    """The IMU noise densities of the noisy case (per-sample sigma / sqrt(rate)), no biases.

    The noise-free case declares no model (None): a zero process noise is not a usable filter
    tuning, so the filters keep their own.
    """
    if noise_free:
        return SensorMeta()
    noise = params.noise
    root = math.sqrt(params.imu_rate_hz)
    return SensorMeta(
        imu_noise=ImuNoise(noise.accel_mps2 / root, noise.gyro_radps / root, 0.0, 0.0, 0.0, 0.0)
    )


def synthesize(params: FwekfReferenceParams, seed: int, *, noise_free: bool = False) -> SynthResult:
    """One noise case of ``fwekf_reference`` in memory: imu and gnss as the tlog holds them,
    truth at full precision."""
    raw = raw_tables(params, seed, noise_free=noise_free)
    return _result(params, raw, noise_free=noise_free)


def _result(
    params: FwekfReferenceParams, raw: dict[str, pa.Table], *, noise_free: bool
) -> SynthResult:
    """imu and gnss of ``raw_tables`` as the tlog holds them, truth at full precision."""
    tables = {
        "imu": as_logged_imu(raw["imu"]),
        "gnss": as_logged_gnss(raw["gnss"]),
        "truth": raw["truth"],
    }
    return SynthResult(tables, sensor_meta(params, noise_free=noise_free), time_base="utc")


def write(
    params: FwekfReferenceParams, seed: int, out_dir: str | Path, *, noise_free: bool = False
) -> list[Path]:
    """Write ``<dataset>.tlog`` and ``reference/`` as the folder ``out_dir``; returns the files."""
    dataset = NOISE_FREE_DATASET if noise_free else DATASET
    raw = raw_tables(params, seed, noise_free=noise_free)

    def write_logs(folder: Path) -> list[tuple[Path, str]]:
        tlog = folder / f"{dataset}.tlog"
        write_tlog(
            tlog,
            imu=raw["imu"],
            gnss=raw["gnss"],
            truth=raw["truth"],
            truth_imu=raw["truth_imu"],
            mav_type=MAV_TYPE_FIXED_WING,
        )
        return [(tlog, "mavlink_tlog")]

    result = _result(params, raw, noise_free=noise_free)
    noise_case = params if not noise_free else dataclasses.replace(params, noise=NO_NOISE)
    plain = synth_params(seed, DATASET, noise_case)
    return write_dataset_dir(out_dir, dataset, result, write_logs, params=plain)


def write_dataset(name: str, synth: SynthSection, out_dir: Path) -> list[Path]:
    """The synth registry's entry point: either noise case from ``params.synth``."""
    check_dataset(__name__, name, DATASET, NOISE_FREE_DATASET)
    return write(synth.fwekf_reference, synth.seed, out_dir, noise_free=name == NOISE_FREE_DATASET)
