"""The ``multirotor_flight`` and ``bench_static`` datasets: a quadrotor's MAVLink tlog.

``multirotor_flight`` (``synth.multirotor_flight``, defaults in
``pipeline.synth.multirotor_params``) is a flight of 177 s whose heading is not its course:

1. 20 s at rest on the ground, armed (heading 30 deg);
2. vertical take-off to 10 m at 2 m/s, 5 s hover;
3. yaw in place by 180 deg in 8 s (peak 42 deg/s), 3 s hover;
4. sideways at 4 m/s (body y along the track: course = yaw + 90 deg) for 14 s, 3 s hover;
5. backwards at 3 m/s (course = yaw + 180 deg) for 12 s, 3 s hover;
6. two figure eights (60 m long, 2 m up and down, 3.7-8 m/s once at speed, up to 2.5 m/s^2
   of horizontal acceleration and 14 deg of tilt) in 73 s, yawing by -90 deg in their middle;
7. 5 s hover, landing at 1.5 m/s, 15 s at rest on the ground.

The motion is built from C2 profiles of time (``pipeline.synth.profile``): the NED velocity of
the vertical and straight legs, the phase ``s`` of the eights (``A [sin s, sin(2 s)/2]`` along
and across their axis, ``-dz sin s`` down) and the yaw. Position, velocity, acceleration and
jerk are exact derivatives of one another (polynomials, and the chain rule through ``s``).
The attitude is a multirotor's: the thrust axis (body -z) along the specific force w.r.t. the
local level ``a - g`` (normal gravity at the take-off point; the Coriolis and transport terms,
~1e-3 m/s^2, are left out), so the roll and pitch come from the horizontal acceleration and the
yaw is free; the body rate w.r.t. NED follows analytically from the jerk and the yaw rate
(ZYX Euler kinematics). Latitude, longitude and height are the NED velocity integrated with
Simpson's rule (``trajectory.integrate_geodetic``); ``imu.ideal_imu`` gives the exact IMU, so
the noise-free IMU integrates back onto the truth.

Sensors: consumer MEMS IMU at 200 Hz (``imu.corrupt``: white noise, bias random walk, 0.2 %
scale factors; fixed turn-on biases of 0.05-0.08 m/s^2 and 0.15-0.25 deg/s per axis from
``turn_on_bias``, where the declared noise model says 0.08 m/s^2 and 0.2 deg/s 1-sigma); a
magnetometer with every IMU sample, ``C_n^b B_n + hard_iron + noise`` in gauss, ``B_n`` the
WMM2025 field of the place (``MagParams``); GPS fixes at 5 Hz of the antenna (12 cm above the
IMU): Gauss-Markov position errors (1 m horizontal, 1.8 m vertical, 20 s), white velocity noise
0.1 m/s, reported as ``h_acc``, ``v_acc`` and ``vel_acc``.

``bench_static`` is the same vehicle and sensors at rest on a slightly tilted bench for 60 s,
disarmed, its receiver reporting no fix (fix type 1, 3 satellites, lat/lon 0).

The tlog (``ingest.writers.mavlink``): HEARTBEAT type MAV_TYPE_QUADROTOR, autopilot ArduPilot
(armed in the flight), HIGHRES_IMU with ``xmag/ymag/zmag`` (``fields_updated`` 0x1FF),
GPS_RAW_INT, and the truth as SIM_STATE only (position, NED velocity and attitude; SIMSTATE,
which has no altitude or velocity, is not written) at 50 Hz. The reference truth table also
holds the true IMU biases (``acc_bias_*_mps2``, ``gyro_bias_*_radps``).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import NamedTuple

import numpy as np
import numpy.typing as npt
import pyarrow as pa
from scipy.interpolate import PPoly

from navreplay.ingest.meta import SensorMeta
from navreplay.ingest.platform import Platform
from navreplay.ingest.schema import FixType, from_columns
from navreplay.ingest.writers.mavlink import (
    MAV_TYPE_QUADROTOR,
    as_logged_gnss,
    as_logged_imu,
    write_tlog,
)
from navreplay.pipeline.nav import earth
from navreplay.pipeline.synth import SynthResult, SynthSection
from navreplay.pipeline.synth.columns import NED, axis_columns, imu_table
from navreplay.pipeline.synth.gnss import antenna
from navreplay.pipeline.synth.imu import corrupt, ideal_imu
from navreplay.pipeline.synth.multirotor_params import FlightPlan, MultirotorFlightParams
from navreplay.pipeline.synth.output import (
    check_dataset,
    dataset_rng,
    synth_params,
    write_dataset_dir,
)
from navreplay.pipeline.synth.profile import ProfileBuilder
from navreplay.pipeline.synth.trajectory import Motion, integrate_geodetic, quats_from_rpy

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]

DATASET = "multirotor_flight"
BENCH_DATASET = "bench_static"
PLATFORM = Platform("multirotor", "synthesized quadrotor (HEARTBEAT type 2)")


class Phase(NamedTuple):
    """One phase of the flight: what the vehicle does from ``start_s`` to ``end_s``."""

    name: str
    start_s: float
    end_s: float


class FlightProfiles(NamedTuple):
    """The flight as C2 profiles of time (``PPoly``, seconds from the first sample).

    Attributes:
        vel_ned: NED velocity of the vertical and straight legs (the eights add theirs).
        eight_rate: the rate of the eights' phase ``s``, rad/s.
        yaw: heading, rad (unwrapped).
        phases: the phases in order.
        end_s: when the last phase ends.
    """

    vel_ned: tuple[PPoly, PPoly, PPoly]
    eight_rate: PPoly
    yaw: PPoly
    phases: tuple[Phase, ...]
    end_s: float


def build_profiles(plan: FlightPlan) -> FlightProfiles:
    """The profiles of the flight ``plan`` (phases in the order of ``FlightPlan``)."""
    vn, ve, vd, rate = ProfileBuilder(), ProfileBuilder(), ProfileBuilder(), ProfileBuilder()
    yaw = ProfileBuilder(value=math.radians(plan.yaw0_deg))
    every = (vn, ve, vd, rate, yaw)
    phases: list[Phase] = []

    def step(name: str, dt: float, targets: dict[int, float] | None = None) -> None:
        """Ramp the builders named by index in ``targets`` over ``dt``, hold the others."""
        if dt <= 0.0:
            return
        start = vn.t
        for i, b in enumerate(every):
            if targets is not None and i in targets:
                b.ramp(targets[i], dt)
            else:
                b.hold(dt)
        if phases and phases[-1].name == name:
            phases[-1] = Phase(name, phases[-1].start_s, vn.t)
        else:
            phases.append(Phase(name, start, vn.t))

    def leg(name: str, course: float, speed: float, hold_s: float) -> None:
        ramp = plan.speed_ramp_s
        step(name, ramp, {0: speed * math.cos(course), 1: speed * math.sin(course)})
        step(name, hold_s)
        step(name, ramp, {0: 0.0, 1: 0.0})

    def vertical(name: str, rate_mps: float) -> None:
        ramp = plan.vertical_ramp_s
        step(name, ramp, {2: rate_mps})
        step(name, (plan.climb_m - abs(rate_mps) * ramp) / abs(rate_mps))
        step(name, ramp, {2: 0.0})

    step("ground", plan.ground_s)
    vertical("take-off", -plan.climb_rate_mps)
    step("hover", plan.hover_s)
    step("yaw in place", plan.yaw_turn_s, {4: yaw.value + math.radians(plan.yaw_turn_deg)})
    step("hover", plan.pause_s)
    leg("sideways", yaw.value + math.pi / 2, plan.sideways_speed_mps, plan.sideways_s)
    step("hover", plan.pause_s)
    leg("backwards", yaw.value + math.pi, plan.backwards_speed_mps, plan.backwards_s)
    step("hover", plan.pause_s)
    _eights(plan, every, phases)
    step("hover", plan.hover_s)
    vertical("landing", plan.descent_rate_mps)
    step("landed", plan.landed_s)
    end = vn.t
    return FlightProfiles(
        (vn.build(end), ve.build(end), vd.build(end)),
        rate.build(end),
        yaw.build(end),
        tuple(phases),
        end,
    )


def _eights(plan: FlightPlan, every: tuple[ProfileBuilder, ...], phases: list[Phase]) -> None:
    """The eights: the phase rate ramps up, holds, ramps down (``2 pi eights`` in all); the
    yaw turns by ``eight_yaw_turn_deg`` in their middle; the velocity profiles hold."""
    vn, ve, vd, rate, yaw = every
    start, total, ramp = vn.t, plan.eights_s, plan.eight_ramp_s
    for b in (vn, ve, vd):
        b.hold(total)
    rate.ramp(plan.eight_rate_radps, ramp)
    rate.hold(total - 2.0 * ramp)
    rate.ramp(0.0, ramp)
    before = 0.5 * (total - plan.eight_yaw_turn_s)
    yaw.hold(before)
    yaw.ramp(yaw.value + math.radians(plan.eight_yaw_turn_deg), plan.eight_yaw_turn_s)
    yaw.hold(total - before - plan.eight_yaw_turn_s)
    phases.append(Phase("figure eights", start, vn.t))


class Kinematics(NamedTuple):
    """Position (from the take-off point), velocity, acceleration and jerk, NED, (n, 3)."""

    pos: F64
    vel: F64
    acc: F64
    jerk: F64


def kinematics(prof: FlightProfiles, plan: FlightPlan, t_s: F64) -> Kinematics:
    """The exact local-level motion at ``t_s``: the legs' polynomials plus the eights."""
    t = np.asarray(t_s, dtype=np.float64)
    pos = np.stack([pp.antiderivative()(t) for pp in prof.vel_ned], axis=-1)
    vel = np.stack([pp(t) for pp in prof.vel_ned], axis=-1)
    acc = np.stack([pp.derivative()(t) for pp in prof.vel_ned], axis=-1)
    jerk = np.stack([pp.derivative(2)(t) for pp in prof.vel_ned], axis=-1)
    s = prof.eight_rate.antiderivative()(t)
    s1, s2, s3 = (prof.eight_rate.derivative(k)(t) for k in (0, 1, 2))
    a, dz = plan.eight_half_length_m, plan.eight_climb_m
    # the eight and its first three derivatives w.r.t. s: along, across its axis, down
    p0 = np.stack([a * np.sin(s), 0.5 * a * np.sin(2 * s), -dz * np.sin(s)], axis=-1)
    p1 = np.stack([a * np.cos(s), a * np.cos(2 * s), -dz * np.cos(s)], axis=-1)
    p2 = np.stack([-a * np.sin(s), -2 * a * np.sin(2 * s), dz * np.sin(s)], axis=-1)
    p3 = np.stack([-a * np.cos(s), -4 * a * np.cos(2 * s), dz * np.cos(s)], axis=-1)
    beta = math.radians(plan.eight_heading_deg)
    rot = np.array([[math.cos(beta), -math.sin(beta), 0.0], [math.sin(beta), math.cos(beta), 0.0]])
    rot = np.vstack([rot, [0.0, 0.0, 1.0]])
    c1, c2, c3 = s1[:, None], s2[:, None], s3[:, None]
    pos += p0 @ rot.T
    vel += (p1 * c1) @ rot.T
    acc += (p2 * c1**2 + p1 * c2) @ rot.T
    jerk += (p3 * c1**3 + 3.0 * p2 * c1 * c2 + p1 * c3) @ rot.T
    return Kinematics(pos, vel, acc, jerk)


