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

from navreplay.pipeline._jit import njit
from navreplay.pipeline.estimation.ins.models.ins import (
    E_ATT,
    E_BG,
    E_CB,
    E_CD,
    E_POS,
    E_VEL,
    N_LOOSE,
    X_BG,
    X_CB,
    X_CD,
    X_H,
    X_LAT,
    X_LON,
    X_Q,
    X_VEL,
    dcm_into,
)
from navreplay.pipeline.nav.earth import E2, F64, OMEGA_IE, A, radii

# Layout of the antenna context filled by ``antenna``: everything the rows of one state need.
AN_LLH = 0  # 0..2: antenna latitude, longitude (rad), height (m)
AN_CL = 3  # 3..5: lever arm in NED, C_b^n l_b (m)
AN_U = 6  # 6..8: lever-arm velocity in NED, u = C_b^n (w_eb^b x l_b) (m/s)
AN_VN = 9  # 9..11: antenna velocity in NED (m/s)
AN_RE = 12  # 12..14: antenna ECEF position (m)
AN_VE = 15  # 15..17: antenna ECEF velocity (m/s)
AN_CEN = 18  # 18..26: C_e^n at the antenna, row-major
AN_C = 27  # 27..35: C_b^n, row-major
AN_DIM = 36


@njit(cache=True, inline="always", error_model="numpy")
def sk(a0: float, a1: float, a2: float, r: int, c: int) -> float:
    """Entry (r, c) of the cross-product matrix [a x]."""
    if r == c:
        return 0.0
    if r == 0:
        return -a2 if c == 1 else a1
    if r == 1:
        return a2 if c == 0 else -a0
    return -a1 if c == 0 else a0


@njit(cache=True, error_model="numpy")
def ned_offset(lat: float, lon: float, h: float, ref: F64) -> tuple[float, float, float]:
    """NED offset (m) of the point (lat, lon, h) from ``ref`` = (lat, lon, h), with the radii of
    ``ref`` (exact for the small offsets of a filter update)."""
    rm, rn = radii(ref[0])
    dlon = lon - ref[1]
    dlon -= 2.0 * math.pi * round(dlon / (2.0 * math.pi))
    return (
        (lat - ref[0]) * (rm + ref[2]),
        dlon * (rn + ref[2]) * math.cos(ref[0]),
        -(h - ref[2]),
    )


@njit(cache=True, error_model="numpy")
def antenna(X: F64, lever_b: F64, w_ib_b: F64, C: F64, out: F64) -> None:
    """The antenna context of state ``X`` (``AN_*`` layout) into ``out`` (``AN_DIM``,).

    Args:
        X: full state; lever_b: lever arm, body FRD, m; w_ib_b: measured angular rate (bias
            not yet removed), rad/s; C: scratch (3, 3).
    """
    dcm_into(X[X_Q : X_Q + 4], C)
    lat, h = X[X_LAT], X[X_H]
    sl, cl = math.sin(lat), math.cos(lat)
    w_ie = (OMEGA_IE * cl, 0.0, -OMEGA_IE * sl)
    # w_eb = w_ib - b_g - C^T w_ie; lever-arm position and velocity in NED
    wx = w_ib_b[0] - X[X_BG] - (C[0, 0] * w_ie[0] + C[2, 0] * w_ie[2])
    wy = w_ib_b[1] - X[X_BG + 1] - (C[0, 1] * w_ie[0] + C[2, 1] * w_ie[2])
    wz = w_ib_b[2] - X[X_BG + 2] - (C[0, 2] * w_ie[0] + C[2, 2] * w_ie[2])
    wxl = (
        wy * lever_b[2] - wz * lever_b[1],
        wz * lever_b[0] - wx * lever_b[2],
        wx * lever_b[1] - wy * lever_b[0],
    )
    for r in range(3):
        out[AN_CL + r] = C[r, 0] * lever_b[0] + C[r, 1] * lever_b[1] + C[r, 2] * lever_b[2]
        out[AN_U + r] = C[r, 0] * wxl[0] + C[r, 1] * wxl[1] + C[r, 2] * wxl[2]
        out[AN_VN + r] = X[X_VEL + r] + out[AN_U + r]
        for c in range(3):
            out[AN_C + 3 * r + c] = C[r, c]
    rm, rn = radii(lat)
    lat_a = lat + out[AN_CL] / (rm + h)
    lon_a = X[X_LON] + out[AN_CL + 1] / ((rn + h) * cl)
    h_a = h - out[AN_CL + 2]
    out[AN_LLH], out[AN_LLH + 1], out[AN_LLH + 2] = lat_a, lon_a, h_a
    sa, ca = math.sin(lat_a), math.cos(lat_a)
    so, co = math.sin(lon_a), math.cos(lon_a)
    rna = A / math.sqrt(1.0 - E2 * sa * sa)
    out[AN_RE] = (rna + h_a) * ca * co
    out[AN_RE + 1] = (rna + h_a) * ca * so
    out[AN_RE + 2] = (rna * (1.0 - E2) + h_a) * sa
    cen = out[AN_CEN : AN_CEN + 9]
    cen[0], cen[1], cen[2] = -sa * co, -sa * so, ca
    cen[3], cen[4], cen[5] = -so, co, 0.0
    cen[6], cen[7], cen[8] = -ca * co, -ca * so, -sa
    for j in range(3):  # v_e = C_e^n^T v_n
        out[AN_VE + j] = (
            cen[j] * out[AN_VN] + cen[3 + j] * out[AN_VN + 1] + cen[6 + j] * out[AN_VN + 2]
        )


