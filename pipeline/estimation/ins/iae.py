"""Innovation-based adaptive estimation of the GNSS measurement noise (``iae_ekf``).

The standard adaptive Kalman filter that issue 22 sets beside paper 004's fuzzy weighting:
Mohamed and Schwarz (1999, "Adaptive Kalman filtering for INS/GPS", J. Geodesy 73:193-203)
estimate the measurement covariance from the innovation sequence over a moving window of
``N`` epochs,

    C_nu = (1/N) sum_j nu_j nu_j^T,        R^ = C_nu - H P- H^T,

since a consistent filter's innovations have the covariance ``H P- H^T + R``. We use its
diagonal pooled over four groups of the fix rows (horizontal position, vertical position,
horizontal velocity, vertical velocity: one receiver, one accuracy per group), as a multiplier
of the variances the log declares (or the learned ones, ``fixnoise``):

    s_g = clip((sum nu^2 - sum (H P- H^T)_ii) / sum R_ii, scale_min, scale_max)

over the rows of group ``g`` in the window (accepted by the gate or not: a gate that hid the
large innovations would blind the estimator to an optimistic receiver). The multipliers take
effect at the next fix, in the gate as in the update (``records.Epoch.r_scale``), so the gate
judges the innovations against the noise the filter now assumes. Until ``min_epochs`` fixes
are in the window the declared variances are used. The bounds keep the estimate from running
away: an estimate below zero (innovations smaller than the filter's own prior spread) means
the prior is conservative, not that the receiver is perfect.

With ``lc_ekf``'s GNSS model (params.yaml) the fix errors' correlated part is carried as
Gauss-Markov states (``inputs.prepare_fixes``), so the innovations hold the white rest whose
variance the IAE estimates; where the fixes are white, it is the whole fix variance.

The IAE adapts R only; its process noise stays that of ``lc_ekf`` (Mohamed and Schwarz's
Q-adaptation is known to destabilise a 15-state INS filter and is left out).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from navreplay.ingest.typed import FieldError
from navreplay.pipeline._jit import njit
from navreplay.pipeline.estimation.ins.fuzzy import (
    FZ_AMAX,
    FZ_AMIN,
    FZ_DIM,
    FZ_MODE,
    FZ_START,
    FZ_WINDOW,
    MODE_IAE,
)
from navreplay.pipeline.nav.earth import F64, I64

#: kinds of fix rows (``measurement.K_PR``): the ring holds three columns per kind
N_KINDS = 6
#: the group of each fix-row kind (``models.measurement`` K_POS + axis, K_VEL + axis):
#: horizontal position, vertical position, horizontal velocity, vertical velocity
GROUP_OF_KIND = np.array([0, 0, 1, 2, 2, 3], dtype=np.int64)
N_GROUPS = 4


@dataclass(frozen=True)
class IaeParams:
    """``filters.iae_ekf.iae``: the window and bounds of the adaptive R.

    Attributes:
        window: GNSS epochs of the innovation statistics (N).
        min_epochs: epochs in the window before the estimate is used.
        scale_min, scale_max: bounds of the multiplier of the declared variances.
    """

    window: int = 30
    min_epochs: int = 10
    scale_min: float = 0.25
    scale_max: float = 1000.0

    def __post_init__(self) -> None:
        if not 2 <= self.window <= 1000:
            raise FieldError("window", "must be within 2..1000")
        if not 1 <= self.min_epochs <= self.window:
            raise FieldError("min_epochs", "must be within 1..window")
        if not 0.0 < self.scale_min <= 1.0 <= self.scale_max:
            raise FieldError("scale_min", "need 0 < scale_min <= 1 <= scale_max")

    def vector(self) -> F64:
        """Packed for the adaptive kernel (``fuzzy.FZ_*`` layout, ``FZ_MODE`` = IAE)."""
        v = np.zeros(FZ_DIM)
        v[FZ_MODE] = MODE_IAE
        v[FZ_WINDOW] = self.window
        v[FZ_START] = self.min_epochs
        v[FZ_AMIN], v[FZ_AMAX] = self.scale_min, self.scale_max
        return v


@njit(cache=True)
def push_innovations(
    ring: F64, count: int, rows: I64, nu: F64, S: F64, r: F64, r_scale: F64, m: int
) -> int:
    """Append one epoch's fix rows to the ring (window, 3 N_KINDS): per kind ``nu^2``, the
    prior spread ``(H P- H^T)_ii = S_ii - r_i`` and the declared variance ``r_i / r_scale``;
    returns the new count."""
    slot = count % ring.shape[0]
    ring[slot, :] = math.nan
    for k in range(m):
        kind = rows[k, 0]
        if kind < N_KINDS:
            ring[slot, kind] = nu[k] * nu[k]
            ring[slot, N_KINDS + kind] = S[k, k] - r[k]
            ring[slot, 2 * N_KINDS + kind] = r[k] / r_scale[kind]
    return count + 1


@njit(cache=True)
def iae_scales(ring: F64, count: int, fz: F64, r_scale: F64) -> None:
    """The multipliers of the declared variances per fix-row kind, in place (module)."""
    if count < fz[FZ_START]:
        return
    use = min(count, ring.shape[0])
    sums = np.zeros((N_GROUPS, 3))
    for kind in range(N_KINDS):
        g = GROUP_OF_KIND[kind]
        for j in range(use):
            if math.isfinite(ring[j, kind]):
                for c in range(3):
                    sums[g, c] += ring[j, c * N_KINDS + kind]
    for kind in range(N_KINDS):
        sq, spread, declared = sums[GROUP_OF_KIND[kind]]
        if declared > 0.0:
            r_scale[kind] = min(max((sq - spread) / declared, fz[FZ_AMIN]), fz[FZ_AMAX])