def thrust_attitude(
    acc: F64, jerk: F64, yaw: F64, yaw_rate: F64, gravity_mps2: float
) -> tuple[F64, F64]:
    """Roll, pitch, yaw (n, 3) and the body rate w.r.t. NED (body FRD, (n, 3)) of a
    multirotor whose thrust axis (body -z) lies along the specific force ``acc - g``.

    With ``z = -f / |f|`` the body z axis in NED and ``u = Rz(-yaw) z = [sin(pitch) cos(roll),
    -sin(roll), cos(pitch) cos(roll)]``: ``pitch = atan2(u_x, u_z)``, ``roll = -asin(u_y)``;
    the rates follow from ``f' = jerk`` and ``u' = Rz(-yaw) z' + yaw' [u_y, -u_x, 0]``.
    """
    f = acc - np.array([0.0, 0.0, gravity_mps2])
    norm = np.linalg.norm(f, axis=-1, keepdims=True)
    z = -f / norm
    zdot = -(jerk / norm - f * np.sum(f * jerk, axis=-1, keepdims=True) / norm**3)
    cy, sy = np.cos(yaw), np.sin(yaw)
    u = np.stack([cy * z[:, 0] + sy * z[:, 1], -sy * z[:, 0] + cy * z[:, 1], z[:, 2]], axis=-1)
    udot = np.stack(
        [
            cy * zdot[:, 0] + sy * zdot[:, 1] + yaw_rate * u[:, 1],
            -sy * zdot[:, 0] + cy * zdot[:, 1] - yaw_rate * u[:, 0],
            zdot[:, 2],
        ],
        axis=-1,
    )
    hxz = np.hypot(u[:, 0], u[:, 2])
    pitch = np.arctan2(u[:, 0], u[:, 2])
    roll = np.arctan2(-u[:, 1], hxz)
    pitch_rate = (u[:, 2] * udot[:, 0] - u[:, 0] * udot[:, 2]) / hxz**2
    roll_rate = -udot[:, 1] / hxz
    sr, cr, sp, cp = np.sin(roll), np.cos(roll), np.sin(pitch), np.cos(pitch)
    w_nb = np.stack(
        [
            roll_rate - yaw_rate * sp,
            pitch_rate * cr + yaw_rate * cp * sr,
            -pitch_rate * sr + yaw_rate * cp * cr,
        ],
        axis=-1,
    )
    return np.stack([roll, pitch, yaw], axis=-1), w_nb


