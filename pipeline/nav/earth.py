"""WGS-84 earth model for navigation-frame (NED) mechanization.

All functions are numba-compiled (``cache=True``) so estimator kernels can call them; they also
work from Python on floats and float64 arrays. Angles are radians, lengths metres.

References: NIMA TR8350.2 (WGS-84 constants, Somigliana normal gravity); Groves, *Principles
of GNSS, Inertial, and Multisensor Integrated Navigation Systems*, 2nd ed., ch. 2.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from navreplay.pipeline._jit import njit

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]

A = 6378137.0  # semi-major axis, m
F = 1.0 / 298.257223563  # flattening
B = A * (1.0 - F)  # semi-minor axis, m
E2 = F * (2.0 - F)  # first eccentricity squared
OMEGA_IE = 7.292115e-5  # earth rotation rate, rad/s
GM = 3.986004418e14  # gravitational constant, m^3/s^2
GAMMA_E = 9.7803253359  # normal gravity at the equator, m/s^2
K_SOMIGLIANA = 0.00193185265241
M_GRAV = OMEGA_IE**2 * A**2 * B / GM


@njit(cache=True, fastmath=False)
def radii(lat: float) -> tuple[float, float]:
    """Meridian (R_M, north-south) and transverse (R_N, east-west) radii of curvature, m."""
    s = math.sin(lat)
    w2 = 1.0 - E2 * s * s
    w = math.sqrt(w2)
    return A * (1.0 - E2) / (w2 * w), A / w


@njit(cache=True)
def gravity(lat: float, h: float) -> float:
    """Normal gravity magnitude (gravitation plus centrifugal), m/s^2, positive down.

    Somigliana's formula with the second-order free-air height correction (TR8350.2, 4-1 and
    4-3). The deflection of the normal away from the ellipsoid normal at height is neglected.
    """
    s2 = math.sin(lat) ** 2
    g0 = GAMMA_E * (1.0 + K_SOMIGLIANA * s2) / math.sqrt(1.0 - E2 * s2)
    return g0 * (1.0 - 2.0 / A * (1.0 + F + M_GRAV - 2.0 * F * s2) * h + 3.0 * h * h / (A * A))


@njit(cache=True)
def omega_ie_n(lat: float) -> F64:
    """Earth rotation rate resolved in NED, rad/s."""
    return np.array([OMEGA_IE * math.cos(lat), 0.0, -OMEGA_IE * math.sin(lat)])


@njit(cache=True)
def omega_en_n(lat: float, h: float, vn: float, ve: float) -> F64:
    """Transport rate (rotation of NED w.r.t. ECEF) resolved in NED, rad/s."""
    rm, rn = radii(lat)
    return np.array([ve / (rn + h), -vn / (rm + h), -ve * math.tan(lat) / (rn + h)])


@njit(cache=True)
def geodetic_to_ecef(lat: float, lon: float, h: float) -> F64:
    """Geodetic latitude, longitude (rad) and ellipsoidal height (m) to ECEF x, y, z (m)."""
    _, rn = radii(lat)
    cl = math.cos(lat)
    return np.array(
        [
            (rn + h) * cl * math.cos(lon),
            (rn + h) * cl * math.sin(lon),
            (rn * (1.0 - E2) + h) * math.sin(lat),
        ]
    )


@njit(cache=True)
def ecef_to_geodetic(x: float, y: float, z: float) -> tuple[float, float, float]:
    """ECEF (m) to geodetic latitude, longitude (rad) and height (m).

    Bowring's initial value refined by Newton iterations on latitude; accurate to well below
    a millimetre anywhere near the earth's surface.
    """
    lon = math.atan2(y, x)
    p = math.hypot(x, y)
    if p < 1e-9:
        lat = math.copysign(0.5 * math.pi, z)
        return lat, lon, abs(z) - B
    # Bowring (1976) start, refined by iterating lat = atan2(z + e^2 R_N sin(lat), p).
    ep2 = E2 / (1.0 - E2)
    theta = math.atan2(z * A, p * B)
    st, ct = math.sin(theta), math.cos(theta)
    lat = math.atan2(z + ep2 * B * st**3, p - E2 * A * ct**3)
    for _ in range(3):
        _, rn = radii(lat)
        lat = math.atan2(z + E2 * rn * math.sin(lat), p)
    sl, cl = math.sin(lat), math.cos(lat)
    h = p * cl + z * sl - A * math.sqrt(1.0 - E2 * sl * sl)
    return lat, lon, h


@njit(cache=True)
def dcm_ecef_to_ned(lat: float, lon: float) -> F64:
    """Rotation matrix C_e^n taking ECEF vectors to NED at (lat, lon)."""
    sl, cl = math.sin(lat), math.cos(lat)
    so, co = math.sin(lon), math.cos(lon)
    return np.array(
        [
            [-sl * co, -sl * so, cl],
            [-so, co, 0.0],
            [-cl * co, -cl * so, -sl],
        ]
    )


@njit(cache=True)
def ned_to_geodetic_offset(lat: float, h: float, dn: float, de: float) -> tuple[float, float]:
    """Small north/east displacement (m) to latitude/longitude increments (rad) at (lat, h)."""
    rm, rn = radii(lat)
    return dn / (rm + h), de / ((rn + h) * math.cos(lat))
