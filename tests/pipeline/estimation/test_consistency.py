"""Monte Carlo NEES and NIS of every filter against the chi-square bounds of bad-inputs.md.

N seeded runs of a 70 s seoul_campus drive (synthesizer of params.yaml with 10 s at rest and
white fix errors, and the filters told so: ``pos_error_corr_time_s: 0``);
each run starts 2 s into the motion from the truth plus an error drawn from P0 (the textbook
set-up: initial errors distributed as the filter believes, biases from their priors).
Runs are independent, so at every step ``N * mean_NEES ~ chi2(N n)`` and, per measurement
block, ``N * mean_NIS ~ chi2(N d)`` exactly. Successive steps of one run are strongly
correlated (errors decorrelate over seconds), which makes the fraction of steps inside a 95 %
interval a high-variance statistic at N = 20 (observed 0.83-0.99 across seed sets for the
same, consistent filter; with 60 runs every state block's NEES is within two standard errors
of its dimension). We therefore require 90 % of the per-step averages inside their two-sided
99 % interval, and the grand mean within three standard errors of the run means and 10 % of
its expectation; a 20 % mis-scaled covariance fails both.

The ``_nhc`` filters: the synthesized vehicle obeys the non-holonomic constraint exactly (no
sideslip), while params.yaml sizes the NHC noise (0.1 m/s) for real vehicles. Their NHC
innovations then carry only the small estimation error, so no nonzero noise makes that stream
chi-square consistent; what must hold is that the filter is not overconfident: NEES and GNSS
NIS not above their upper bounds, and the NHC NIS below its dimension.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pytest
from scipy.stats import chi2

from navreplay.pipeline.estimation.config import FiltersParams
from navreplay.pipeline.estimation.core.consistency import nees
from navreplay.pipeline.estimation.ins.config import FILTER_KINDS
from navreplay.pipeline.estimation.ins.models import measurement as me
from navreplay.pipeline.estimation.ins.replay import run_filter
from navreplay.pipeline.estimation.ins.truth import error_states
from tests.pipeline.estimation.conftest import ALL_FILTERS, drawn_start, seoul

N_RUNS = 20
# position, velocity, attitude, then the synthesizer's bias priors, then the clock
P0_SIGMA = np.array(
    [2.0] * 3 + [0.2] * 3 + [0.02, 0.02, 0.1] + [0.05] * 3 + [5e-4] * 3 + [10.0, 1.0]
)
START_ROW = 1200  # 12 s: moving


@dataclass
class MonteCarlo:
    nees: np.ndarray  # (N, K) per run and step
    dof: int
    nis: dict[str, np.ndarray]  # stream -> (N, J) per run and block
    nis_dof: dict[str, np.ndarray]  # stream -> (J,) block dimensions


@pytest.fixture(scope="module")
def monte_carlo(filters: FiltersParams) -> dict[str, MonteCarlo]:
    runs: dict[str, list[tuple[np.ndarray, np.ndarray, np.ndarray]]] = {f: [] for f in ALL_FILTERS}
    dof = {}
    for seed in range(N_RUNS):
        tables, sensors = seoul(70.0, seed=1000 + seed, white_fixes=True)
        for name in ALL_FILTERS:
            n = 17 if FILTER_KINDS[name].coupling == "tight" else 15
            rng = np.random.default_rng(seed)
            start = drawn_start(tables["truth"], START_ROW, n, P0_SIGMA, rng)
            p = filters.get(name)
            p = replace(p, gnss=replace(p.gnss, pos_error_corr_time_s=0.0))  # white fixes
            r = run_filter(tables, sensors, name, p, initial=start)
            assert r.status == "ok"
            inside, err, names = error_states(r, tables["truth"])
            assert len(names) == n
            dof[name] = n
            runs[name].append((nees(err, r.P[inside]), r.inn_i, r.inn_f[:, 0]))
    out = {}
    for name, rr in runs.items():
        inn_i = rr[0][1]
        for _, other, _ in rr:  # identical schedules: blocks line up across runs
            np.testing.assert_array_equal(other[:, :4], inn_i[:, :4])
        streams = {me.STREAM_NAMES[c]: inn_i[:, 1] == c for c in np.unique(inn_i[:, 1]).tolist()}
        out[name] = MonteCarlo(
            nees=np.array([e for e, _, _ in rr]),
            dof=dof[name],
            nis={s: np.array([v[sel] for _, _, v in rr]) for s, sel in streams.items()},
            nis_dof={s: inn_i[sel, 3] for s, sel in streams.items()},
        )
    return out


def per_step_bounds(dof: np.ndarray | int) -> tuple[np.ndarray, np.ndarray]:
    """The two-sided 99 % interval of the N-run average of a chi2(dof) statistic."""
    lo = np.asarray(chi2.ppf(0.005, N_RUNS * np.asarray(dof)) / N_RUNS)
    hi = np.asarray(chi2.ppf(0.995, N_RUNS * np.asarray(dof)) / N_RUNS)
    return lo, hi


def unbiased(per_run: np.ndarray, expected: float) -> bool:
    """Grand mean within three standard errors (from the spread of run means) and 10 %."""
    means = per_run.mean(axis=1)
    se = means.std(ddof=1) / np.sqrt(means.size)
    grand = float(means.mean())
    return abs(grand - expected) <= max(3.0 * se, 1e-9) and abs(grand / expected - 1) < 0.1


@pytest.mark.parametrize("name", [f for f in ALL_FILTERS if not FILTER_KINDS[f].nhc])
def test_nees_and_nis_within_chi2_bounds(name: str, monte_carlo: dict[str, MonteCarlo]) -> None:
    mc = monte_carlo[name]
    avg = mc.nees.mean(axis=0)
    lo, hi = per_step_bounds(mc.dof)
    inside = float(np.mean((avg >= lo) & (avg <= hi)))
    assert inside >= 0.9, f"ANEES inside its 99 % bounds at {inside:.0%} of steps"
    assert unbiased(mc.nees, mc.dof), f"ANEES {mc.nees.mean():.2f} for {mc.dof} states"
    for stream, nis in mc.nis.items():
        d = mc.nis_dof[stream]
        lo_s, hi_s = per_step_bounds(d)
        avg_s = nis.mean(axis=0)
        inside = float(np.mean((avg_s >= lo_s) & (avg_s <= hi_s)))
        assert inside >= 0.9, f"{stream}: NIS inside its bounds at {inside:.0%} of updates"
        assert unbiased(nis / d, 1.0), f"{stream}: mean NIS/dof {np.mean(nis / d):.3f}"


@pytest.mark.parametrize("name", [f for f in ALL_FILTERS if FILTER_KINDS[f].nhc])
def test_nhc_filters_are_not_overconfident(name: str, monte_carlo: dict[str, MonteCarlo]) -> None:
    mc = monte_carlo[name]
    avg = mc.nees.mean(axis=0)
    _, hi = per_step_bounds(mc.dof)
    assert np.mean(avg > hi) <= 0.05
    assert mc.nees.mean() <= mc.dof
    for stream, nis in mc.nis.items():
        d = mc.nis_dof[stream]
        _, hi_s = per_step_bounds(d)
        assert np.mean(nis.mean(axis=0) > hi_s) <= 0.05, stream
        if stream == "nhc":
            assert nis.mean() < 0.5 * d.mean()  # conservative by design on exact-NHC data
        else:
            assert nis.mean() / d.mean() < 1.1
