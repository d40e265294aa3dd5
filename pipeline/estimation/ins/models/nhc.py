"""Non-holonomic constraint of a land vehicle (paper 001, section "Non-holonomic constraint").

Unless the vehicle slides or leaves the ground, its velocity in the body frame has no lateral
and no vertical component: ``v^b = C_n^b v^n`` with ``v_y^b = 0`` and ``v_z^b = 0``, fused as
pseudo-measurements with noise covering sideslip, suspension travel and mounting error. The
constraint is applied at the IMU (the filter has no separate rear-axle lever arm; mount the
IMU near the rear axle or raise the noise).

With ``C_true = Exp(phi) C`` the body velocity perturbs as
``d(v^b) = C^T dv + C^T [v x] phi``, so ``H_v = C^T`` and ``H_phi = C^T [v^n x]`` (rows y, z).
"""

from __future__ import annotations

from navreplay.pipeline._jit import njit
from navreplay.pipeline.estimation.ins.models.gnss import AN_C, sk
from navreplay.pipeline.estimation.ins.models.ins import E_ATT, E_VEL, X_VEL
from navreplay.pipeline.nav.earth import F64


@njit(cache=True, error_model="numpy")
def body_velocity(X: F64, ant: F64, axis: int) -> float:
    """Component ``axis`` of the IMU velocity in body FRD, m/s (``ant``: antenna context of
    ``X``, for its ``C_b^n``)."""
    return float(
        ant[AN_C + axis] * X[X_VEL]
        + ant[AN_C + 3 + axis] * X[X_VEL + 1]
        + ant[AN_C + 6 + axis] * X[X_VEL + 2]
    )


@njit(cache=True, error_model="numpy")
def nhc_jac(X: F64, ant: F64, axis: int, n: int, H_row: F64) -> None:
    """Jacobian row of ``body_velocity(X, ant, axis)``: ``C^T`` and ``C^T [v x]`` rows."""
    v0, v1, v2 = X[X_VEL], X[X_VEL + 1], X[X_VEL + 2]
    for c in range(n):
        H_row[c] = 0.0
    for c in range(3):
        H_row[E_VEL + c] = ant[AN_C + 3 * c + axis]
        a = 0.0
        for k in range(3):
            a += ant[AN_C + 3 * k + axis] * sk(v0, v1, v2, k, c)
        H_row[E_ATT + c] = a