@njit(cache=True, inline="always", error_model="numpy")
def _los(ant: F64, sat: F64) -> tuple[float, float, float, float]:
    """Range to the satellite and the ECEF unit vector from the antenna to it."""
    dx = sat[0] - ant[AN_RE]
    dy = sat[1] - ant[AN_RE + 1]
    dz = sat[2] - ant[AN_RE + 2]
    rng = math.sqrt(dx * dx + dy * dy + dz * dz)
    return rng, dx / rng, dy / rng, dz / rng


@njit(cache=True, error_model="numpy")
def pseudorange_h(ant: F64, X: F64, sat: F64) -> float:
    """Predicted pseudorange ``|r_sat - r_ant| + cb`` (m) for satellite ``sat[0:3]`` (ECEF)."""
    rng, _, _, _ = _los(ant, sat)
    return float(rng + X[X_CB])


@njit(cache=True, error_model="numpy")
def pseudorange_rate_h(ant: F64, X: F64, sat: F64) -> float:
    """Predicted pseudorange rate ``e . (v_sat - v_ant) + cd`` (m/s); ``sat[3:6]`` is the
    satellite ECEF velocity."""
    _, ex, ey, ez = _los(ant, sat)
    rate = (
        ex * (sat[3] - ant[AN_VE]) + ey * (sat[4] - ant[AN_VE + 1]) + ez * (sat[5] - ant[AN_VE + 2])
    )
    return float(rate + X[X_CD])


@njit(cache=True, inline="always", error_model="numpy")
def _los_ned(ant: F64, ex: float, ey: float, ez: float) -> tuple[float, float, float]:
    """An ECEF vector resolved in NED (``C_e^n`` of the antenna)."""
    c = ant[AN_CEN : AN_CEN + 9]
    return (
        c[0] * ex + c[1] * ey + c[2] * ez,
        c[3] * ex + c[4] * ey + c[5] * ez,
        c[6] * ex + c[7] * ey + c[8] * ez,
    )


@njit(cache=True, error_model="numpy")
def position_jac(ant: F64, axis: int, n: int, H_row: F64) -> None:
    """Jacobian row of the antenna position (NED ``axis``): ``[I, 0, -[(C l) x], 0, 0]``,
    plus the fix's own Gauss-Markov error (states 15, 16: north, east) where a loosely coupled
    filter carries it (``n > N_LOOSE``: only loose coupling has position rows)."""
    for c in range(n):
        H_row[c] = 0.0
    H_row[E_POS + axis] = 1.0
    if n > N_LOOSE and axis < 2:
        H_row[E_CB + axis] = 1.0
    cl0, cl1, cl2 = ant[AN_CL], ant[AN_CL + 1], ant[AN_CL + 2]
    for c in range(3):
        H_row[E_ATT + c] = -sk(cl0, cl1, cl2, axis, c)


