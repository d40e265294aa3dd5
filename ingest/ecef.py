"""ECEF <-> geodetic/NED conversions for readers whose logs store earth-centred states.

Vectorised over rows; WGS-84 throughout. ``ingest`` cannot import ``pipeline.nav``, so the
few conversions the readers need live here (geodetic from ECEF through ``pymap3d``, the rest
in closed form).

Conventions: ``C_a_b`` rotates a vector from frame b to frame a (``v_a = C_a_b @ v_b``);
quaternions are Hamilton, scalar first (``q_wxyz``), and ``dcm_from_quat_wxyz(q)`` is the
matrix that maps vectors of the rotated frame into the reference frame; Euler angles are
ZYX (yaw, pitch, roll) of body FRD w.r.t. NED, as in ``pipeline.nav.rotations``.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pymap3d

from navreplay.ingest.arrays import F64


def geodetic_from_ecef(xyz_m: npt.ArrayLike) -> tuple[F64, F64, F64]:
    """Latitude, longitude (deg) and ellipsoidal height (m) of ECEF points of shape (n, 3)."""
    p = np.asarray(xyz_m, dtype=np.float64).reshape(-1, 3)
    lat, lon, alt = pymap3d.ecef2geodetic(p[:, 0], p[:, 1], p[:, 2], deg=True)
    return (
        np.asarray(lat, dtype=np.float64),
        np.asarray(lon, dtype=np.float64),
        np.asarray(alt, dtype=np.float64),
    )


def ecef_from_geodetic(lat_deg: npt.ArrayLike, lon_deg: npt.ArrayLike, alt_m: npt.ArrayLike) -> F64:
    """ECEF points (n, 3), m, of geodetic latitude/longitude (deg) and ellipsoidal height."""
    x, y, z = pymap3d.geodetic2ecef(lat_deg, lon_deg, alt_m, deg=True)
    return np.stack([np.asarray(v, dtype=np.float64).reshape(-1) for v in (x, y, z)], axis=1)


def c_ned_ecef(lat_deg: npt.ArrayLike, lon_deg: npt.ArrayLike) -> F64:
    """Rotation matrices (n, 3, 3) from ECEF to the local NED frame at each point."""
    lat = np.radians(np.asarray(lat_deg, dtype=np.float64).reshape(-1))
    lon = np.radians(np.asarray(lon_deg, dtype=np.float64).reshape(-1))
    sl, cl, so, co = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)
    zero = np.zeros_like(lat)
    rows = (
        (-sl * co, -sl * so, cl),
        (-so, co, zero),
        (-cl * co, -cl * so, -sl),
    )
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)


def ned_from_ecef_vectors(
    vec_ecef: npt.ArrayLike, lat_deg: npt.ArrayLike, lon_deg: npt.ArrayLike
) -> F64:
    """ECEF vectors (n, 3), e.g. velocities, resolved in NED at each point: (n, 3)."""
    v = np.asarray(vec_ecef, dtype=np.float64).reshape(-1, 3)
    out: F64 = np.einsum("nij,nj->ni", c_ned_ecef(lat_deg, lon_deg), v)
    return out


def dcm_from_quat_wxyz(q_wxyz: npt.ArrayLike) -> F64:
    """Rotation matrices (n, 3, 3) of Hamilton quaternions (n, 4), normalised first."""
    q = np.asarray(q_wxyz, dtype=np.float64).reshape(-1, 4)
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=-2,
    )


def rpy_from_dcm(c_ned_body: npt.ArrayLike) -> tuple[F64, F64, F64]:
    """ZYX Euler angles (rad) of body axes w.r.t. NED from ``C_ned_body`` of shape (n, 3, 3).

    Roll in (-pi, pi], pitch in [-pi/2, pi/2], yaw (heading, clockwise from north) in
    (-pi, pi].
    """
    c = np.asarray(c_ned_body, dtype=np.float64).reshape(-1, 3, 3)
    roll = np.arctan2(c[:, 2, 1], c[:, 2, 2])
    pitch = -np.arcsin(np.clip(c[:, 2, 0], -1.0, 1.0))
    yaw = np.arctan2(c[:, 1, 0], c[:, 0, 0])
    return roll, pitch, yaw


def velocity_ned_from_course(
    speed_mps: npt.ArrayLike, course_deg: npt.ArrayLike
) -> tuple[F64, F64]:
    """North and east velocity (m/s) of a ground speed and a course over ground (deg true)."""
    v = np.asarray(speed_mps, dtype=np.float64)
    c = np.radians(np.asarray(course_deg, dtype=np.float64))
    return v * np.cos(c), v * np.sin(c)
