"""Planar vehicle models of paper 003: kinematic and dynamic (linear-tire) single track.

**State** (paper 003 eq. 18)::

    x = [v (m/s), beta (rad), psi (rad), X (m), Y (m)]

``v`` is the speed of the centre of gravity along its path, ``beta`` the sideslip angle at the
centre of gravity (course = psi + beta), ``psi`` the heading clockwise from north (NED, kept
unwrapped so that interacting-multiple-model mixing can average it), ``X`` north and ``Y``
east of the run's local origin.

**Input** (eq. 19): ``u = [v_whl, delta]``, the longitudinal (wheel) speed, m/s, and the
road-wheel steering angle, rad (positive = right turn, FRD).

**Measurements** (eq. 20): GPS speed ``v``, yaw rate, GPS course ``beta + psi`` (residual
wrapped to (-pi, pi]), GPS ``X`` and ``Y``. The dynamic model's yaw rate depends on the
steering input directly (``yaw_rate_steer_sens``), so the steering noise is part of that
row's measurement variance (``vehicle.kernel.epoch_values``).

Both models step with ``dt`` (the actual spacing of the vehicle samples) and hold ``u``
constant over the step:

- **kinematic** (no tire slip, low speed): ``beta' = atan(l_r tan(delta) / L)``,
  ``v' = v_whl / cos(beta')``, ``psi' = psi + dt v sin(beta) / l_r``;
- **dynamic** (linear tires, lateral force and slip, high speed): the single-track model with
  slip angles ``alpha_f = delta - beta - l_f r / v``, ``alpha_r = -beta + l_r r / v`` and axle
  forces ``F = C alpha``. Its yaw mode (time constant ``I_z v / (l_f^2 C_f + l_r^2 C_r)``, tens
  of milliseconds) is taken quasi-static, ``l_f F_f = l_r F_r``, which keeps the paper's
  five-element state: ``r = v (c1 delta + c2 beta) / D`` with ``D = l_f^2 C_f + l_r^2 C_r``,
  ``c1 = l_f C_f``, ``c2 = l_r C_r - l_f C_f``. The sideslip then obeys the linear ODE
  ``beta_dot = (F_f + F_r) / (m v) - r = a beta + b delta``, integrated exactly over the step
  (``beta' = e^(a dt) beta + (e^(a dt) - 1) / a * b delta``, stable at any speed; the
  coefficients use the input speed, floored at ``V_MIN``); ``v' = v_whl / cos(beta')``,
  ``psi' = psi + dt r``.

Positions advance along the mid-step course: ``X' = X + dt v cos(psi + beta + dt psi_dot / 2)``
(same for ``Y`` with sin). At low speed the dynamic model tends to the small-angle kinematic
model (both give ``beta = l_r delta / L``); it differs through the small-angle tire law
(``tan(delta)`` vs ``delta``: 7 % of yaw rate at 0.45 rad of steering) and, at speed, through
understeer and the sign change of the sideslip, which the kinematic model misses.

Process noise: ``Q = G diag(sigma_vwhl^2, sigma_delta^2) G^T + diag(q) dt`` with ``G`` the
input Jacobian (paper 003's ``G Q G^T``) and ``q`` white model-error densities.

``vp`` (``VP_DIM``) packs the vehicle: ``l_f, l_r, m, C_f, C_r`` (m, m, kg, N/rad, N/rad).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from navreplay.pipeline._jit import njit
from navreplay.pipeline.nav.earth import F64

NX = 5
X_V, X_BETA, X_PSI, X_N, X_E = 0, 1, 2, 3, 4
VP_LF, VP_LR, VP_M, VP_CF, VP_CR = 0, 1, 2, 3, 4
VP_DIM = 5
KINEMATIC, DYNAMIC = 0, 1
MODEL_NAMES = ("kinematic", "dynamic")
V_MIN = 0.5  # m/s: floor of the speed in the dynamic model's coefficients (v -> 0 singular)

# measurement kinds (rows of an update)
Z_SPEED, Z_YAW_RATE, Z_COURSE, Z_N, Z_E = 0, 1, 2, 3, 4


class ProcessNoise(NamedTuple):
    """What ``process_noise`` is made of: the input 1-sigma ``sig_u`` (2,), wheel speed (m/s)
    and steering (rad), and the white model-error densities ``q`` (5,), one per state."""

    sig_u: F64
    q: F64


@njit(cache=True)
def wrap_angle(a: float) -> float:
    """``a`` wrapped to (-pi, pi]."""
    two_pi = 2.0 * math.pi
    w = a + math.pi - two_pi * math.floor((a + math.pi) / two_pi)  # in [0, 2 pi)
    if w == 0.0:
        w = two_pi
    return w - math.pi


@njit(cache=True)
def dyn_coefficients(v: float, vp: F64) -> tuple[float, float, float, float, float]:
    """(a, b, c1/D, c2/D, D) of the dynamic model at speed ``v`` (see the module docstring)."""
    lf, lr, m, cf, cr = vp[VP_LF], vp[VP_LR], vp[VP_M], vp[VP_CF], vp[VP_CR]
    d = lf * lf * cf + lr * lr * cr
    c1 = lf * cf
    c2 = lr * cr - lf * cf
    vv = max(v, V_MIN)
    a = -(cf + cr - c2 * c2 / d) / (m * vv) - vv * c2 / d
    b = (cf + c1 * c2 / d) / (m * vv) - vv * c1 / d
    return a, b, c1 / d, c2 / d, d


@njit(cache=True)
def _beta_step(beta: float, v_in: float, delta: float, dt: float, vp: F64) -> tuple[float, float]:
    """Dynamic sideslip after ``dt`` and its derivative w.r.t. the previous sideslip."""
    a, b, _, _, _ = dyn_coefficients(v_in, vp)
    phi = math.exp(a * dt)
    return phi * beta + (phi - 1.0) / a * b * delta, phi


@njit(cache=True)
def yaw_rate(model: int, x: F64, delta: float, vp: F64) -> float:
    """The model's yaw rate at state ``x`` with steering ``delta``, rad/s (FRD: + = right)."""
    v, beta = float(x[X_V]), float(x[X_BETA])
    if model == KINEMATIC:
        return v * math.sin(beta) / float(vp[VP_LR])
    _, _, c1d, c2d, _ = dyn_coefficients(v, vp)
    return v * (c1d * delta + c2d * beta)


