"""The Takagi-Sugeno fuzzy system of paper 004 that sets the fading factor alpha of the FWEKF.

Inputs (paper 004 eq. 31-32), over the last ``window`` GNSS epochs of normalized innovations
``e = nu / sqrt(S_ii)`` (position and velocity components, prior covariance):

- ``mean``: the RMS over components of the windowed mean of ``e`` (eq. 31), scaled by the
  square root of the number of epochs in the window and less one, floored at zero: white
  residuals give a windowed mean of about ``1 / sqrt(window)``, so the input is about zero
  for a consistent filter and grows with a bias in the measurements or a drifting state;
- ``cov``: the windowed mean of ``e^2`` less one (eq. 32: the residual covariance relative
  to the one the filter predicts, eq. 28): zero for a consistent filter, positive when the
  residuals are larger than the filter expects (its covariance too small, or the
  measurements worse than declared).

Both inputs are the *excess over a consistent filter*, dimensionless, so one set of
memberships serves any sensor and "Zero" means "nothing to adapt". Each input has three
Gaussian memberships, Zero / Small / Large (centres and widths in ``FuzzyParams``). The nine
rules of Table 1 map (mean, cov) to an output label::

                 cov: Zero   Small   Large
    mean Zero        Z       S       S
    mean Small       S       L       S
    mean Large       Z       NS      NS

Firing strengths are products of memberships (eq. 30, product implication) and the output is
their weighted average (eq. 29, the centroid of the Takagi-Sugeno singletons). The consequents
are increments of the fading factor, ``alpha = 1 + sum(w y) / sum(w)``, clipped to
``[alpha_min, alpha_max]``: Z keeps the plain EKF (alpha = 1), S and L fade old information
(alpha > 1 inflates the prior covariance, ``P- = alpha^2 Phi P Phi^T + Q``, paper eq. 26,
so recent measurements weigh more), NS (alpha < 1) trusts the model more when the residual
mean is large without a matching covariance increase (a measurement bias, which the paper's
controller is meant to detect). A consequent may also grow linearly with ``cov``
(``cov_slope``: the paper's "linear combination of the input variable covariance").

What is *our reading*, not the paper's text (the paper gives eq. 29-32, Table 1 and
"Gaussian" memberships; its Fig. 3, the membership functions, is not readable in the text
we have, and it states no window, no normalisation and no consequent values):

- the residuals are normalized by the unweighted prior innovation covariance of eq. 28
  (``S = H P- H^T + R``, R as declared), per component, position and velocity rows;
- the two inputs are the excesses over a consistent filter defined above (the
  ``sqrt(N)`` scaling of the mean and the ``- 1`` offsets are ours); a consequence: with
  white residuals of scale ``s`` the mean input is about ``s - 1``, so a large white
  residual (an optimistic receiver, fault F8) reads as a Large mean, like a bias;
- the window (10 fixes), the centres and widths of the Zero/Small/Large sets, the
  shoulders of the outer sets, the consequents as increments of alpha and their values,
  and the bounds on alpha are ours (``FuzzyParams`` defaults = params.yaml
  ``filters.fwekf.fuzzy``), chosen so that consistent residuals give alpha = 1 and never
  tuned to reproduce the paper's curves.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from navreplay.ingest.typed import FieldError
from navreplay.pipeline._jit import njit
from navreplay.pipeline.nav.earth import F64, I64

Z, S, L, NS = 0, 1, 2, 3
LABELS = ("Z", "S", "L", "NS")
#: Table 1 of paper 004: RULES[mean label][cov label] -> output label (Zero, Small, Large).
RULES = np.array([[Z, S, S], [S, L, S], [Z, NS, NS]], dtype=np.int64)

FZ_MEAN_C, FZ_MEAN_S, FZ_COV_C, FZ_COV_S, FZ_OUT = 0, 3, 6, 9, 12
FZ_SLOPE, FZ_AMIN, FZ_AMAX, FZ_WINDOW = 16, 17, 18, 19
#: the adaptive kernel's mode (fuzzy fading, or ``iae``'s adaptive R: its bounds in
#: FZ_AMIN / FZ_AMAX, the epochs before it adapts in FZ_START)
FZ_MODE, FZ_START = 20, 21
FZ_DIM = 22
MODE_FUZZY, MODE_IAE = 0, 1


@dataclass(frozen=True)
class FuzzyParams:
    """``filters.fwekf.fuzzy``: memberships, consequents and bounds of the fuzzy system.

    Attributes:
        window: number of GNSS epochs of the residual statistics (eq. 31-32).
        mean_centers: Zero, Small, Large centres of the residual-mean input.
        mean_sigmas: their Gaussian widths.
        cov_centers: Zero, Small, Large centres of the residual-covariance input.
        cov_sigmas: their widths.
        outputs: consequents Z, S, L, NS (increments of alpha).
        cov_slope: added to every consequent per unit of the covariance input.
        alpha_min, alpha_max: bounds of alpha.
    """

    window: int = 10
    mean_centers: tuple[float, float, float] = (0.0, 2.0, 5.0)
    mean_sigmas: tuple[float, float, float] = (0.5, 0.6, 1.5)
    cov_centers: tuple[float, float, float] = (0.0, 1.5, 6.0)
    cov_sigmas: tuple[float, float, float] = (0.4, 0.5, 2.0)
    outputs: tuple[float, float, float, float] = (0.0, 0.05, 0.15, -0.02)
    cov_slope: float = 0.0
    alpha_min: float = 0.98
    alpha_max: float = 1.3

    def __post_init__(self) -> None:
        if not 2 <= self.window <= 1000:
            raise FieldError("window", "must be within 2..1000")
        for name in ("mean_centers", "cov_centers"):
            c = getattr(self, name)
            if not c[0] < c[1] < c[2]:
                raise FieldError(name, "must be increasing (Zero < Small < Large)")
        for name in ("mean_sigmas", "cov_sigmas"):
            if min(getattr(self, name)) <= 0:
                raise FieldError(name, "must be > 0")
        if not 0.0 < self.alpha_min <= 1.0 <= self.alpha_max:
            raise FieldError("alpha_min", "need 0 < alpha_min <= 1 <= alpha_max")

    def vector(self) -> F64:
        """Packed for the kernels (``FZ_*`` layout)."""
        v = np.zeros(FZ_DIM)
        v[FZ_MEAN_C : FZ_MEAN_C + 3] = self.mean_centers
        v[FZ_MEAN_S : FZ_MEAN_S + 3] = self.mean_sigmas
        v[FZ_COV_C : FZ_COV_C + 3] = self.cov_centers
        v[FZ_COV_S : FZ_COV_S + 3] = self.cov_sigmas
        v[FZ_OUT : FZ_OUT + 4] = self.outputs
        v[FZ_SLOPE], v[FZ_AMIN], v[FZ_AMAX] = self.cov_slope, self.alpha_min, self.alpha_max
        v[FZ_WINDOW] = self.window
        return v


@njit(cache=True)
def membership(x: float, center: float, sigma: float) -> float:
    """Gaussian membership ``exp(-(x - c)^2 / (2 sigma^2))``."""
    d = (x - center) / sigma
    return math.exp(-0.5 * d * d)


@njit(cache=True)
def memberships(x: float, fz: F64, first_c: int, first_s: int) -> F64:
    """Zero, Small, Large memberships of one input; the outer sets are shoulders (an input
    beyond the Large centre is fully Large, below the Zero centre fully Zero)."""
    out = np.empty(3)
    for j in range(3):
        c = fz[first_c + j]
        if (j == 0 and x <= c) or (j == 2 and x >= c):
            out[j] = 1.0
        else:
            out[j] = membership(x, c, fz[first_s + j])
    return out


@njit(cache=True)
def infer_alpha(mean_in: float, cov_in: float, fz: F64, rules: I64) -> float:
    """alpha from the two inputs: the nine rules, product firing, weighted average, bounds."""
    mu_m = memberships(mean_in, fz, FZ_MEAN_C, FZ_MEAN_S)
    mu_c = memberships(cov_in, fz, FZ_COV_C, FZ_COV_S)
    num = 0.0
    den = 0.0
    for i in range(3):
        for j in range(3):
            w = mu_m[i] * mu_c[j]
            y = fz[FZ_OUT + rules[i, j]] + fz[FZ_SLOPE] * cov_in
            num += w * y
            den += w
    a = 1.0 + (num / den if den > 0.0 else 0.0)
    return float(min(max(a, fz[FZ_AMIN]), fz[FZ_AMAX]))


@njit(cache=True)
def residual_inputs(ring: F64, count: int) -> tuple[float, float]:
    """(mean input, cov input) from the ring of normalized residuals (window, k); NaN entries
    (components absent at an epoch) are skipped. Returns (0, 0) before any data.

    The mean input is ``max(0, sqrt(epochs) * RMS_c(mean_c) - 1)`` and the cov input
    ``mean(e^2) - 1`` (module docstring)."""
    n, k = ring.shape
    use = min(count, n)
    s_mean = 0.0
    n_comp = 0
    s_sq = 0.0
    n_sq = 0
    for c in range(k):
        acc = 0.0
        m = 0
        for r in range(use):
            e = ring[r, c]
            if math.isfinite(e):
                acc += e
                s_sq += e * e
                m += 1
        if m > 0:
            mean = acc / m
            s_mean += mean * mean
            n_comp += 1
            n_sq += m
    if n_comp == 0:
        return 0.0, 0.0
    mean_in = max(0.0, math.sqrt(use * s_mean / n_comp) - 1.0)
    return mean_in, s_sq / n_sq - 1.0
