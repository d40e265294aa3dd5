"""GNSS measurement models: loosely coupled fixes and tightly coupled pseudoranges (eq. 7-8).

All functions take the full state ``X`` of ``models.ins`` and the GNSS antenna lever arm
``lever_b`` (antenna relative to the IMU, body FRD, m). Jacobians are with respect to the
error state of ``models.ins`` (NED metres, nav-frame rotation vector ...), first order.

Antenna kinematics: ``r_ant = r + C_b^n l_b`` and ``v_ant = v^n + C_b^n (w_eb^b x l_b)`` with
``w_eb^b = (w_ib^b - b_g) - C_n^b w_ie^n`` (paper 001 eq. 8 uses ``w_eb^b``). Perturbing the
attitude on the left, ``d(C l) = phi x (C l) = -[(C l) x] phi``.

- Position (loose): the antenna's NED offset from a reference point ``ref = (lat, lon, h)``
  (the EKF's nominal or the UKF's mean), so measurement, prediction and innovation are metres;
  ``H = [I, 0, -[(C l) x], 0, 0]``.
- Velocity (loose): ``v_ant``; ``H_v = I``, ``H_phi = -[u x]`` with ``u = C (w_eb x l)``,
  ``H_bg = C [l x]``.
- Pseudorange (tight, eq. 7): ``|r_sat - r_ant| + cb`` in ECEF; with ``e`` the unit vector from
  the antenna to the satellite in NED, ``H_r = -e^T``, ``H_phi = e^T [(C l) x]``, ``H_cb = 1``.
- Pseudorange rate (tight, eq. 8): ``e . (v_sat - v_ant) + cd``; ``H_v = -e^T``,
  ``H_phi = e^T [u x]``, ``H_bg = -e^T C [l x]``, ``H_r = -(dv - e (e . dv))^T / range``
  (the line of sight turns as the antenna moves), ``H_cd = 1``.

Satellite states follow the ``gnss_obs`` conventions of ``ingest.schema``: ECEF at transmit
time in the receive-time frame, so the geometric range is ``|r_sat - r_ant|`` (no Sagnac term).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from pipeline.estimation.models.ins import (
    E_ATT,
    E_BG,
    E_CB,
    E_CD,
    E_POS,
    E_VEL,
    X_BG,
    X_CB,
    X_CD,
    X_H,
    X_LAT,
    X_LON,
    X_Q,
    X_VEL,
)
from pipeline.nav.earth import F64, OMEGA_IE, dcm_ecef_to_ned, geodetic_to_ecef, radii
from pipeline.nav.rotations import quat_to_dcm


@nb.njit(cache=True)
def ned_offset(lat: float, lon: float, h: float, ref: F64) -> F64:
    """NED offset (m) of the point (lat, lon, h) from ``ref`` = (lat, lon, h), with the radii of
    ``ref`` (exact for the small offsets of a filter update)."""
    rm, rn = radii(ref[0])
    dlon = lon - ref[1]
    dlon -= 2.0 * math.pi * round(dlon / (2.0 * math.pi))
    return np.array(
        [(lat - ref[0]) * (rm + ref[2]), dlon * (rn + ref[2]) * math.cos(ref[0]), -(h - ref[2])]
    )


@nb.njit(cache=True)
def antenna_geodetic(X: F64, lever_b: F64) -> tuple[float, float, float, F64]:
    """Antenna latitude, longitude (rad), height (m) and the NED lever arm ``C_b^n l_b``."""
    C = quat_to_dcm(X[X_Q : X_Q + 4])
    cl = C @ lever_b
    lat, h = X[X_LAT], X[X_H]
    rm, rn = radii(lat)
    return (
        lat + cl[0] / (rm + h),
        X[X_LON] + cl[1] / ((rn + h) * math.cos(lat)),
        h - cl[2],
        cl,
    )


@nb.njit(cache=True)
def antenna_velocity(X: F64, lever_b: F64, w_ib_b: F64) -> tuple[F64, F64]:
    """Antenna velocity w.r.t. the earth in NED and the lever-arm term ``u = C (w_eb x l)``.

    Args:
        X: full state.
        lever_b: lever arm, body FRD, m.
        w_ib_b: measured angular rate (bias not yet removed), rad/s.
    """
    C = quat_to_dcm(X[X_Q : X_Q + 4])
    lat = X[X_LAT]
    w_ie_n = np.array([OMEGA_IE * math.cos(lat), 0.0, -OMEGA_IE * math.sin(lat)])
    w_eb = w_ib_b - X[X_BG : X_BG + 3] - C.T @ w_ie_n
    u = C @ np.cross(w_eb, lever_b)
    return X[X_VEL : X_VEL + 3] + u, u


@nb.njit(cache=True)
def _skew(v: F64) -> F64:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


@nb.njit(cache=True)
def position_h(X: F64, lever_b: F64, ref: F64) -> F64:
    """Predicted antenna position as a NED offset from ``ref`` (m), shape (3,)."""
    lat_a, lon_a, h_a, _ = antenna_geodetic(X, lever_b)
    return ned_offset(lat_a, lon_a, h_a, ref)


@nb.njit(cache=True)
def position_jac(X: F64, lever_b: F64, n: int) -> F64:
    """Jacobian of ``position_h`` w.r.t. the error state, shape (3, n)."""
    C = quat_to_dcm(X[X_Q : X_Q + 4])
    sk = _skew(C @ lever_b)
    H = np.zeros((3, n))
    for r in range(3):
        H[r, E_POS + r] = 1.0
        for c in range(3):
            H[r, E_ATT + c] = -sk[r, c]
    return H


@nb.njit(cache=True)
def velocity_h(X: F64, lever_b: F64, w_ib_b: F64) -> F64:
    """Predicted antenna velocity in NED (m/s), shape (3,)."""
    v, _ = antenna_velocity(X, lever_b, w_ib_b)
    return v


@nb.njit(cache=True)
def velocity_jac(X: F64, lever_b: F64, w_ib_b: F64, n: int) -> F64:
    """Jacobian of ``velocity_h`` w.r.t. the error state, shape (3, n)."""
    C = quat_to_dcm(X[X_Q : X_Q + 4])
    _, u = antenna_velocity(X, lever_b, w_ib_b)
    su = _skew(u)
    cl = C @ _skew(lever_b)
    H = np.zeros((3, n))
    for r in range(3):
        H[r, E_VEL + r] = 1.0
        for c in range(3):
            H[r, E_ATT + c] = -su[r, c]
            H[r, E_BG + c] = cl[r, c]
    return H


@nb.njit(cache=True)
def antenna_ecef(X: F64, lever_b: F64, w_ib_b: F64) -> tuple[F64, F64, F64]:
    """Antenna ECEF position (m), ECEF velocity (m/s) and ``C_e^n`` at the antenna."""
    lat_a, lon_a, h_a, _ = antenna_geodetic(X, lever_b)
    v_n, _ = antenna_velocity(X, lever_b, w_ib_b)
    c_en = dcm_ecef_to_ned(lat_a, lon_a)
    return geodetic_to_ecef(lat_a, lon_a, h_a), c_en.T @ v_n, c_en


@nb.njit(cache=True)
def pseudorange_h(r_ant: F64, X: F64, sat: F64) -> float:
    """Predicted pseudorange ``|r_sat - r_ant| + cb`` (m) for satellite ``sat[0:3]`` (ECEF)."""
    dx, dy, dz = sat[0] - r_ant[0], sat[1] - r_ant[1], sat[2] - r_ant[2]
    return float(math.sqrt(dx * dx + dy * dy + dz * dz) + X[X_CB])


@nb.njit(cache=True)
def pseudorange_rate_h(r_ant: F64, v_ant: F64, X: F64, sat: F64) -> float:
    """Predicted pseudorange rate ``e . (v_sat - v_ant) + cd`` (m/s); ``sat[3:6]`` is the
    satellite ECEF velocity."""
    d = sat[0:3] - r_ant
    rng = math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
    rate = d[0] * (sat[3] - v_ant[0]) + d[1] * (sat[4] - v_ant[1]) + d[2] * (sat[5] - v_ant[2])
    return float(rate / rng + X[X_CD])


@nb.njit(cache=True)
def pseudorange_jac(
    X: F64, lever_b: F64, r_ant: F64, c_en: F64, sat: F64, n: int, H_row: F64
) -> None:
    """Jacobian row of ``pseudorange_h`` w.r.t. the error state, written into ``H_row`` (n,)."""
    d = sat[0:3] - r_ant
    e_n = c_en @ (d / math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]))
    C = quat_to_dcm(X[X_Q : X_Q + 4])
    att = e_n @ _skew(C @ lever_b)
    for c in range(n):
        H_row[c] = 0.0
    for c in range(3):
        H_row[E_POS + c] = -e_n[c]
        H_row[E_ATT + c] = att[c]
    H_row[E_CB] = 1.0


@nb.njit(cache=True)
def pseudorange_rate_jac(
    X: F64,
    lever_b: F64,
    w_ib_b: F64,
    r_ant: F64,
    v_ant: F64,
    c_en: F64,
    sat: F64,
    n: int,
    H_row: F64,
) -> None:
    """Jacobian row of ``pseudorange_rate_h`` w.r.t. the error state, into ``H_row`` (n,)."""
    d = sat[0:3] - r_ant
    rng = math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
    e_n = c_en @ (d / rng)
    dv_n = c_en @ (sat[3:6] - v_ant)
    los_turn = (dv_n - e_n * (e_n @ dv_n)) / rng
    C = quat_to_dcm(X[X_Q : X_Q + 4])
    _, u = antenna_velocity(X, lever_b, w_ib_b)
    att = e_n @ _skew(u)
    bg = -(e_n @ (C @ _skew(lever_b)))
    for c in range(n):
        H_row[c] = 0.0
    for c in range(3):
        H_row[E_POS + c] = -los_turn[c]
        H_row[E_VEL + c] = -e_n[c]
        H_row[E_ATT + c] = att[c]
        H_row[E_BG + c] = bg[c]
    H_row[E_CD] = 1.0
