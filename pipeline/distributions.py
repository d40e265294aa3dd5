"""Quantiles of the chi-square, Student t and normal distributions, from ``scipy.special``.

``scipy.stats`` computes them with these same special functions (``chi2.ppf`` is
``2 gammaincinv(df / 2, q)``, ``chi2.isf`` is ``chdtri``, ``t.ppf`` is ``stdtrit``, ``norm.ppf``
is ``ndtri``), so the values are the same to the bit (``tests/pipeline/test_distributions.py``).
Importing ``scipy.stats`` builds every distribution class it has: 1-3 s of the start of every
``navreplay`` process that needs one gate or one chi-square bound, a fifth of a small log's
``analyze``. The filters, the integrity monitor and the reports use these instead; the
experiments that need ``scipy.stats``'s machinery (bootstrap intervals, ranks) import it
where they use it.

Arguments outside the distributions' domains give NaN, as ``scipy.stats`` does: ``q`` outside
[0, 1], ``df <= 0``.
"""

from __future__ import annotations

import math

from scipy import special


def _domain(q: float, df: float) -> bool:
    return bool(0.0 <= q <= 1.0 and df > 0.0)


def chi2_ppf(q: float, df: float) -> float:
    """The ``q`` quantile of the chi-square distribution with ``df`` degrees of freedom."""
    if not _domain(q, df):
        return float("nan")
    return float(2.0 * special.gammaincinv(df / 2.0, q))


def chi2_isf(q: float, df: float) -> float:
    """The value the chi-square distribution with ``df`` degrees of freedom exceeds with
    probability ``q``."""
    if not _domain(q, df):
        return float("nan")
    return float(special.chdtri(df, q))


def t_ppf(q: float, df: float) -> float:
    """The ``q`` quantile of Student's t distribution with ``df`` degrees of freedom."""
    if not _domain(q, df):
        return float("nan")
    if q in (0.0, 1.0):  # the support's ends (stdtrit gives +inf at both)
        return math.copysign(math.inf, q - 0.5)
    return float(special.stdtrit(df, q))


def norm_ppf(q: float) -> float:
    """The ``q`` quantile of the standard normal distribution."""
    return float(special.ndtri(q)) if 0.0 <= q <= 1.0 else float("nan")
