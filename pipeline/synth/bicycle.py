"""Single-track (bicycle) car model with linear tires: the truth model of ``car_speed_ramp``.

The planar rigid body has longitudinal speed ``u`` (prescribed by the driver), lateral speed
``v_y`` and yaw rate ``r`` (body FRD: y right, r positive clockwise seen from above), heading
``psi`` from north. Each axle's lateral force is its cornering stiffness times its slip angle
(linear tires, paper 003's dynamic model, after Rajamani 2006 ch. 2)::

    alpha_f = delta - atan((v_y + l_f r) / u)        F_f = C_f alpha_f
    alpha_r =       - atan((v_y - l_r r) / u)        F_r = C_r alpha_r
    m (v_y_dot + u r) = F_f cos(delta) + F_r
    I_z r_dot         = l_f F_f cos(delta) - l_r F_r
    psi_dot = r

The slip angles keep their exact kinematics (atan) so that at low speed, where the forces
vanish, the model tends to the kinematic bicycle (``tan(alpha) -> 0``: ``r = u tan(delta) / L``,
``beta = atan(l_r tan(delta) / L)``); at speed it shows the sideslip and understeer a kinematic
model misses. For small angles the steady-state yaw rate is the textbook
``r = u delta / (L + K u^2)`` with understeer gradient ``K = m (l_r / C_f - l_f / C_r) / L``.

Position is integrated as geodetic latitude/longitude along the path (constant height), so the
truth is consistent with the NED velocity everywhere. The kernel is numba-compiled RK4.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from navreplay.pipeline._jit import njit
from navreplay.pipeline.nav.earth import radii
from navreplay.pipeline.synth.checks import require_positive

F64 = npt.NDArray[np.float64]

#: Output columns of ``simulate``.
COLUMNS = (
    "v_y_mps",
    "r_radps",
    "psi_rad",
    "lat_rad",
    "lon_rad",
    "a_y_mps2",
    "alpha_f_rad",
    "alpha_r_rad",
)


@dataclass(frozen=True)
class VehicleParams:
    """Mass, geometry and tire stiffness of the car (a mid-size sedan by default).

    Attributes:
        mass_kg: vehicle mass.
        yaw_inertia_kgm2: moment of inertia about the vertical axis.
        cg_to_front_m: distance from the centre of gravity to the front axle, ``l_f``.
        cg_to_rear_m: distance to the rear axle, ``l_r``.
        cornering_stiffness_front_npr: front axle (both tires), N/rad.
        cornering_stiffness_rear_npr: rear axle (both tires), N/rad.
    """

    mass_kg: float = 1500.0
    yaw_inertia_kgm2: float = 2250.0
    cg_to_front_m: float = 1.2
    cg_to_rear_m: float = 1.5
    cornering_stiffness_front_npr: float = 80_000.0
    cornering_stiffness_rear_npr: float = 100_000.0

    def __post_init__(self) -> None:
        require_positive(self)

    @property
    def wheelbase_m(self) -> float:
        return self.cg_to_front_m + self.cg_to_rear_m

    @property
    def understeer_gradient_rad_per_mps2(self) -> float:
        """``K = m (l_r / C_f - l_f / C_r) / L`` (rad per m/s^2 of lateral acceleration)."""
        return (
            self.mass_kg
            / self.wheelbase_m
            * (
                self.cg_to_rear_m / self.cornering_stiffness_front_npr
                - self.cg_to_front_m / self.cornering_stiffness_rear_npr
            )
        )

    def steady_state_yaw_rate(self, speed_mps: float, steer_rad: float) -> float:
        """Small-angle steady-state yaw rate ``u delta / (L + K u^2)``, rad/s."""
        k = self.understeer_gradient_rad_per_mps2
        return speed_mps * steer_rad / (self.wheelbase_m + k * speed_mps**2)

    def as_tuple(self) -> tuple[float, float, float, float, float, float]:
        return (
            self.mass_kg,
            self.yaw_inertia_kgm2,
            self.cg_to_front_m,
            self.cg_to_rear_m,
            self.cornering_stiffness_front_npr,
            self.cornering_stiffness_rear_npr,
        )


@njit(cache=True)
def _lateral(
    vy: float, r: float, u: float, delta: float, p: tuple[float, float, float, float, float, float]
) -> tuple[float, float, float, float]:
    """(v_y_dot, r_dot, alpha_f, alpha_r) of the linear-tire bicycle model."""
    m, iz, lf, lr, cf, cr = p
    af = delta - math.atan2(vy + lf * r, u)
    ar = -math.atan2(vy - lr * r, u)
    ff = cf * af * math.cos(delta)
    fr = cr * ar
    return (ff + fr) / m - u * r, (lf * ff - lr * fr) / iz, af, ar


@njit(cache=True)
def _derivative(
    s: F64,
    u: float,
    delta: float,
    p: tuple[float, float, float, float, float, float],
    h: float,
    out: F64,
) -> None:
    vy, r, psi, lat = s[0], s[1], s[2], s[3]
    dvy, dr, _, _ = _lateral(vy, r, u, delta, p)
    rm, rn = radii(lat)
    vn = u * math.cos(psi) - vy * math.sin(psi)
    ve = u * math.sin(psi) + vy * math.cos(psi)
    out[0] = dvy
    out[1] = dr
    out[2] = r
    out[3] = vn / (rm + h)
    out[4] = ve / ((rn + h) * math.cos(lat))


@njit(cache=True)
def simulate(
    u_half: F64,
    delta_half: F64,
    step_s: float,
    out_every: int,
    p: tuple[float, float, float, float, float, float],
    psi0: float,
    lat0: float,
    lon0: float,
    h: float,
) -> F64:
    """Integrate the model from rest laterally (v_y = r = 0) with RK4.

    Args:
        u_half, delta_half: longitudinal speed (m/s, > 0) and road-wheel steer angle (rad) on
            the half-step grid ``t = j * step_s / 2``, shape (2 n + 1,) for n steps.
        step_s: RK4 step, s.
        out_every: record every ``out_every`` steps (the first sample is t = 0).
        p: ``VehicleParams.as_tuple()``.
        psi0, lat0, lon0: initial heading, latitude, longitude (rad); h: height (m).

    Returns:
        shape (n // out_every + 1, 8), columns ``COLUMNS``.
    """
    n = (u_half.size - 1) // 2
    rows = n // out_every + 1
    out = np.empty((rows, 8))
    s = np.array([0.0, 0.0, psi0, lat0, lon0])
    y = np.empty(5)
    k1, k2, k3, k4 = np.empty(5), np.empty(5), np.empty(5), np.empty(5)
    row = 0
    for i in range(n + 1):
        if i % out_every == 0:
            dvy, _, af, ar = _lateral(s[0], s[1], u_half[2 * i], delta_half[2 * i], p)
            out[row, :5] = s
            out[row, 5] = dvy + u_half[2 * i] * s[1]
            out[row, 6] = af
            out[row, 7] = ar
            row += 1
        if i == n:
            break
        u0, um, u1 = u_half[2 * i], u_half[2 * i + 1], u_half[2 * i + 2]
        d0, dm, d1 = delta_half[2 * i], delta_half[2 * i + 1], delta_half[2 * i + 2]
        _derivative(s, u0, d0, p, h, k1)
        for j in range(5):
            y[j] = s[j] + 0.5 * step_s * k1[j]
        _derivative(y, um, dm, p, h, k2)
        for j in range(5):
            y[j] = s[j] + 0.5 * step_s * k2[j]
        _derivative(y, um, dm, p, h, k3)
        for j in range(5):
            y[j] = s[j] + step_s * k3[j]
        _derivative(y, u1, d1, p, h, k4)
        for j in range(5):
            s[j] += step_s / 6.0 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j])
    return out
