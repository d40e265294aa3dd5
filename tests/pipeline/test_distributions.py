"""``pipeline.distributions`` gives scipy.stats's quantiles to the bit, without importing it."""

from __future__ import annotations

import math
import subprocess
import sys

import pytest
from scipy import stats

from navreplay.pipeline import distributions as d

QS = (0.0, 1e-12, 0.001, 0.025, 0.05, 0.3, 0.5, 0.9, 0.975, 0.99, 0.999999, 1.0)
DFS = (0.37, 1, 2, 3, 4.5, 9, 17, 64, 1000.25, 1e5)


def _same(a: float, b: float) -> bool:
    return (math.isnan(a) and math.isnan(b)) or a == b


@pytest.mark.parametrize("df", DFS)
def test_the_quantiles_equal_scipy_stats_to_the_bit(df: float) -> None:
    for q in QS:
        assert _same(d.chi2_ppf(q, df), float(stats.chi2.ppf(q, df))), (q, df)
        assert _same(d.chi2_isf(q, df), float(stats.chi2.isf(q, df))), (q, df)
        assert _same(d.t_ppf(q, df), float(stats.t.ppf(q, df))), (q, df)
    for q in QS:
        assert _same(d.norm_ppf(q), float(stats.norm.ppf(q))), q


def test_outside_the_domain_is_nan_as_in_scipy_stats() -> None:
    for q, df in ((-0.1, 3), (1.1, 3), (0.5, 0), (0.5, -2), (math.nan, 3)):
        for mine, theirs in ((d.chi2_ppf, stats.chi2.ppf), (d.chi2_isf, stats.chi2.isf),
                             (d.t_ppf, stats.t.ppf)):  # fmt: skip
            assert math.isnan(mine(q, df)), (mine, q, df)
            assert math.isnan(float(theirs(q, df))), (theirs, q, df)
    assert math.isnan(d.norm_ppf(1.5))
    assert math.isnan(float(stats.norm.ppf(1.5)))


def test_a_run_and_its_report_do_not_import_the_slow_scipy_modules() -> None:
    """The filters' gates, the integrity monitor and the report's bounds come from here, and
    the synthesizers' profiles import scipy.interpolate only when they build one: a fresh
    process importing the analysis, a run and the report leaves both unloaded (together
    2-3 s of every start)."""
    code = (
        "import sys, navreplay.pipeline.analyze, navreplay.pipeline.report.render, "
        "navreplay.pipeline.stages.run; "
        "print(sorted(m for m in ('scipy.stats', 'scipy.interpolate') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
