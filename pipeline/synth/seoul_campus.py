"""``seoul_campus``: the land-vehicle drive of paper 001, with exact truth.

A car rests for ``stationary_s`` (alignment), then drives a campus route near 37.46 N,
126.95 E: straights at 3-15 m/s, gentle hills (grades up to ~5 %), a stop, 90 and 180 deg
turns, and full clockwise and counter-clockwise loops. The ``cw`` variant meets a clockwise
loop first; ``ccw`` is its mirror image (every turn reversed). The route repeats if the drive
is longer than one lap.

Streams (``pipeline.synth.{trajectory, imu, gnss, constellation}``): a 100 Hz IMU derived
exactly from the motion, then corrupted by the MEMS error model; GPS L1 C/A observables of
the nominal 24-slot constellation at 1 Hz and receiver fixes of the roof antenna; 100 Hz truth
of the IMU (body) origin with the true sensor biases and receiver clock. Time is GPS time.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Literal

import numpy as np

from navreplay.ingest.gpstime import NS_PER_S, gps_from_calendar
from navreplay.ingest.meta import SensorMeta
from navreplay.ingest.schema import from_columns
from navreplay.pipeline.synth import (
    SynthResult,
    SynthSection,
    constellation,
    gnss,
    imu,
    trajectory,
)
from navreplay.pipeline.synth.columns import NED, RPY, axis_columns, imu_table
from navreplay.pipeline.synth.seoul_params import NO_IMU_ERRORS, SeoulCampusParams
from navreplay.pipeline.synth.trajectory import Leg

__all__ = ["ROUTE", "SeoulCampusParams", "route", "simulate", "simulate_drive", "write_dataset"]

Variant = Literal["cw", "ccw"]
_VARIANT_KEY = {"cw": 1, "ccw": 2}

# One lap, clockwise-first (positive angles turn right). About 7.5 minutes.
ROUTE: tuple[Leg, ...] = (
    Leg("straight", speed_mps=8.0, duration_s=20.0),
    Leg("turn", speed_mps=8.0, angle_deg=90.0, radius_m=30.0),
    Leg("straight", speed_mps=12.0, duration_s=30.0, hill_m=6.0),
    Leg("turn", speed_mps=6.0, angle_deg=360.0, radius_m=25.0),  # clockwise loop
    Leg("straight", speed_mps=10.0, duration_s=20.0),
    Leg("turn", speed_mps=6.0, angle_deg=90.0, radius_m=20.0),
    Leg("straight", speed_mps=15.0, duration_s=40.0, hill_m=-4.0),
    Leg("stop", duration_s=10.0),
    Leg("straight", speed_mps=5.0, duration_s=15.0),
    Leg("turn", speed_mps=6.0, angle_deg=-90.0, radius_m=20.0),
    Leg("straight", speed_mps=3.0, duration_s=12.0),
    Leg("turn", speed_mps=7.0, angle_deg=-360.0, radius_m=30.0),  # counter-clockwise loop
    Leg("straight", speed_mps=13.0, duration_s=30.0, hill_m=5.0),
    Leg("turn", speed_mps=6.0, angle_deg=-180.0, radius_m=25.0),
    Leg("straight", speed_mps=11.0, duration_s=25.0),
    Leg("turn", speed_mps=9.0, angle_deg=360.0, radius_m=40.0),  # clockwise loop
    Leg("straight", speed_mps=14.0, duration_s=20.0),
    Leg("turn", speed_mps=8.0, angle_deg=-90.0, radius_m=30.0),
    Leg("turn", speed_mps=5.0, angle_deg=-360.0, radius_m=20.0),  # counter-clockwise loop
    Leg("straight", speed_mps=12.0, duration_s=30.0, hill_m=-5.0),
    Leg("turn", speed_mps=12.0, angle_deg=45.0, radius_m=60.0),
    Leg("straight", speed_mps=10.0, duration_s=20.0),
    Leg("turn", speed_mps=8.0, angle_deg=135.0, radius_m=35.0),
)


def route(variant: Variant) -> list[Leg]:
    """The lap of a variant: ``cw`` as written, ``ccw`` mirrored."""
    if variant not in _VARIANT_KEY:
        raise ValueError(f"variant must be 'cw' or 'ccw', not {variant!r}")
    return list(ROUTE) if variant == "cw" else [leg.mirrored() for leg in ROUTE]


def simulate(params: SeoulCampusParams, *, seed: int, variant: Variant) -> SynthResult:
    """Synthesize the drive: canonical ``imu``, ``gnss``, ``gnss_obs`` and ``truth`` tables.

    The same (params, seed, variant) give identical tables. The constellation (satellite
    clocks) depends on ``seed`` only, so both variants see the same sky; every other draw also
    depends on the variant.
    """
    return simulate_drive(params, route(variant), seed=seed, stream=_VARIANT_KEY[variant])


def simulate_drive(
    params: SeoulCampusParams,
    legs: list[Leg],
    *,
    seed: int,
    stream: int,
    start_speed_mps: float = 0.0,
) -> SynthResult:
    """The campus car, IMU and receiver on the drive ``legs`` (``trajectory.build_profiles``;
    ``start_speed_mps``: a rolling start): canonical ``imu``, ``gnss``, ``gnss_obs`` and
    ``truth`` tables.

    The constellation is drawn from ``seed`` alone; the IMU, clock, observable and fix errors
    from ``seed`` and ``stream`` (one stream per drive, so drives differ in their noise).
    """
    profiles = trajectory.build_profiles(
        legs,
        params.stationary_s,
        params.duration_s,
        trajectory.Limits(
            params.max_accel_mps2, params.max_yaw_accel_radps2, params.max_grade_rate_ps
        ),
        start_speed_mps=start_speed_mps,
    )
    motion = trajectory.sample(
        profiles,
        rate_hz=params.imu_rate_hz,
        duration_s=params.duration_s,
        lat0_rad=math.radians(params.lat_deg),
        lon0_rad=math.radians(params.lon_deg),
        h0_m=params.alt_m,
        yaw0_rad=math.radians(params.yaw_deg),
        body=trajectory.Body(
            roll_per_lat_acc=params.roll_per_lat_acc_rad,
            sideslip_per_lat_acc=params.sideslip_per_lat_acc_rad,
            pitch_per_long_acc=params.pitch_per_long_acc_rad,
            road_rms_m=params.road_rms_m,
            road_seed=seed,
        ),
    )
    n = motion.t_s.size
    dt_ns = NS_PER_S // params.imu_rate_hz
    t0 = gps_from_calendar(params.start_gps)
    t_ns = t0 + np.arange(n, dtype=np.int64) * dt_ns
    sky_rng = np.random.default_rng(np.random.SeedSequence([seed, 0]))
    imu_rng, clock_rng, obs_rng, fix_rng = (
        np.random.default_rng(s) for s in np.random.SeedSequence([seed, stream]).spawn(4)
    )
    noisy = not params.noise_free
    imu_errors = params.imu if noisy else NO_IMU_ERRORS

    acc, gyro = imu.ideal_imu(motion)
    acc_m, gyro_m, acc_b, gyro_b = imu.corrupt(
        acc, gyro, float(params.imu_rate_hz), imu_errors, imu_rng
    )
    clock_b, clock_d = gnss.receiver_clock(n, dt_ns / NS_PER_S, params.gnss, clock_rng, noisy=noisy)
    eph = constellation.nominal_gps(int(t_ns[0]), int(t_ns[-1]), params.constellation, sky_rng)
    rows = np.arange(0, n, params.imu_rate_hz // params.gnss_rate_hz)
    ant = gnss.antenna(motion, rows, np.asarray(params.lever_arm_m, dtype=np.float64))
    obs = gnss.observables(
        eph, t_ns[rows], ant, clock_b[rows], clock_d[rows], params.gnss, obs_rng, noisy=noisy
    )
    fix = gnss.fixes(t_ns[rows], ant, obs, params.gnss, fix_rng, noisy=noisy)

    truth: dict[str, np.ndarray] = {
        "t_ns": t_ns,
        "lat_deg": np.degrees(motion.lat_rad),
        "lon_deg": np.degrees(motion.lon_rad),
        "alt_m": motion.h_m,
        **axis_columns("vel_{}_mps", motion.vel_ned_mps, NED),
        **axis_columns("{}_rad", motion.rpy_rad, RPY),
        "clock_bias_m": clock_b,
        "clock_drift_mps": clock_d,
        **axis_columns("acc_bias_{}_mps2", acc_b),
        **axis_columns("gyro_bias_{}_radps", gyro_b),
    }
    tables = {
        "imu": imu_table(t_ns, acc_m, gyro_m),
        "gnss": from_columns("gnss", fix),
        "gnss_obs": from_columns("gnss_obs", obs),
        "truth": from_columns("truth", truth),
    }
    sensors = SensorMeta(imu_noise=imu_errors.noise_model(), lever_arm_m=params.lever_arm_m)
    return SynthResult(tables=tables, sensors=sensors, ephemeris=eph, time_base="gps")


def write_dataset(name: str, synth: SynthSection, out_dir: Path) -> list[Path]:
    """Simulate ``seoul_campus_cw`` or ``seoul_campus_ccw`` and write its files into
    ``out_dir`` (``pipeline.synth.files``); returns the paths written."""
    from navreplay.pipeline.synth.files import write_result

    variant: Variant = "cw" if name.endswith("_cw") else "ccw"
    if name not in (f"seoul_campus_{v}" for v in _VARIANT_KEY):
        raise ValueError(f"not a seoul_campus dataset: {name!r}")
    result = simulate(synth.seoul_campus, seed=synth.seed, variant=variant)
    return write_result(name, result, out_dir, params=synth.seoul_campus)
