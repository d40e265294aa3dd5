"""Synthetic IMU: exact readings of a trajectory, then a MEMS error model.

``ideal_imu`` evaluates ``pipeline.nav.mechanization.imu_from_motion`` at every sample, so the
noise-free IMU integrates back onto the trajectory. ``corrupt`` adds, per axis and sensor,

    y = (1 + s) * x + b0 + b_rw(t) + w,

with ``s`` a constant scale-factor error, ``b0`` a constant (turn-on) bias, ``b_rw`` a random
walk of density ``rw`` (increments N(0, rw^2 dt)) and ``w`` white noise of density ``n``
(per sample N(0, n^2 * rate)). The densities are those of ``ingest.config.ImuNoise``.
"""

from __future__ import annotations

import numpy as np

from navreplay.pipeline._jit import njit
from navreplay.pipeline.nav.earth import F64
from navreplay.pipeline.nav.mechanization import I_QW, I_VN, NAV_DIM, imu_from_motion
from navreplay.pipeline.synth.seoul_params import ImuErrors
from navreplay.pipeline.synth.trajectory import Motion


@njit(cache=True)
def _ideal(lat: F64, h: F64, vel: F64, q: F64, vdot: F64, w_nb: F64) -> tuple[F64, F64]:
    n = lat.shape[0]
    acc, gyro = np.empty((n, 3)), np.empty((n, 3))
    x = np.zeros(NAV_DIM)
    for i in range(n):
        x[0], x[2] = lat[i], h[i]
        x[I_VN : I_VN + 3] = vel[i]
        x[I_QW : I_QW + 4] = q[i]
        acc[i], gyro[i] = imu_from_motion(x, vdot[i], w_nb[i])
    return acc, gyro


def ideal_imu(motion: Motion) -> tuple[F64, F64]:
    """Exact specific force and angular rate (body FRD; m/s^2, rad/s) at every sample."""
    return _ideal(
        motion.lat_rad,
        motion.h_m,
        motion.vel_ned_mps,
        motion.q_wxyz,
        motion.vdot_ned_mps2,
        motion.w_nb_b_radps,
    )


def _sensor(
    x: F64,
    rate_hz: float,
    noise: float,
    bias0: float,
    rw: float,
    scale_ppm: float,
    rng: np.random.Generator,
) -> tuple[F64, F64]:
    n = x.shape[0]
    b0 = rng.normal(0.0, 1.0, 3) * bias0
    steps = rng.normal(0.0, 1.0, (n, 3)) * (rw / np.sqrt(rate_hz))
    steps[0] = 0.0
    bias = b0 + np.cumsum(steps, axis=0)
    scale = 1.0 + rng.normal(0.0, 1.0, 3) * scale_ppm * 1e-6
    white = rng.normal(0.0, 1.0, (n, 3)) * (noise * np.sqrt(rate_hz))
    return x * scale + bias + white, bias


def corrupt(
    acc: F64, gyro: F64, rate_hz: float, errors: ImuErrors, rng: np.random.Generator
) -> tuple[F64, F64, F64, F64]:
    """Measured IMU and the true biases: (acc, gyro, acc_bias, gyro_bias), each (N, 3).

    The draws are made in a fixed order (accelerometer first), so a seed reproduces them.
    """
    acc_m, acc_b = _sensor(
        acc,
        rate_hz,
        errors.accel_noise_mps2_rthz,
        errors.accel_bias_sigma_mps2,
        errors.accel_bias_rw_mps3_rthz,
        errors.accel_scale_sigma_ppm,
        rng,
    )
    gyro_m, gyro_b = _sensor(
        gyro,
        rate_hz,
        errors.gyro_noise_radps_rthz,
        errors.gyro_bias_sigma_radps,
        errors.gyro_bias_rw_radps2_rthz,
        errors.gyro_scale_sigma_ppm,
        rng,
    )
    return acc_m, gyro_m, acc_b, gyro_b
