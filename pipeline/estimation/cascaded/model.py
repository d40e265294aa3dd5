"""The two models of paper 000's cascade as pure functions: f, F, h, H, Q, R.

Every function here is compiled with numba (``cache=True``) and is the *only* statement of
the physics: the compiled EKF/UKF/hybrid kernels, the filterpy reference backend and the
finite-difference tests all call these same functions.

**Navigation filter** (paper 000 eq. 15-17), state ``X1`` (``NAV_*`` indices)::

    X1 = [E (m), N (m), r_b (m/s), psi (rad), g_b (rad/s), psi_b (rad)]
    u1 = [V_x^radar (m/s), psi_dot^gyro (rad/s)]                         (inputs, eq. 16)
    E_dot = (V_x^radar - r_b) sin psi      N_dot = (V_x^radar - r_b) cos psi
    psi_dot = psi_dot^gyro - g_b           r_b, g_b, psi_b: random walks
    Y1 = [E^GPS, N^GPS, psi^GPS] = C1 X1,  psi^GPS = psi + psi_b         (heading row wraps)

The time update is the Euler step of eq. 22, ``X1+ = X1 + dt f(X1, u1)``, and ``F1 = I + dt
J1``. Paper 000 prints ``J1`` linearized "about the desired heading psi_d" with row 2 reading
``(V_x + r_b) sin(psi_d)``; the derivative of ``N_dot`` w.r.t. ``psi`` is ``-(V_x - r_b)
sin(psi)`` (a sign typo in the paper, invisible at its ``psi_d = 0``). ``nav_jacobian`` is the true
Jacobian of ``nav_f`` at the estimate (``JAC_ESTIMATE``), or, with ``JAC_DESIRED``, the
paper's linearization with ``psi`` replaced by ``psi_d`` (the corrected sign either way).

**Control filter** (paper 000 eq. 18-19), state ``X2`` (``CTL_*`` indices)::

    X2 = [psi_dot (rad/s), psi_ddot (rad/s^2), V_x (m/s), delta (rad), delta_dot (rad/s),
          delta_b (rad)]
    u  = steering-valve command (eq. 4; with K_v = 1 a steer-rate command, rad/s)
    psi_dddot = -w_n^2 psi_dot - 2 zeta w_n psi_ddot + K_R w_n^2 delta      (eq. 3)
    delta_ddot = -delta_dot / tau_v + K_v / tau_v u                          (eq. 4)
    Y2 = [psi_dot^meas, V^meas, delta^pot] = C2 X2,  delta^pot = delta + delta_b

The paper prints ``X2`` with ``psi_ddot`` twice and ``J2[1, 3] = K_R w_n``; its eq. 3, its
``A_c`` (eq. 11) and ``C2`` (which measures the first state with the yaw-rate sensor) make the
first state the yaw rate and the entry ``K_R w_n^2``, as the simulator
(``pipeline.synth.tractor``) integrates it. The model is linear, so the time update is eq.
23, ``X2+ = Phi X2 + Gamma u``, with ``(Phi, Gamma)`` the exact zero-order-hold discretization
of eq. 14 for the actual step (``ctl_discretize``, computed with the controller's own
``lqr.discretize`` and cached per step length).

**Noise**: ``Q`` is diagonal, Table 1's variances accumulated over ``noise_interval_s`` and
scaled linearly to the actual step, ``Q = q dt / noise_interval_s`` (with 1 s: Table 1 as
continuous densities discretized to first order, the reading ``config`` argues for; with
0.02 s: Table 1 as the variance of one paper step); ``R`` is diagonal, Table 2's variances.
"""

from __future__ import annotations

import math

import numpy as np

from navreplay.pipeline._jit import njit
from navreplay.pipeline.control.lqr import discretize
from navreplay.pipeline.nav.earth import F64

NX = 6  #: dimension of each filter's state
NZ = 3  #: rows of each filter's measurement vector

NAV_E, NAV_N, NAV_RB, NAV_PSI, NAV_GB, NAV_PSIB = 0, 1, 2, 3, 4, 5
CTL_PD, CTL_PDD, CTL_VX, CTL_DEL, CTL_DELD, CTL_DELB = 0, 1, 2, 3, 4, 5

U_RADAR, U_GYRO = 0, 1  #: navigation inputs u1
U_CMD = 0  #: control input u (steering command)

Z_E, Z_N, Z_PSI = 0, 1, 2  #: rows of Y1
Z_RATE, Z_SPEED, Z_STEER = 0, 1, 2  #: rows of Y2

