"""Straight-line tracking LQR for the tractor (paper 000, eq. 8-14).

The lateral control state (eq. 11) is ``X_c = [y_err, psi_err, psi_dot, psi_ddot, delta,
delta_dot]`` (m, rad, rad/s, rad/s^2, rad, rad/s); the paper prints its third and fourth
elements as "psi" and "psi_dot", but its ``A_c`` makes them the yaw rate and yaw acceleration,
which is how they are used here. The input ``u`` is the steering-valve command of eq. 4 (with
``K_v = 1`` a steer-rate command, rad/s).

The gain is computed once from the continuous model ``(A_c, B_c)`` at the desired speed,
discretized exactly with the block matrix exponential of eq. 14, by solving the discrete
algebraic Riccati equation for the cost of eq. 13. The navigation and control filters of the
cascaded-filter issue use this same gain on their estimates; the synthesizer uses it on the
true state to record the open-loop dataset.

Sign conventions (paper 000 eq. 1-2): heading ``psi`` from north, clockwise (NED yaw), yaw
rate positive clockwise seen from above, steer angle positive to the right, East/North in m.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import scipy.linalg

from navreplay.ingest.typed import FieldError

F64 = npt.NDArray[np.float64]

#: Q_c of eq. 13: lateral error and steer angle weighted.
PAPER_Q_C: tuple[float, ...] = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0)
#: R_c of eq. 13.
PAPER_R_C = 0.1


@dataclass(frozen=True)
class YawSteerModel:
    """Identified yaw and steering dynamics of paper 000 eq. 3-4 (Table 3 at 3 m/s).

    Yaw (eq. 3, read as a second-order lag from steer angle to yaw rate):
    ``psi_dddot = -2 zeta w_n psi_ddot - w_n^2 psi_dot + K_R w_n^2 delta``.
    Steering valve (eq. 4): ``delta_ddot = -delta_dot / tau_v + K_v / tau_v u``.

    Attributes:
        k_r: DC gain from steer angle to yaw rate, (rad/s)/rad.
        zeta: yaw damping ratio.
        omega_n_radps: yaw natural frequency, rad/s.
        k_v: steering-valve DC gain, (rad/s) per unit command.
        tau_v_s: steering-valve time constant, s.
    """

    k_r: float = 1.0
    zeta: float = 0.35
    omega_n_radps: float = 6.4
    k_v: float = 1.0
    tau_v_s: float = 0.1053

    def __post_init__(self) -> None:
        if self.omega_n_radps <= 0:
            raise FieldError("omega_n_radps", "must be > 0")
        if self.tau_v_s <= 0:
            raise FieldError("tau_v_s", "must be > 0")
        if self.zeta < 0:
            raise FieldError("zeta", "must be >= 0")


def yaw_steer_model(model: YawSteerModel) -> tuple[F64, F64]:
    """Continuous yaw and steering dynamics (eq. 3-4) on ``[psi, psi_dot, psi_ddot, delta,
    delta_dot]``: ``A`` of shape (5, 5) and ``B`` of shape (5, 1), input ``u`` of eq. 4.

    The lateral control model (``lateral_model``) and the tractor simulator
    (``pipeline.synth.tractor``) both build on it.
    """
    wn = model.omega_n_radps
    a = np.zeros((5, 5))
    a[0, 1] = 1.0
    a[1, 2] = 1.0
    a[2, 1] = -(wn**2)
    a[2, 2] = -2.0 * model.zeta * wn
    a[2, 3] = model.k_r * wn**2
    a[3, 4] = 1.0
    a[4, 4] = -1.0 / model.tau_v_s
    b = np.zeros((5, 1))
    b[4, 0] = model.k_v / model.tau_v_s
    return a, b


def lateral_model(speed_mps: float, model: YawSteerModel) -> tuple[F64, F64]:
    """Continuous lateral control model ``(A_c, B_c)`` of eq. 11 at the desired speed.

    The lateral error ``y_err`` in front of ``yaw_steer_model`` (its heading is ``psi_err``).

    Returns:
        ``A_c`` of shape (6, 6) and ``B_c`` of shape (6, 1).
    """
    a5, b5 = yaw_steer_model(model)
    a = np.zeros((6, 6))
    a[0, 1] = speed_mps  # eq. 10: y_err_dot = V_x psi_err
    a[1:, 1:] = a5
    b = np.zeros((6, 1))
    b[1:] = b5
    return a, b


def discretize(a: F64, b: F64, dt_s: float) -> tuple[F64, F64]:
    """Zero-order-hold discretization by the block matrix exponential (eq. 14).

    ``expm([[A, B], [0, 0]] dt) = [[A_d, B_d], [0, I]]``.

    Args:
        a: shape (n, n). b: shape (n, m). dt_s: sample period, s.

    Returns:
        ``A_d`` (n, n) and ``B_d`` (n, m).
    """
    n, m = b.shape
    block = np.zeros((n + m, n + m))
    block[:n, :n] = a
    block[:n, n:] = b
    e = scipy.linalg.expm(block * dt_s)
    return e[:n, :n], e[:n, n:]


def dlqr(a_d: F64, b_d: F64, q: F64, r: F64) -> F64:
    """Infinite-horizon discrete LQR gain for ``u = -K x`` minimizing eq. 13.

    ``K = (R + B^T P B)^-1 B^T P A`` with ``P`` the stabilizing solution of the discrete
    algebraic Riccati equation.

    Returns:
        ``K`` of shape (m, n).

    Raises:
        ValueError: no stabilizing solution (the pair is not stabilizable/detectable).
    """
    try:
        p = scipy.linalg.solve_discrete_are(a_d, b_d, q, r)
    except (np.linalg.LinAlgError, ValueError) as err:
        raise ValueError(f"no stabilizing Riccati solution: {err}") from err
    gain: F64 = np.asarray(np.linalg.solve(r + b_d.T @ p @ b_d, b_d.T @ p @ a_d), np.float64)
    return gain


def tractor_lqr_gain(
    speed_mps: float,
    dt_s: float,
    model: YawSteerModel | None = None,
    q_diag: tuple[float, ...] = PAPER_Q_C,
    r: float = PAPER_R_C,
) -> F64:
    """The paper's straight-line tracking gain ``K_c`` (eq. 11-14), shape (6,).

    Args:
        speed_mps: desired forward speed ``V_x,d``, m/s (paper: 3).
        dt_s: controller sample period, s (paper: 0.02).
        model: yaw/steering dynamics (default: Table 3).
        q_diag: diagonal of ``Q_c`` (default: diag[1 0 0 0 1 0]).
        r: ``R_c`` (default 0.1).
    """
    a, b = lateral_model(speed_mps, model or YawSteerModel())
    a_d, b_d = discretize(a, b, dt_s)
    k = dlqr(a_d, b_d, np.diag(np.asarray(q_diag, dtype=np.float64)), np.array([[r]]))
    gain: F64 = k[0]
    return gain


@dataclass(frozen=True)
class StraightLine:
    """A desired straight line (eq. 8-9): through ``(east_m, north_m)`` with heading ``psi_d``.

    Attributes:
        east_m, north_m: a point of the line, m (local East/North).
        heading_rad: desired heading ``psi_d``, from north clockwise, rad.
    """

    east_m: float
    north_m: float
    heading_rad: float

    def lateral_error(self, east_m: float, north_m: float) -> float:
        """``y_err`` of eq. 9, m; positive when the vehicle is to the right of the line."""
        return (east_m - self.east_m) * math.cos(self.heading_rad) - (
            north_m - self.north_m
        ) * math.sin(self.heading_rad)

    def control_state(
        self,
        east_m: float,
        north_m: float,
        heading_rad: float,
        yaw_rate_radps: float,
        yaw_accel_radps2: float,
        steer_rad: float,
        steer_rate_radps: float,
    ) -> F64:
        """``X_c`` of eq. 11 from (estimated or true) vehicle states, shape (6,).

        The heading error (eq. 8) is wrapped to [-pi, pi).
        """
        psi_err = (heading_rad - self.heading_rad + math.pi) % (2.0 * math.pi) - math.pi
        return np.array(
            [
                self.lateral_error(east_m, north_m),
                psi_err,
                yaw_rate_radps,
                yaw_accel_radps2,
                steer_rad,
                steer_rate_radps,
            ]
        )


def lqr_command(gain: F64, control_state: F64) -> float:
    """``u = -K_c X_c`` (eq. 12)."""
    return -float(gain @ control_state)