@njit(cache=True)
def yaw_rate_jac(model: int, x: F64, delta: float, vp: F64, out: F64) -> None:
    """d yaw_rate / dx into ``out`` (5,); the dynamic coefficients do not depend on ``x``."""
    out[:] = 0.0
    if model == KINEMATIC:
        out[X_V] = math.sin(x[X_BETA]) / vp[VP_LR]
        out[X_BETA] = x[X_V] * math.cos(x[X_BETA]) / vp[VP_LR]
        return
    _, _, c1d, c2d, _ = dyn_coefficients(x[X_V], vp)
    out[X_V] = c1d * delta + c2d * x[X_BETA]
    out[X_BETA] = x[X_V] * c2d


@njit(cache=True)
def yaw_rate_steer_sens(model: int, x: F64, delta: float, vp: F64) -> float:
    """d yaw_rate / d delta, (rad/s)/rad: how the steering input's own noise enters a yaw-rate
    prediction (``v c1 / D`` for the dynamic model, whose yaw rate is set by the steering of
    the same sample; 0 for the kinematic one, whose yaw rate follows the sideslip state)."""
    if model == KINEMATIC:
        return 0.0
    _, _, c1d, _, _ = dyn_coefficients(x[X_V], vp)
    return float(x[X_V] * c1d)


@njit(cache=True)
def step(model: int, x: F64, v_whl: float, delta: float, dt: float, vp: F64, out: F64) -> None:
    """Process model ``x' = f(x, u, dt)`` into ``out`` (may not alias ``x``)."""
    v, beta, psi = x[X_V], x[X_BETA], x[X_PSI]
    if model == KINEMATIC:
        beta_n = math.atan(vp[VP_LR] * math.tan(delta) / (vp[VP_LF] + vp[VP_LR]))
    else:
        beta_n, _ = _beta_step(beta, v_whl, delta, dt, vp)
    r = yaw_rate(model, x, delta, vp)
    th = psi + beta + 0.5 * dt * r
    out[X_V] = v_whl / math.cos(beta_n)
    out[X_BETA] = beta_n
    out[X_PSI] = psi + dt * r
    out[X_N] = x[X_N] + dt * v * math.cos(th)
    out[X_E] = x[X_E] + dt * v * math.sin(th)


@njit(cache=True)
def step_jac(model: int, x: F64, v_whl: float, delta: float, dt: float, vp: F64, F: F64) -> None:
    """State Jacobian ``F = df/dx`` (5, 5) of ``step``."""
    v, beta, psi = x[X_V], x[X_BETA], x[X_PSI]
    F[:, :] = 0.0
    dr = np.empty(NX)
    yaw_rate_jac(model, x, delta, vp, dr)
    r = yaw_rate(model, x, delta, vp)
    if model == KINEMATIC:
        beta_n = math.atan(vp[VP_LR] * math.tan(delta) / (vp[VP_LF] + vp[VP_LR]))
        dbeta = 0.0
    else:
        beta_n, dbeta = _beta_step(beta, v_whl, delta, dt, vp)
    c = math.cos(beta_n)
    F[X_V, X_BETA] = v_whl * math.sin(beta_n) / (c * c) * dbeta
    F[X_BETA, X_BETA] = dbeta
    F[X_PSI, X_V] = dt * dr[X_V]
    F[X_PSI, X_BETA] = dt * dr[X_BETA]
    F[X_PSI, X_PSI] = 1.0
    th = psi + beta + 0.5 * dt * r
    ct, st = math.cos(th), math.sin(th)
    dth_v, dth_b = 0.5 * dt * dr[X_V], 1.0 + 0.5 * dt * dr[X_BETA]
    F[X_N, X_V] = dt * (ct - v * st * dth_v)
    F[X_N, X_BETA] = -dt * v * st * dth_b
    F[X_N, X_PSI] = -dt * v * st
    F[X_N, X_N] = 1.0
    F[X_E, X_V] = dt * (st + v * ct * dth_v)
    F[X_E, X_BETA] = dt * v * ct * dth_b
    F[X_E, X_PSI] = dt * v * ct
    F[X_E, X_E] = 1.0


