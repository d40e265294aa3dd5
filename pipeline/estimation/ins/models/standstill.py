"""Zero-velocity and zero-angular-rate updates of a vehicle at rest (ZUPT, ZARU).

While the vehicle stands still (``ins.standstill`` finds when), its IMU velocity is zero and
its gyros read the earth's rotation plus their bias. Two pseudo-measurements follow, fused at
the stops of the replay that lie inside a standstill interval:

- ZUPT: ``v^n = 0``, ``H_v = I``: holds velocity and position, and through the velocity's
  coupling with the tilt, roll and pitch and the horizontal accelerometer biases;
- ZARU: the mean angular rate of the IMU samples since the previous stop,
  ``w_mean = b_g + C_n^b w_ie^n``: with ``C_true = Exp(phi) C`` (``C = C_b^n``),
  ``d(C^T w) = C^T [w x] phi``, so ``H_bg = I`` and ``H_phi = C^T [w_ie^n x]``. It holds the
  gyro biases, the yaw's among them, which nothing else observes at rest.
"""

from __future__ import annotations

import math

from navreplay.pipeline._jit import njit
from navreplay.pipeline.estimation.ins.models.gnss import AN_C, sk
from navreplay.pipeline.estimation.ins.models.ins import E_ATT, E_BG, E_VEL, X_BG, X_LAT
from navreplay.pipeline.nav.earth import F64, OMEGA_IE


@njit(cache=True, error_model="numpy")
def _earth_rate_n(X: F64) -> tuple[float, float, float]:
    lat = X[X_LAT]
    return OMEGA_IE * math.cos(lat), 0.0, -OMEGA_IE * math.sin(lat)


@njit(cache=True, error_model="numpy")
def zaru_h(X: F64, ant: F64, axis: int) -> float:
    """Predicted angular rate about body ``axis`` at rest: gyro bias plus the earth rate in
    the body frame (``ant``: antenna context of ``X``, for its ``C_b^n``)."""
    w0, w1, w2 = _earth_rate_n(X)
    return float(
        X[X_BG + axis]
        + ant[AN_C + axis] * w0
        + ant[AN_C + 3 + axis] * w1
        + ant[AN_C + 6 + axis] * w2
    )


@njit(cache=True, error_model="numpy")
def zaru_jac(X: F64, ant: F64, axis: int, n: int, H_row: F64) -> None:
    """Jacobian row of ``zaru_h``: ``H_bg = I`` and the ``C^T [w_ie x]`` row."""
    w0, w1, w2 = _earth_rate_n(X)
    for c in range(n):
        H_row[c] = 0.0
    H_row[E_BG + axis] = 1.0
    for c in range(3):
        a = 0.0
        for k in range(3):
            a += ant[AN_C + 3 * k + axis] * sk(w0, w1, w2, k, c)
        H_row[E_ATT + c] = a


@njit(cache=True, error_model="numpy")
def zupt_jac(axis: int, n: int, H_row: F64) -> None:
    """Jacobian row of the IMU's NED velocity component ``axis``."""
    for c in range(n):
        H_row[c] = 0.0
    H_row[E_VEL + axis] = 1.0
