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

import numba as nb
import numpy as np

from pipeline.estimation.models.ins import E_ATT, E_VEL, X_Q, X_VEL
from pipeline.nav.earth import F64
from pipeline.nav.rotations import quat_to_dcm


@nb.njit(cache=True)
def body_velocity(X: F64) -> F64:
    """Velocity of the IMU in body FRD, m/s, shape (3,)."""
    return quat_to_dcm(X[X_Q : X_Q + 4]).T @ X[X_VEL : X_VEL + 3]


@nb.njit(cache=True)
def nhc_jac(X: F64, n: int) -> F64:
    """Jacobian of ``body_velocity(X)[1:3]`` w.r.t. the error state, shape (2, n)."""
    ct = quat_to_dcm(X[X_Q : X_Q + 4]).T
    v = X[X_VEL : X_VEL + 3]
    vx = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    att = ct @ vx
    H = np.zeros((2, n))
    for r in range(2):
        for c in range(3):
            H[r, E_VEL + c] = ct[1 + r, c]
            H[r, E_ATT + c] = att[1 + r, c]
    return H