def _wrap(angle: F64) -> F64:
    out: F64 = (angle + math.pi) % (2.0 * math.pi) - math.pi
    return out


def n_samples(params: MultirotorFlightParams, *, bench: bool = False) -> int:
    """IMU samples of the flight (whole seconds, the last phase held) or of the bench log."""
    end = params.bench.duration_s if bench else build_profiles(params.flight).end_s
    return round(math.ceil(end) * params.imu_rate_hz) + 1


def flight_motion(params: MultirotorFlightParams) -> Motion:
    """The flight sampled at the IMU rate (``t_s`` from 0)."""
    plan, o = params.flight, params.origin
    prof = build_profiles(plan)
    n = n_samples(params)
    rate = params.imu_rate_hz
    t2 = np.arange(2 * n - 1, dtype=np.float64) / (2 * rate)  # the grid and its midpoints
    lat0, lon0 = math.radians(o.lat_deg), math.radians(o.lon_deg)
    kin = kinematics(prof, plan, t2)
    lat, lon, h = integrate_geodetic(lat0, lon0, o.alt_m, kin.vel, 1.0 / rate)
    s = slice(0, None, 2)
    t = t2[s]
    yaw = prof.yaw(t)
    rpy, w_nb = thrust_attitude(
        kin.acc[s], kin.jerk[s], yaw, prof.yaw.derivative()(t), earth.gravity(lat0, o.alt_m)
    )
    q = quats_from_rpy(rpy)
    rpy[:, 2] = _wrap(rpy[:, 2])
    return Motion(t, lat, lon, h, kin.vel[s], kin.acc[s], rpy, w_nb, q)