@njit(cache=True, inline="always", error_model="numpy")
def _cross(
    a0: float, a1: float, a2: float, b0: float, b1: float, b2: float
) -> tuple[float, float, float]:
    """``a x b``; note ``a^T [b x] = (a x b)^T`` for the Jacobian rows below."""
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


@njit(cache=True, error_model="numpy")
def velocity_jac(ant: F64, lever_b: F64, axis: int, n: int, H_row: F64) -> None:
    """Jacobian row of the antenna NED velocity: ``H_v = I``, ``H_phi = -[u x]``,
    ``H_bg = C [l x]`` (its row ``axis``: ``(C_axis x l)^T``)."""
    for c in range(n):
        H_row[c] = 0.0
    H_row[E_VEL + axis] = 1.0
    u0, u1, u2 = ant[AN_U], ant[AN_U + 1], ant[AN_U + 2]
    row = AN_C + 3 * axis
    bg = _cross(ant[row], ant[row + 1], ant[row + 2], lever_b[0], lever_b[1], lever_b[2])
    for c in range(3):
        H_row[E_ATT + c] = -sk(u0, u1, u2, axis, c)
        H_row[E_BG + c] = bg[c]


@njit(cache=True, error_model="numpy")
def pseudorange_jac(ant: F64, sat: F64, n: int, H_row: F64) -> None:
    """Jacobian row of ``pseudorange_h``: ``H_r = -e^T``, ``H_phi = e^T [(C l) x]``,
    ``H_cb = 1`` (``e`` in NED)."""
    _, ex, ey, ez = _los(ant, sat)
    e = _los_ned(ant, ex, ey, ez)
    for c in range(n):
        H_row[c] = 0.0
    att = _cross(e[0], e[1], e[2], ant[AN_CL], ant[AN_CL + 1], ant[AN_CL + 2])
    for c in range(3):
        H_row[E_POS + c] = -e[c]
        H_row[E_ATT + c] = att[c]
    H_row[E_CB] = 1.0


@njit(cache=True, error_model="numpy")
def pseudorange_rate_jac(ant: F64, lever_b: F64, sat: F64, n: int, H_row: F64) -> None:
    """Jacobian row of ``pseudorange_rate_h``: ``H_v = -e^T``, ``H_phi = e^T [u x]``,
    ``H_bg = -e^T C [l x]``, ``H_r = -(dv - e (e . dv))^T / range``, ``H_cd = 1``."""
    rng, ex, ey, ez = _los(ant, sat)
    e = _los_ned(ant, ex, ey, ez)
    dv = _los_ned(ant, sat[3] - ant[AN_VE], sat[4] - ant[AN_VE + 1], sat[5] - ant[AN_VE + 2])
    edv = e[0] * dv[0] + e[1] * dv[1] + e[2] * dv[2]
    for c in range(n):
        H_row[c] = 0.0
    att = _cross(e[0], e[1], e[2], ant[AN_U], ant[AN_U + 1], ant[AN_U + 2])
    ce = (  # C^T e: e^T C [l x] = (C^T e x l)^T
        ant[AN_C] * e[0] + ant[AN_C + 3] * e[1] + ant[AN_C + 6] * e[2],
        ant[AN_C + 1] * e[0] + ant[AN_C + 4] * e[1] + ant[AN_C + 7] * e[2],
        ant[AN_C + 2] * e[0] + ant[AN_C + 5] * e[1] + ant[AN_C + 8] * e[2],
    )
    bg = _cross(ce[0], ce[1], ce[2], lever_b[0], lever_b[1], lever_b[2])
    for c in range(3):
        H_row[E_POS + c] = -(dv[c] - e[c] * edv) / rng
        H_row[E_VEL + c] = -e[c]
        H_row[E_ATT + c] = att[c]
        H_row[E_BG + c] = -bg[c]
    H_row[E_CD] = 1.0
