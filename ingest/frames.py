"""Axis conventions: REP-103 ENU/FLU -> NED/FRD, and the IMU mounting rotation.

Canonical tables use NED for navigation vectors and FRD for body vectors (architecture
section 2). ROS (REP-103) uses ENU and FLU, except frames whose id ends in ``_ned``.

- FLU -> FRD is a half turn about x: ``(x, y, z) -> (x, -y, -z)``. It applies to IMU specific
  force and angular rate, and to body rates of odometry/twist (``yaw_rate_radps`` changes
  sign; forward speed does not).
- ENU -> NED: ``(e, n, u) -> (n, e, -u)``.

Mounting: the IMU may be mounted rotated in the vehicle. ``C_body_sensor`` rotates a vector
from sensor axes (already FRD) to body FRD axes, ``v_body = C_body_sensor @ v_sensor``, and is
built from ``mounting_rpy_deg`` = (roll, pitch, yaw) as ``Rz(yaw) @ Ry(pitch) @ Rx(roll)``
(the sensor's attitude in the body frame, ZYX Euler, the convention of
``pipeline.nav.rotations``). When the descriptor gives no mounting it is levelled from
gravity (``level_from_gravity``): with f the mean specific force at rest in sensor axes,
roll = atan2(-f_y, -f_z), pitch = atan2(f_x, sqrt(f_y^2 + f_z^2)), yaw = 0 (yaw about gravity
is unobservable from the accelerometer and reported as such). After it, the specific force
at rest is (0, 0, -|f|).
"""

from __future__ import annotations

import math

import numpy as np

from navreplay.ingest.arrays import F64

Vec3 = tuple[float, float, float]

ACC = ("acc_x_mps2", "acc_y_mps2", "acc_z_mps2")
GYRO = ("gyro_x_radps", "gyro_y_radps", "gyro_z_radps")
VEL_NED = ("vel_n_mps", "vel_e_mps", "vel_d_mps")
MAG = ("mag_x_gauss", "mag_y_gauss", "mag_z_gauss")


def flu_to_frd(columns: dict[str, np.ndarray], table: str) -> list[str]:
    """Convert a block's vector columns from FLU/ENU to FRD/NED in place; returns what changed.

    imu: y and z of specific force and angular rate negate; mag: y and z of the magnetic
    field negate. vehicle: ``yaw_rate_radps`` and
    ``steer_rad`` negate (positive left in FLU, positive right in FRD). gnss/truth velocity
    (if present): ENU -> NED.
    """
    changed: list[str] = []
    if table == "imu":
        for name in (ACC[1], ACC[2], GYRO[1], GYRO[2]):
            columns[name] = -columns[name]
            changed.append(name)
    elif table == "mag":
        for name in (MAG[1], MAG[2]):
            columns[name] = -columns[name]
            changed.append(name)
    elif table == "vehicle":
        for name in ("yaw_rate_radps", "steer_rad"):
            if name in columns:
                columns[name] = -columns[name]
                changed.append(name)
    elif all(v in columns for v in VEL_NED):
        e, n, u = (columns[v] for v in VEL_NED)
        columns[VEL_NED[0]], columns[VEL_NED[1]], columns[VEL_NED[2]] = n, e, -u
        changed.extend(VEL_NED)
    return changed


def enu_to_ned(e: F64, n: F64, u: F64) -> tuple[F64, F64, F64]:
    """ENU components -> (north, east, down)."""
    return n, e, -u


def dcm_from_rpy_deg(rpy_deg: Vec3) -> F64:
    """``Rz(yaw) @ Ry(pitch) @ Rx(roll)`` for (roll, pitch, yaw) in degrees."""
    r, p, y = (math.radians(a) for a in rpy_deg)
    cr, sr, cp, sp, cy, sy = (
        math.cos(r),
        math.sin(r),
        math.cos(p),
        math.sin(p),
        math.cos(y),
        math.sin(y),
    )
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def rpy_deg_from_dcm(c: F64) -> Vec3:
    """Inverse of ``dcm_from_rpy_deg`` (pitch in [-90, 90] deg)."""
    roll = math.atan2(c[2, 1], c[2, 2])
    pitch = -math.asin(max(-1.0, min(1.0, float(c[2, 0]))))
    yaw = math.atan2(c[1, 0], c[0, 0])
    return (math.degrees(roll), math.degrees(pitch), math.degrees(yaw))


def level_from_gravity(f_sensor: F64) -> Vec3:
    """Mounting (roll, pitch, 0) in degrees that turns ``f_sensor`` into (0, 0, -|f|)."""
    fx, fy, fz = (float(v) for v in f_sensor)
    roll = math.atan2(-fy, -fz)
    pitch = math.atan2(fx, math.hypot(fy, fz))
    return (math.degrees(roll), math.degrees(pitch), 0.0)


def tilt_deg(f_sensor: F64) -> float:
    """Angle between ``f_sensor`` and the body's up direction (-z), degrees."""
    norm = float(np.linalg.norm(f_sensor))
    if norm == 0.0:
        return float("nan")
    return math.degrees(math.acos(max(-1.0, min(1.0, -float(f_sensor[2]) / norm))))


def rotate_imu(
    columns: dict[str, np.ndarray],
    c_body_sensor: F64,
    vectors: tuple[tuple[str, str, str], ...] = (ACC, GYRO),
) -> None:
    """Apply ``v_body = C @ v_sensor`` to specific force and angular rate (or the given
    column triples: ``(MAG,)`` for the magnetometer), in place."""
    for names in vectors:
        v = np.stack([columns[n] for n in names])
        out = c_body_sensor @ v
        for k, n in enumerate(names):
            columns[n] = out[k]