def bench_motion(params: MultirotorFlightParams) -> Motion:
    """The vehicle at rest on the bench at the origin, in the bench's attitude."""
    b, o = params.bench, params.origin
    n = n_samples(params, bench=True)
    rpy = np.tile(np.radians([b.roll_deg, b.pitch_deg, b.yaw_deg]), (n, 1))
    rpy[:, 2] = _wrap(rpy[:, 2])
    zeros = np.zeros((n, 3))
    return Motion(
        np.arange(n, dtype=np.float64) / params.imu_rate_hz,
        np.full(n, math.radians(o.lat_deg)),
        np.full(n, math.radians(o.lon_deg)),
        np.full(n, o.alt_m),
        zeros,
        zeros.copy(),
        rpy,
        zeros.copy(),
        quats_from_rpy(rpy),
    )


def dcm_body_to_ned(q: F64) -> F64:
    """C_b^n of every quaternion row [w, x, y, z], (n, 3, 3)."""
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=-2,
    )


def magnetometer(
    motion: Motion, params: MultirotorFlightParams, rng: np.random.Generator | None
) -> F64:
    """The magnetometer in body FRD, gauss, (n, 3): ``C_n^b B_n + hard_iron (+ noise)``;
    without ``rng`` the noise-free reading."""
    m = params.mag
    field_b = np.einsum("nji,j->ni", dcm_body_to_ned(motion.q_wxyz), np.array(m.field_ned_gauss))
    out: F64 = field_b + np.array(m.hard_iron_gauss)
    if rng is not None:
        out = out + m.noise_gauss * rng.standard_normal(out.shape)
    return out