MODEL_NAV, MODEL_CTL = 0, 1

#: model parameter vector ``par``: Table 3 and the linearization choice
P_WN, P_ZETA, P_KR, P_KV, P_TAUV, P_JAC, P_PSID = 0, 1, 2, 3, 4, 5, 6
PAR_DIM = 7
JAC_ESTIMATE, JAC_DESIRED = 0.0, 1.0

#: control discretization cache ``disc``: [dt, Phi (row-major 36), Gamma (6)]
DISC_DIM = 1 + NX * NX + NX


def model_params(
    omega_n_radps: float,
    zeta: float,
    k_r: float,
    k_v: float,
    tau_v_s: float,
    *,
    jacobian_at_desired: bool = False,
    desired_heading_rad: float = 0.0,
) -> F64:
    """Pack the model parameters (Table 3, linearization point) into ``par`` (``P_*``)."""
    par = np.zeros(PAR_DIM)
    par[P_WN], par[P_ZETA], par[P_KR], par[P_KV], par[P_TAUV] = (
        omega_n_radps,
        zeta,
        k_r,
        k_v,
        tau_v_s,
    )
    par[P_JAC] = JAC_DESIRED if jacobian_at_desired else JAC_ESTIMATE
    par[P_PSID] = desired_heading_rad
    return par


@njit(cache=True, error_model="numpy")
def wrap_pi(a: float) -> float:
    """Wrap an angle to [-pi, pi)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


@njit(cache=True, error_model="numpy")
def _zero(M: F64) -> None:
    for i in range(M.shape[0]):
        for j in range(M.shape[1]):
            M[i, j] = 0.0


# --- navigation filter (eq. 15-17) -------------------------------------------------------


@njit(cache=True, error_model="numpy")
def nav_f(x: F64, u: F64, dt: float, out: F64) -> None:
    """Euler time update of eq. 16/22: ``out = x + dt * x_dot(x, u1)``, shape (6,)."""
    v = u[U_RADAR] - x[NAV_RB]
    psi = x[NAV_PSI]
    for j in range(NX):
        out[j] = x[j]
    out[NAV_E] += dt * v * math.sin(psi)
    out[NAV_N] += dt * v * math.cos(psi)
    out[NAV_PSI] += dt * (u[U_GYRO] - x[NAV_GB])


@njit(cache=True, error_model="numpy")
def nav_jacobian(x: F64, u: F64, dt: float, par: F64, F: F64) -> None:
    """``F1 = I + dt J1`` (eq. 17, 22), (6, 6): the Jacobian of ``nav_f`` at ``x``, or with
    ``par[P_JAC] == JAC_DESIRED`` the paper's linearization about ``psi_d = par[P_PSID]``."""
    psi = par[P_PSID] if par[P_JAC] == JAC_DESIRED else x[NAV_PSI]
    v = u[U_RADAR] - x[NAV_RB]
    s, c = math.sin(psi), math.cos(psi)
    _zero(F)
    for j in range(NX):
        F[j, j] = 1.0
    F[NAV_E, NAV_RB] = -dt * s
    F[NAV_E, NAV_PSI] = dt * v * c
    F[NAV_N, NAV_RB] = -dt * c
    F[NAV_N, NAV_PSI] = -dt * v * s
    F[NAV_PSI, NAV_GB] = -dt


# --- control filter (eq. 18-19) ----------------------------------------------------------


@njit(cache=True, error_model="numpy")
def ctl_continuous(par: F64, A: F64, B: F64) -> None:
    """Continuous ``J2`` (6, 6) and ``B2`` (6,) of eq. 19 (with eq. 3's ``K_R w_n^2``)."""
    wn = par[P_WN]
    _zero(A)
    for j in range(NX):
        B[j] = 0.0
    A[CTL_PD, CTL_PDD] = 1.0
    A[CTL_PDD, CTL_PD] = -(wn * wn)
    A[CTL_PDD, CTL_PDD] = -2.0 * par[P_ZETA] * wn
    A[CTL_PDD, CTL_DEL] = par[P_KR] * wn * wn
    A[CTL_DEL, CTL_DELD] = 1.0
    A[CTL_DELD, CTL_DELD] = -1.0 / par[P_TAUV]
    B[CTL_DELD] = par[P_KV] / par[P_TAUV]


