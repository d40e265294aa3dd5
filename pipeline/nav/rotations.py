"""Attitude conventions: Hamilton quaternions, scalar first, body FRD to navigation NED.

``q_wxyz`` rotates body vectors into the navigation frame: ``v_n = C_b^n(q) @ v_b``. Euler
angles are the aerospace ZYX sequence: ``C_b^n = Rz(yaw) @ Ry(pitch) @ Rx(roll)``; yaw is the
heading from north, clockwise seen from above. All functions are numba-compiled.
"""

from __future__ import annotations

import math

import numpy as np

from navreplay.pipeline._jit import njit
from navreplay.pipeline.nav.earth import F64


@njit(cache=True)
def skew(v: F64) -> F64:
    """The cross-product matrix [v x] such that skew(v) @ w == cross(v, w)."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


@njit(cache=True)
def quat_mul(p: F64, q: F64) -> F64:
    """Hamilton product p * q (scalar first)."""
    return np.array(
        [
            p[0] * q[0] - p[1] * q[1] - p[2] * q[2] - p[3] * q[3],
            p[0] * q[1] + p[1] * q[0] + p[2] * q[3] - p[3] * q[2],
            p[0] * q[2] - p[1] * q[3] + p[2] * q[0] + p[3] * q[1],
            p[0] * q[3] + p[1] * q[2] - p[2] * q[1] + p[3] * q[0],
        ]
    )


@njit(cache=True)
def quat_normalize(q: F64) -> F64:
    """Unit quaternion with non-negative scalar part (q and -q are the same rotation)."""
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    s = 1.0 / n if q[0] >= 0.0 else -1.0 / n
    return q * s


@njit(cache=True)
def quat_to_dcm(q: F64) -> F64:
    """C_b^n from a unit quaternion q_wxyz."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    return np.array(
        [
            [w * w + x * x - y * y - z * z, 2.0 * (x * y - w * z), 2.0 * (x * z + w * y)],
            [2.0 * (x * y + w * z), w * w - x * x + y * y - z * z, 2.0 * (y * z - w * x)],
            [2.0 * (x * z - w * y), 2.0 * (y * z + w * x), w * w - x * x - y * y + z * z],
        ]
    )


@njit(cache=True)
def dcm_to_quat(c: F64) -> F64:
    """Unit quaternion (scalar part >= 0) from a rotation matrix (Shepperd's method)."""
    tr = c[0, 0] + c[1, 1] + c[2, 2]
    q = np.empty(4)
    if tr > max(c[0, 0], c[1, 1], c[2, 2]):
        s = 2.0 * math.sqrt(1.0 + tr)
        q[0] = 0.25 * s
        q[1] = (c[2, 1] - c[1, 2]) / s
        q[2] = (c[0, 2] - c[2, 0]) / s
        q[3] = (c[1, 0] - c[0, 1]) / s
    elif c[0, 0] >= c[1, 1] and c[0, 0] >= c[2, 2]:
        s = 2.0 * math.sqrt(1.0 + c[0, 0] - c[1, 1] - c[2, 2])
        q[0] = (c[2, 1] - c[1, 2]) / s
        q[1] = 0.25 * s
        q[2] = (c[0, 1] + c[1, 0]) / s
        q[3] = (c[0, 2] + c[2, 0]) / s
    elif c[1, 1] >= c[2, 2]:
        s = 2.0 * math.sqrt(1.0 + c[1, 1] - c[0, 0] - c[2, 2])
        q[0] = (c[0, 2] - c[2, 0]) / s
        q[1] = (c[0, 1] + c[1, 0]) / s
        q[2] = 0.25 * s
        q[3] = (c[1, 2] + c[2, 1]) / s
    else:
        s = 2.0 * math.sqrt(1.0 + c[2, 2] - c[0, 0] - c[1, 1])
        q[0] = (c[1, 0] - c[0, 1]) / s
        q[1] = (c[0, 2] + c[2, 0]) / s
        q[2] = (c[1, 2] + c[2, 1]) / s
        q[3] = 0.25 * s
    return quat_normalize(q)


@njit(cache=True)
def euler_to_dcm(roll: float, pitch: float, yaw: float) -> F64:
    """C_b^n = Rz(yaw) Ry(pitch) Rx(roll)."""
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    return np.array(
        [
            [cp * cy, sr * sp * cy - cr * sy, cr * sp * cy + sr * sy],
            [cp * sy, sr * sp * sy + cr * cy, cr * sp * sy - sr * cy],
            [-sp, sr * cp, cr * cp],
        ]
    )


@njit(cache=True)
def dcm_to_euler(c: F64) -> tuple[float, float, float]:
    """(roll, pitch, yaw) of C_b^n; yaw in (-pi, pi]."""
    pitch = -math.asin(min(1.0, max(-1.0, c[2, 0])))
    roll = math.atan2(c[2, 1], c[2, 2])
    yaw = math.atan2(c[1, 0], c[0, 0])
    return roll, pitch, yaw


@njit(cache=True)
def euler_to_quat(roll: float, pitch: float, yaw: float) -> F64:
    """q_wxyz of C_b^n = Rz(yaw) Ry(pitch) Rx(roll)."""
    return dcm_to_quat(euler_to_dcm(roll, pitch, yaw))


@njit(cache=True)
def quat_to_euler(q: F64) -> tuple[float, float, float]:
    """(roll, pitch, yaw) of a unit quaternion q_wxyz."""
    return dcm_to_euler(quat_to_dcm(q))


@njit(cache=True)
def rotvec_to_quat(v: F64) -> F64:
    """Quaternion of the rotation by angle |v| about axis v/|v| (exact; small-angle safe)."""
    angle = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    if angle < 1e-8:
        # Taylor expansion of sin(a/2)/a avoids 0/0; error O(a^4).
        k = 0.5 - angle * angle / 48.0
        return quat_normalize(np.array([1.0 - angle * angle / 8.0, v[0] * k, v[1] * k, v[2] * k]))
    k = math.sin(0.5 * angle) / angle
    return np.array([math.cos(0.5 * angle), v[0] * k, v[1] * k, v[2] * k])


@njit(cache=True)
def quat_to_rotvec(q: F64) -> F64:
    """Rotation vector (axis times angle, angle in [0, pi]) of a unit quaternion."""
    qq = quat_normalize(q)
    s = math.sqrt(qq[1] * qq[1] + qq[2] * qq[2] + qq[3] * qq[3])
    if s < 1e-12:
        return 2.0 * qq[1:4]
    angle = 2.0 * math.atan2(s, qq[0])
    return qq[1:4] * (angle / s)


@njit(cache=True)
def wrap_angle(a: float) -> float:
    """Angle wrapped to (-pi, pi]."""
    return a - 2.0 * math.pi * math.ceil((a - math.pi) / (2.0 * math.pi))