def _t_ns(params: MultirotorFlightParams, n: int) -> I64:
    step_us = 1_000_000 // params.imu_rate_hz
    out: I64 = (params.start_unix_s * 1_000_000 + np.arange(n, dtype=np.int64) * step_us) * 1000
    return out


def _gauss_markov(m: int, phi: float, rng: np.random.Generator) -> F64:
    """m steps of a unit-variance first-order Gauss-Markov process per axis (3 axes)."""
    w = rng.standard_normal((m, 3))
    u = np.empty((m, 3))
    u[0] = w[0]
    for k in range(1, m):
        u[k] = phi * u[k - 1] + math.sqrt(1.0 - phi * phi) * w[k]
    return u


def flight_gnss(
    motion: Motion, rows: I64, t_ns: I64, params: MultirotorFlightParams, rng: np.random.Generator
) -> pa.Table:
    """GPS fixes of the antenna at samples ``rows`` (see ``MultirotorGnss``)."""
    g = params.gnss
    ant = antenna(motion, rows, np.array(g.lever_arm_m))
    m = rows.size
    phi = math.exp(-1.0 / (g.tau_s * params.gnss_rate_hz))
    err = _gauss_markov(m, phi, rng) * np.array([g.h_sigma_m, g.h_sigma_m, g.v_sigma_m])
    vel = ant.vel_ned_mps + g.vel_sigma_mps * rng.standard_normal((m, 3))
    rm, rn = np.vectorize(earth.radii)(ant.lat_rad)
    return from_columns(
        "gnss",
        {
            "t_ns": t_ns,
            "lat_deg": np.degrees(ant.lat_rad + err[:, 0] / (rm + ant.h_m)),
            "lon_deg": np.degrees(ant.lon_rad + err[:, 1] / ((rn + ant.h_m) * np.cos(ant.lat_rad))),
            "alt_m": ant.h_m - err[:, 2],
            **axis_columns("vel_{}_mps", vel, NED),
            "h_acc_m": np.full(m, g.h_sigma_m),
            "v_acc_m": np.full(m, g.v_sigma_m),
            "speed_acc_mps": np.full(m, g.vel_sigma_mps),
            "fix_type": np.full(m, FixType.FIX_3D, dtype=np.int8),
            "num_sats": np.full(m, g.num_sats, dtype=np.int16),
        },
    )


def bench_gnss(t_ns: I64, params: MultirotorFlightParams) -> pa.Table:
    """What a receiver without a fix reports: fix type 0/1, lat/lon/alt 0, speed 0, no
    accuracies, a few satellites."""
    m, b = t_ns.size, params.bench
    zeros = np.zeros(m)
    unknown = np.full(m, np.nan)
    return from_columns(
        "gnss",
        {
            "t_ns": t_ns,
            "lat_deg": zeros,
            "lon_deg": zeros,
            "alt_m": zeros,
            "vel_n_mps": zeros,
            "vel_e_mps": zeros,
            "vel_d_mps": zeros,
            "h_acc_m": unknown,
            "v_acc_m": unknown,
            "speed_acc_mps": unknown,
            "fix_type": np.full(m, b.fix_type, dtype=np.int8),
            "num_sats": np.full(m, b.num_sats, dtype=np.int16),
        },
    )


class RawLog(NamedTuple):
    """What the tlog is written from: canonical tables at full precision and the
    magnetometer (body FRD, gauss, one row per imu row).

    ``tables``: ``imu``, ``gnss``, ``truth`` (with the true IMU biases) and ``truth_imu``
    (the error-free IMU at the truth rows, for the SIM_STATE acceleration and gyro fields).
    """

    tables: dict[str, pa.Table]
    mag_gauss: F64


