"""A small seoul_campus-type drive for the estimation tests (until the synthesizer lands).

The truth is a land vehicle on flat ground near the SNU campus: a static start, then a speed
profile and yaw-rate profile with clockwise and counter-clockwise turns; no sideslip, so the
non-holonomic constraint holds exactly. The IMU is the exact inverse of the mechanization
(``imu_from_motion``) plus white noise and random-walk biases; GNSS fixes are the antenna
position and velocity plus white noise; the satellites fly circular 26,560 km orbits and give
pseudoranges and rates of the antenna with a random-walk receiver clock.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache

import numba as nb
import numpy as np
import pyarrow as pa

from ingest.config import ImuNoise
from ingest.meta import SensorMeta
from ingest.schema import from_columns
from pipeline.nav import earth
from pipeline.nav.earth import F64
from pipeline.nav.mechanization import imu_from_motion
from pipeline.nav.rotations import euler_to_quat, quat_to_dcm

NOISE = ImuNoise(
    accel_noise_mps2_rthz=0.002,
    gyro_noise_radps_rthz=2e-4,
    accel_bias_sigma_mps2=0.05,
    gyro_bias_sigma_radps=2e-3,
    accel_bias_rw_mps3_rthz=1e-4,
    gyro_bias_rw_radps2_rthz=1e-5,
)


@dataclass(frozen=True)
class DriveSpec:
    duration_s: float = 60.0
    static_s: float = 4.0
    speed_mps: float = 10.0
    imu_hz: int = 100
    gnss_hz: int = 1
    n_sats: int = 8
    lever_arm_m: tuple[float, float, float] = (0.6, 0.2, -1.2)
    noise: ImuNoise = field(default=NOISE)
    fix_sigma_h_m: float = 1.5
    fix_sigma_v_m: float = 2.5
    fix_sigma_vel_mps: float = 0.1
    pr_sigma_m: float = 2.0
    prr_sigma_mps: float = 0.05
    clock_bias_psd: float = 0.1
    clock_drift_psd: float = 0.01
    turn_rate_radps: float = 0.25


@dataclass(frozen=True)
class CleanDrive:
    t_ns: np.ndarray
    nav: np.ndarray  # (N, 10) truth navigation state
    vdot_n: np.ndarray
    w_nb_b: np.ndarray


def _smooth(x: F64) -> F64:
    """C1 smoothstep on [0, 1] and its derivative."""
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3 - 2 * x)


def _dsmooth(x: F64) -> F64:
    inside = (x > 0) & (x < 1)
    return np.where(inside, 6 * x * (1 - x), 0.0)


def _profiles(spec: DriveSpec, t: np.ndarray) -> tuple[F64, F64, F64, F64]:
    """Speed, its derivative, yaw rate and its integral (yaw) on the sample times."""
    ramp = 6.0
    u = (t - spec.static_s) / ramp
    speed = spec.speed_mps * _smooth(u)
    dspeed = spec.speed_mps * _dsmooth(u) / ramp
    # turns: alternating left/right arcs, each 8 s with smooth entry and exit, 4 s straights
    period = 24.0
    tt = np.maximum(t - spec.static_s - ramp, 0.0)
    phase = np.mod(tt, period)
    sign = np.where(np.floor(tt / period) % 2 == 0, 1.0, -1.0)
    bump = np.where(phase < 8.0, np.sin(np.pi * phase / 8.0) ** 2, 0.0)
    rate = spec.turn_rate_radps * sign * bump * (tt > 0)
    dt = np.diff(t, prepend=t[0])
    yaw0 = 0.4
    yaw = yaw0 + np.cumsum(0.5 * (rate + np.roll(rate, 1)) * dt * (np.arange(t.size) > 0))
    return speed, dspeed, rate, yaw


@nb.njit(cache=True)
def _imu(nav: F64, vdot: F64, w_nb: F64) -> F64:
    out = np.empty((nav.shape[0], 6))
    for k in range(nav.shape[0]):
        f, w = imu_from_motion(nav[k], vdot[k], w_nb[k])
        out[k, :3] = f
        out[k, 3:] = w
    return out


@lru_cache(maxsize=4)
def clean_drive(spec: DriveSpec) -> tuple[CleanDrive, np.ndarray]:
    """The noise-free truth and its exact IMU."""
    n = int(spec.duration_s * spec.imu_hz) + 1
    t_ns = np.arange(n, dtype=np.int64) * (1_000_000_000 // spec.imu_hz)
    t = t_ns * 1e-9
    speed, dspeed, rate, yaw = _profiles(spec, t)
    vn, ve = speed * np.cos(yaw), speed * np.sin(yaw)
    vdot = np.column_stack(
        [
            dspeed * np.cos(yaw) - speed * rate * np.sin(yaw),
            dspeed * np.sin(yaw) + speed * rate * np.cos(yaw),
            np.zeros(n),
        ]
    )
    lat0, lon0, h = math.radians(37.4596), math.radians(126.9516), 80.0
    rm, _ = earth.radii(lat0)
    lat = lat0 + np.concatenate([[0.0], np.cumsum(0.5 * (vn[1:] + vn[:-1]) * np.diff(t))]) / (
        rm + h
    )
    rm_k = np.array([earth.radii(x)[0] for x in lat[:: max(1, n // 200)]])
    rm_i = np.interp(np.arange(n), np.arange(n)[:: max(1, n // 200)], rm_k)
    rn_i = np.array([earth.radii(x)[1] for x in lat[:: max(1, n // 200)]])
    rn_i = np.interp(np.arange(n), np.arange(n)[:: max(1, n // 200)], rn_i)
    dlat = vn / (rm_i + h)
    lat = lat0 + np.concatenate([[0.0], np.cumsum(0.5 * (dlat[1:] + dlat[:-1]) * np.diff(t))])
    dlon = ve / ((rn_i + h) * np.cos(lat))
    lon = lon0 + np.concatenate([[0.0], np.cumsum(0.5 * (dlon[1:] + dlon[:-1]) * np.diff(t))])
    nav = np.zeros((n, 10))
    nav[:, 0], nav[:, 1], nav[:, 2] = lat, lon, h
    nav[:, 3], nav[:, 4] = vn, ve
    for k in range(n):
        nav[k, 6:10] = euler_to_quat(0.0, 0.0, yaw[k])
    w_nb = np.column_stack([np.zeros(n), np.zeros(n), rate])
    imu = _imu(nav, vdot, w_nb)
    return CleanDrive(t_ns, nav, vdot, w_nb), imu


def _satellites(spec: DriveSpec, rng: np.random.Generator, lat: float, lon: float) -> F64:
    """Orbit elements: (n_sats, 4) of initial ECI position direction and plane angles."""
    r_rx = earth.geodetic_to_ecef(lat, lon, 80.0)
    c_en = earth.dcm_ecef_to_ned(lat, lon)
    radius = 26_560e3
    sats = []
    for k in range(spec.n_sats):
        az = 2 * math.pi * k / spec.n_sats + rng.uniform(-0.3, 0.3)
        el = math.radians(rng.uniform(20, 80))
        los_n = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), -math.sin(el)])
        los_e = c_en.T @ los_n
        b = float(r_rx @ los_e)
        rng_m = -b + math.sqrt(b * b - (r_rx @ r_rx - radius**2))
        p0 = r_rx + rng_m * los_e
        u = p0 / np.linalg.norm(p0)
        a = rng.normal(size=3)
        w = np.cross(u, a)
        w /= np.linalg.norm(w)
        sats.append(np.concatenate([u, w]))
    return np.array(sats)


def _sat_state(elems: F64, t: float) -> tuple[F64, F64]:
    """ECEF position and velocity of every satellite at time t."""
    radius = 26_560e3
    nmot = math.sqrt(earth.GM / radius**3)
    u, w = elems[:, :3], elems[:, 3:]
    ang = nmot * t
    r_i = radius * (np.cos(ang) * u + np.sin(ang) * w)
    v_i = radius * nmot * (-np.sin(ang) * u + np.cos(ang) * w)
    th = earth.OMEGA_IE * t
    c, s = math.cos(th), math.sin(th)
    rot = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])  # ECI -> ECEF
    r_e = r_i @ rot.T
    omega = np.array([0.0, 0.0, earth.OMEGA_IE])
    v_e = v_i @ rot.T - np.cross(omega, r_e)
    return r_e, v_e


def simulate(spec: DriveSpec, seed: int) -> tuple[dict[str, pa.Table], SensorMeta]:
    """Canonical tables (imu, gnss, gnss_obs, truth) and sensor metadata of one noisy run."""
    rng = np.random.default_rng(seed)
    clean, imu_clean = clean_drive(spec)
    t_ns, nav = clean.t_ns, clean.nav
    n = t_ns.size
    dt = 1.0 / spec.imu_hz
    nz = spec.noise
    ba = rng.normal(0, nz.accel_bias_sigma_mps2, 3) + np.cumsum(
        rng.normal(0, nz.accel_bias_rw_mps3_rthz * math.sqrt(dt), (n, 3)), axis=0
    )
    bg = rng.normal(0, nz.gyro_bias_sigma_radps, 3) + np.cumsum(
        rng.normal(0, nz.gyro_bias_rw_radps2_rthz * math.sqrt(dt), (n, 3)), axis=0
    )
    imu = imu_clean.copy()
    imu[:, :3] += ba + rng.normal(0, nz.accel_noise_mps2_rthz / math.sqrt(dt), (n, 3))
    imu[:, 3:] += bg + rng.normal(0, nz.gyro_noise_radps_rthz / math.sqrt(dt), (n, 3))
    cd = 1.5 + np.cumsum(rng.normal(0, math.sqrt(spec.clock_drift_psd * dt), n))
    cb = 300.0 + np.cumsum(cd * dt + rng.normal(0, math.sqrt(spec.clock_bias_psd * dt), n))
    lever = np.array(spec.lever_arm_m)
    step = spec.imu_hz // spec.gnss_hz
    gi = np.arange(0, n, step)
    ant_llh, ant_vel, ant_ecef, ant_vecef = [], [], [], []
    for k in gi:
        c = quat_to_dcm(nav[k, 6:10])
        ln = c @ lever
        rm, rn = earth.radii(nav[k, 0])
        lat = nav[k, 0] + ln[0] / (rm + nav[k, 2])
        lon = nav[k, 1] + ln[1] / ((rn + nav[k, 2]) * math.cos(nav[k, 0]))
        h = nav[k, 2] - ln[2]
        w_ie = np.array([earth.OMEGA_IE * math.cos(lat), 0, -earth.OMEGA_IE * math.sin(lat)])
        w_eb = (imu_clean[k, 3:]) - c.T @ w_ie
        v = nav[k, 3:6] + c @ np.cross(w_eb, lever)
        ant_llh.append((lat, lon, h))
        ant_vel.append(v)
        ant_ecef.append(earth.geodetic_to_ecef(lat, lon, h))
        ant_vecef.append(earth.dcm_ecef_to_ned(lat, lon).T @ v)
    ant_llh_a, ant_vel_a = np.array(ant_llh), np.array(ant_vel)
    m = gi.size
    rm0, rn0 = earth.radii(nav[0, 0])
    e_n = rng.normal(0, spec.fix_sigma_h_m, m)
    e_e = rng.normal(0, spec.fix_sigma_h_m, m)
    e_d = rng.normal(0, spec.fix_sigma_v_m, m)
    gnss = from_columns(
        "gnss",
        {
            "t_ns": t_ns[gi],
            "lat_deg": np.degrees(ant_llh_a[:, 0] + e_n / (rm0 + 80)),
            "lon_deg": np.degrees(ant_llh_a[:, 1] + e_e / ((rn0 + 80) * math.cos(nav[0, 0]))),
            "alt_m": ant_llh_a[:, 2] - e_d,
            "vel_n_mps": ant_vel_a[:, 0] + rng.normal(0, spec.fix_sigma_vel_mps, m),
            "vel_e_mps": ant_vel_a[:, 1] + rng.normal(0, spec.fix_sigma_vel_mps, m),
            "vel_d_mps": ant_vel_a[:, 2] + rng.normal(0, spec.fix_sigma_vel_mps, m),
            "h_acc_m": np.full(m, spec.fix_sigma_h_m),
            "v_acc_m": np.full(m, spec.fix_sigma_v_m),
            "speed_acc_mps": np.full(m, spec.fix_sigma_vel_mps),
            "fix_type": np.full(m, 3),
            "num_sats": np.full(m, spec.n_sats),
        },
    )
    elems = _satellites(spec, np.random.default_rng(12345), nav[0, 0], nav[0, 1])
    cols: dict[str, list[object]] = {
        k: []
        for k in [
            "t_ns",
            "sv",
            "pseudorange_m",
            "pseudorange_rate_mps",
            "sat_x_m",
            "sat_y_m",
            "sat_z_m",
            "sat_vx_mps",
            "sat_vy_mps",
            "sat_vz_mps",
            "elevation_deg",
            "pseudorange_std_m",
            "pseudorange_rate_std_mps",
        ]
    }
    for j, k in enumerate(gi):
        r_s, v_s = _sat_state(elems, t_ns[k] * 1e-9)
        for s in range(spec.n_sats):
            d = r_s[s] - ant_ecef[j]
            rho = float(np.linalg.norm(d))
            e = d / rho
            los_n = earth.dcm_ecef_to_ned(ant_llh_a[j, 0], ant_llh_a[j, 1]) @ e
            cols["t_ns"].append(int(t_ns[k]))
            cols["sv"].append(f"G{s + 1:02d}")
            cols["pseudorange_m"].append(rho + cb[k] + rng.normal(0, spec.pr_sigma_m))
            cols["pseudorange_rate_mps"].append(
                float(e @ (v_s[s] - ant_vecef[j])) + cd[k] + rng.normal(0, spec.prr_sigma_mps)
            )
            for ax, name in enumerate("xyz"):
                cols[f"sat_{name}_m"].append(r_s[s, ax])
                cols[f"sat_v{name}_mps"].append(v_s[s, ax])
            cols["elevation_deg"].append(math.degrees(math.asin(-los_n[2])))
            cols["pseudorange_std_m"].append(spec.pr_sigma_m)
            cols["pseudorange_rate_std_mps"].append(spec.prr_sigma_mps)
    obs = from_columns("gnss_obs", {k: np.asarray(v) for k, v in cols.items()})
    from pipeline.nav.rotations import quat_to_euler

    rpy = np.array([quat_to_euler(q) for q in nav[:, 6:10]])
    truth = from_columns(
        "truth",
        {
            "t_ns": t_ns,
            "lat_deg": np.degrees(nav[:, 0]),
            "lon_deg": np.degrees(nav[:, 1]),
            "alt_m": nav[:, 2],
            "vel_n_mps": nav[:, 3],
            "vel_e_mps": nav[:, 4],
            "vel_d_mps": nav[:, 5],
            "roll_rad": rpy[:, 0],
            "pitch_rad": rpy[:, 1],
            "yaw_rad": rpy[:, 2],
            "acc_bias_x_mps2": ba[:, 0],
            "acc_bias_y_mps2": ba[:, 1],
            "acc_bias_z_mps2": ba[:, 2],
            "gyro_bias_x_radps": bg[:, 0],
            "gyro_bias_y_radps": bg[:, 1],
            "gyro_bias_z_radps": bg[:, 2],
            "clock_bias_m": cb,
            "clock_drift_mps": cd,
        },
    )
    imu_t = from_columns(
        "imu",
        {
            "t_ns": t_ns,
            "acc_x_mps2": imu[:, 0],
            "acc_y_mps2": imu[:, 1],
            "acc_z_mps2": imu[:, 2],
            "gyro_x_radps": imu[:, 3],
            "gyro_y_radps": imu[:, 4],
            "gyro_z_radps": imu[:, 5],
        },
    )
    sensors = SensorMeta(imu_noise=spec.noise, lever_arm_m=spec.lever_arm_m)
    return {"imu": imu_t, "gnss": gnss, "gnss_obs": obs, "truth": truth}, sensors
