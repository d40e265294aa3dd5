"""Intervals for the outage experiments: paired ratio of means and plain means.

The reduction of filter B over filter A at satellite count k is ``100 (1 - mean(b) / mean(a))``
over the same outage windows (architecture section 5), a ratio of means of paired samples.
Its interval is a paired bootstrap over windows with BCa correction (``scipy.stats.bootstrap``,
``paired=True``): each resample draws whole windows, keeping A's and B's errors on the same
window together, so the large window-to-window variation in difficulty (turns, speed, the
error each filter entered the window with) that both filters share cancels out of the ratio,
as it does in the estimate. BCa corrects the bias and skew a ratio of means has in small
samples. The window is the resampling unit because the starts are drawn independently and
uniformly over the drive for every seed: the interval covers the mean over outage start times
on this drive (this noise realization), not other drives or sensors. The delta-method
interval of the same ratio is reported beside it as a cross-check.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from navreplay.pipeline.distributions import norm_ppf
from navreplay.pipeline.nav.earth import F64


@dataclass(frozen=True)
class Interval:
    """An estimate with a two-sided interval (NaN bounds when undefined)."""

    estimate: float
    low: float
    high: float

    def json(self) -> list[float | None]:
        return [_finite(self.low), _finite(self.high)]


def _finite(x: float) -> float | None:
    return x if math.isfinite(x) else None


def reduction_pct(a: F64, b: F64, axis: int = -1) -> F64:
    """``100 (1 - mean(b) / mean(a))`` along ``axis`` (vectorized for the bootstrap)."""
    return np.asarray(100.0 * (1.0 - np.mean(b, axis=axis) / np.mean(a, axis=axis)))


def _bootstrap(
    data: tuple[F64, ...],
    stat: Callable[..., F64],
    confidence: float,
    resamples: int,
    seed: int,
    paired: bool,
) -> tuple[float, float]:
    if data[0].size < 2 or all(np.ptp(d) == 0 for d in data):
        return math.nan, math.nan
    from scipy.stats import bootstrap  # scipy.stats takes seconds to import (distributions)

    with warnings.catch_warnings():
        # BCa warns and returns NaN on a degenerate resample distribution; NaN is reported
        warnings.simplefilter("ignore", RuntimeWarning)
        res = bootstrap(
            list(data),
            stat,
            n_resamples=resamples,
            paired=paired,
            vectorized=True,
            confidence_level=confidence,
            method="BCa",
            rng=np.random.default_rng(seed),
        )
    return float(res.confidence_interval.low), float(res.confidence_interval.high)


def paired_reduction(
    a: F64, b: F64, confidence: float = 0.95, resamples: int = 10_000, seed: int = 0
) -> Interval:
    """The reduction of b over a in % with its paired BCa bootstrap interval."""
    est = float(reduction_pct(a, b)) if a.size and np.mean(a) > 0 else math.nan
    lo, hi = _bootstrap((a, b), reduction_pct, confidence, resamples, seed, paired=True)
    return Interval(est, lo, hi)


def delta_reduction(a: F64, b: F64, confidence: float = 0.95) -> Interval:
    """The same ratio with the delta-method interval: ``r = mean(b) / mean(a)``,
    ``var r ~ (s_b^2 - 2 r s_ab + r^2 s_a^2) / (n mean(a)^2)``."""
    n = a.size
    if n < 2 or np.mean(a) <= 0:
        return Interval(math.nan, math.nan, math.nan)
    ma, mb = float(np.mean(a)), float(np.mean(b))
    r = mb / ma
    cov = np.cov(np.vstack([a, b]))
    var = (cov[1, 1] - 2.0 * r * cov[0, 1] + r * r * cov[0, 0]) / (n * ma * ma)
    z = norm_ppf(0.5 + confidence / 2.0)
    half = 100.0 * z * math.sqrt(max(var, 0.0))
    est = 100.0 * (1.0 - r)
    return Interval(est, est - half, est + half)


def _mean(x: F64, axis: int = -1) -> F64:
    return np.asarray(np.mean(x, axis=axis))


def mean_interval(
    x: F64, confidence: float = 0.95, resamples: int = 10_000, seed: int = 0
) -> Interval:
    """The mean of x with its BCa bootstrap interval (windows as the resampling unit)."""
    x = x[np.isfinite(x)]
    if x.size == 0:
        return Interval(math.nan, math.nan, math.nan)
    lo, hi = _bootstrap((x,), _mean, confidence, resamples, seed, paired=False)
    return Interval(float(np.mean(x)), lo, hi)