def ctl_discretize(par: F64, dt: float) -> F64:
    """Exact zero-order-hold ``(Phi, Gamma)`` of eq. 19 over ``dt``, by eq. 14 exactly as the
    controller computes it (``pipeline.control.lqr.discretize``), as a ``disc`` array
    ``[dt, Phi (36), Gamma (6)]``. Called outside the compiled loop, once per distinct step
    length (``engine.CascadeState`` caches it)."""
    A = np.empty((NX, NX))
    B = np.empty(NX)
    ctl_continuous(par, A, B)
    a_d, b_d = discretize(A, B[:, None], dt)
    disc = np.empty(DISC_DIM)
    disc[0] = dt
    disc[1 : 1 + NX * NX] = a_d.ravel()
    disc[1 + NX * NX :] = b_d[:, 0]
    return disc


@njit(cache=True, error_model="numpy")
def ctl_f(x: F64, u: F64, disc: F64, out: F64) -> None:
    """Time update of eq. 23: ``out = Phi x + Gamma u`` (``disc`` from ``ctl_discretize``
    for this step)."""
    for i in range(NX):
        a = disc[1 + NX * NX + i] * u[U_CMD]
        for j in range(NX):
            a += disc[1 + i * NX + j] * x[j]
        out[i] = a


@njit(cache=True, error_model="numpy")
def ctl_jacobian(disc: F64, F: F64) -> None:
    """``Phi`` (6, 6) of the cached discretization, the Jacobian of ``ctl_f``."""
    for i in range(NX):
        for j in range(NX):
            F[i, j] = disc[1 + i * NX + j]


# --- one interface over both models ------------------------------------------------------


@njit(cache=True, error_model="numpy")
def model_f(model: int, x: F64, u: F64, dt: float, par: F64, disc: F64, out: F64) -> None:
    """Time update ``f`` of ``model`` (``MODEL_NAV``, or ``MODEL_CTL`` with ``disc`` from
    ``ctl_discretize(par, dt)``)."""
    if model == MODEL_NAV:
        nav_f(x, u, dt, out)
    else:
        ctl_f(x, u, disc, out)


@njit(cache=True, error_model="numpy")
def model_jacobian(model: int, x: F64, u: F64, dt: float, par: F64, disc: F64, F: F64) -> None:
    """Transition matrix ``F`` (6, 6) of ``model`` at ``x``."""
    if model == MODEL_NAV:
        nav_jacobian(x, u, dt, par, F)
    else:
        ctl_jacobian(disc, F)


#: ``C1`` and ``C2`` by their unit entries (row, state), all others zero: ``Y1`` is East,
#: North and the GPS heading ``psi + psi_b`` (unwrapped), ``Y2`` the yaw rate, the speed and
#: the potentiometer ``delta + delta_b``
NAV_C = np.array([[Z_E, NAV_E], [Z_N, NAV_N], [Z_PSI, NAV_PSI], [Z_PSI, NAV_PSIB]], np.int64)
CTL_C = np.array(
    [[Z_RATE, CTL_PD], [Z_SPEED, CTL_VX], [Z_STEER, CTL_DEL], [Z_STEER, CTL_DELB]], np.int64
)


@njit(cache=True, error_model="numpy")
def model_h(model: int, x: F64, out: F64) -> None:
    """All three measurement rows ``h(x) = C x`` of ``model`` (``Y1 = C1 X1``,
    ``Y2 = C2 X2``; ``NAV_C``, ``CTL_C``)."""
    unit = NAV_C if model == MODEL_NAV else CTL_C
    for i in range(NZ):
        out[i] = 0.0
    for k in range(unit.shape[0]):
        out[unit[k, 0]] += x[unit[k, 1]]


@njit(cache=True, error_model="numpy")
def model_meas_jacobian(model: int, H: F64) -> None:
    """Measurement Jacobian ``H = C`` (3, 6) of ``model`` (constant)."""
    unit = NAV_C if model == MODEL_NAV else CTL_C
    _zero(H)
    for k in range(unit.shape[0]):
        H[unit[k, 0], unit[k, 1]] = 1.0


@njit(cache=True, error_model="numpy")
def is_angle_row(model: int, row: int) -> bool:
    """Whether residuals of this measurement row wrap to [-pi, pi) (the GPS heading)."""
    return model == MODEL_NAV and row == Z_PSI


@njit(cache=True, error_model="numpy")
def model_noise(q_diag: F64, dt: float, noise_interval_s: float, Q: F64) -> None:
    """Diagonal process noise over ``dt``: Table 1 variances per ``noise_interval_s``."""
    _zero(Q)
    scale = dt / noise_interval_s
    for j in range(NX):
        Q[j, j] = q_diag[j] * scale