@njit(cache=True)
def input_jac(model: int, x: F64, v_whl: float, delta: float, dt: float, vp: F64, G: F64) -> None:
    """Input Jacobian ``G = df/du`` (5, 2), columns (v_whl, delta).

    The dynamic sideslip's dependence on ``v_whl`` (through the coefficients) is taken by a
    central difference: it only shapes the process noise.
    """
    G[:, :] = 0.0
    v, beta, psi = x[X_V], x[X_BETA], x[X_PSI]
    lf, lr = vp[VP_LF], vp[VP_LR]
    if model == KINEMATIC:
        k = lr / (lf + lr)
        t = math.tan(delta)
        beta_n = math.atan(k * t)
        db_dd = k * (1.0 + t * t) / (1.0 + k * k * t * t)
        db_dv = 0.0
        dr_dd = 0.0
    else:
        beta_n, _ = _beta_step(beta, v_whl, delta, dt, vp)
        a, b, c1d, _, _ = dyn_coefficients(v_whl, vp)
        db_dd = (math.exp(a * dt) - 1.0) / a * b
        h = 1e-4 * max(v_whl, 1.0)
        bp, _ = _beta_step(beta, v_whl + h, delta, dt, vp)
        bm, _ = _beta_step(beta, v_whl - h, delta, dt, vp)
        db_dv = (bp - bm) / (2.0 * h)
        dr_dd = v * c1d
    c = math.cos(beta_n)
    sec_tan = math.sin(beta_n) / (c * c)
    G[X_V, 0] = 1.0 / c + v_whl * sec_tan * db_dv
    G[X_V, 1] = v_whl * sec_tan * db_dd
    G[X_BETA, 0] = db_dv
    G[X_BETA, 1] = db_dd
    G[X_PSI, 1] = dt * dr_dd
    r = yaw_rate(model, x, delta, vp)
    th = psi + beta + 0.5 * dt * r
    G[X_N, 1] = -dt * v * math.sin(th) * 0.5 * dt * dr_dd
    G[X_E, 1] = dt * v * math.cos(th) * 0.5 * dt * dr_dd


@njit(cache=True, inline="always")
def process_noise(
    model: int, x: F64, v_whl: float, delta: float, dt: float, vp: F64, noise: ProcessNoise, Q: F64
) -> None:
    """``Q = G diag(sig_u^2) G^T + diag(q) dt`` (5, 5) of ``noise`` (``ProcessNoise``)."""
    sig_u, q = noise
    G = np.empty((NX, 2))
    input_jac(model, x, v_whl, delta, dt, vp, G)
    for i in range(NX):
        for j in range(NX):
            Q[i, j] = G[i, 0] * G[j, 0] * sig_u[0] ** 2 + G[i, 1] * G[j, 1] * sig_u[1] ** 2
        Q[i, i] += q[i] * dt


@njit(cache=True)
def measure(model: int, x: F64, delta: float, kind: int, vp: F64) -> float:
    """Predicted value of measurement ``kind`` (``Z_*``); the course is not wrapped."""
    if kind == Z_SPEED:
        return float(x[X_V])
    if kind == Z_YAW_RATE:
        return yaw_rate(model, x, delta, vp)
    if kind == Z_COURSE:
        return float(x[X_BETA] + x[X_PSI])
    if kind == Z_N:
        return float(x[X_N])
    return float(x[X_E])


@njit(cache=True)
def measure_jac(model: int, x: F64, delta: float, kind: int, vp: F64, out: F64) -> None:
    """Jacobian row (5,) of ``measure``."""
    if kind == Z_YAW_RATE:
        yaw_rate_jac(model, x, delta, vp, out)
        return
    out[:] = 0.0
    if kind == Z_SPEED:
        out[X_V] = 1.0
    elif kind == Z_COURSE:
        out[X_BETA] = 1.0
        out[X_PSI] = 1.0
    elif kind == Z_N:
        out[X_N] = 1.0
    else:
        out[X_E] = 1.0


@njit(cache=True)
def residual(kind: int, z: float, hx: float) -> float:
    """``z - h(x)``, wrapped to (-pi, pi] for the course."""
    d = z - hx
    return wrap_angle(d) if kind == Z_COURSE else d