def raw_log(params: MultirotorFlightParams, seed: int, *, bench: bool = False) -> RawLog:
    """The flight (or the bench log) with its sensors; ``seed`` draws every error.

    Random draws, in order: the IMU (``imu.corrupt``), the magnetometer noise, the GNSS.
    """
    rng = dataset_rng(seed, BENCH_DATASET if bench else DATASET)
    motion = bench_motion(params) if bench else flight_motion(params)
    n = motion.t_s.size
    t_ns = _t_ns(params, n)
    acc, gyro = ideal_imu(motion)
    drawn = dataclasses.replace(params.imu, accel_bias_sigma_mps2=0.0, gyro_bias_sigma_radps=0.0)
    acc_m, gyro_m, acc_b, gyro_b = corrupt(acc, gyro, params.imu_rate_hz, drawn, rng)
    b0 = params.turn_on_bias
    acc_b += np.array(b0.accel_mps2)
    gyro_b += np.radians(b0.gyro_dps)
    acc_m += np.array(b0.accel_mps2)
    gyro_m += np.radians(b0.gyro_dps)
    mag = magnetometer(motion, params, rng)
    g_rows = np.arange(0, n, params.imu_rate_hz // params.gnss_rate_hz)
    gnss = (
        bench_gnss(t_ns[g_rows], params)
        if bench
        else flight_gnss(motion, g_rows, t_ns[g_rows], params, rng)
    )
    rows = np.arange(0, n, params.imu_rate_hz // params.truth_rate_hz)
    truth = from_columns(
        "truth",
        {
            "t_ns": t_ns[rows],
            "lat_deg": np.degrees(motion.lat_rad[rows]),
            "lon_deg": np.degrees(motion.lon_rad[rows]),
            "alt_m": motion.h_m[rows],
            **axis_columns("vel_{}_mps", motion.vel_ned_mps[rows], NED),
            "roll_rad": motion.rpy_rad[rows, 0],
            "pitch_rad": motion.rpy_rad[rows, 1],
            "yaw_rad": motion.rpy_rad[rows, 2],
            **axis_columns("acc_bias_{}_mps2", acc_b[rows]),
            **axis_columns("gyro_bias_{}_radps", gyro_b[rows]),
        },
    )
    tables = {
        "imu": imu_table(t_ns, acc_m, gyro_m),
        "gnss": gnss,
        "truth": truth,
        "truth_imu": imu_table(t_ns[rows], acc[rows], gyro[rows]),
    }
    return RawLog(tables, mag)


def sensor_meta(params: MultirotorFlightParams) -> SensorMeta:
    """The IMU noise model that was simulated, the antenna lever arm and the platform."""
    return SensorMeta(
        imu_noise=params.imu.noise_model(),
        lever_arm_m=params.gnss.lever_arm_m,
        platform=PLATFORM,
    )


def _result(params: MultirotorFlightParams, raw: RawLog) -> SynthResult:
    """imu and gnss as the tlog holds them, truth at full precision."""
    t = raw.tables
    tables = {
        "imu": as_logged_imu(t["imu"]),
        "gnss": as_logged_gnss(t["gnss"]),
        "truth": t["truth"],
    }
    return SynthResult(tables, sensor_meta(params), time_base="utc")


def synthesize(params: MultirotorFlightParams, seed: int, *, bench: bool = False) -> SynthResult:
    """``multirotor_flight`` (or ``bench_static``) in memory."""
    return _result(params, raw_log(params, seed, bench=bench))


def write(
    params: MultirotorFlightParams, seed: int, out_dir: str | Path, *, bench: bool = False
) -> list[Path]:
    """Write ``<dataset>.tlog`` and ``reference/`` as the folder ``out_dir``; returns the files."""
    dataset = BENCH_DATASET if bench else DATASET
    raw = raw_log(params, seed, bench=bench)

    def write_logs(folder: Path) -> list[tuple[Path, str]]:
        tlog = folder / f"{dataset}.tlog"
        t = raw.tables
        write_tlog(
            tlog,
            imu=t["imu"],
            gnss=t["gnss"],
            truth=t["truth"],
            truth_imu=t["truth_imu"],
            mav_type=MAV_TYPE_QUADROTOR,
            mag_gauss=raw.mag_gauss,
            truth_messages=("SIM_STATE",),
            armed=not bench,
        )
        return [(tlog, "mavlink_tlog")]

    plain = synth_params(seed, DATASET, params)
    return write_dataset_dir(out_dir, dataset, _result(params, raw), write_logs, params=plain)


def write_dataset(name: str, synth: SynthSection, out_dir: Path) -> list[Path]:
    """The synth registry's entry point: the flight or the bench log from ``params.synth``."""
    check_dataset(__name__, name, DATASET, BENCH_DATASET)
    return write(synth.multirotor_flight, synth.seed, out_dir, bench=name == BENCH_DATASET)
