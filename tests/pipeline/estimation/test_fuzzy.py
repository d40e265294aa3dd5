"""The Takagi-Sugeno fuzzy system of paper 004: rule table, memberships, bounds, monotonicity."""

from __future__ import annotations

import math

import numpy as np
import pytest

from navreplay.ingest.typed import FieldError
from navreplay.pipeline.estimation.ins.fuzzy import (
    FZ_COV_C,
    FZ_COV_S,
    FZ_MEAN_C,
    FZ_MEAN_S,
    RULES,
    FuzzyParams,
    infer_alpha,
    membership,
    memberships,
    residual_inputs,
)

FP = FuzzyParams()
FZ = FP.vector()
ZERO, SMALL, LARGE, NEG = (1.0 + y for y in FP.outputs)


def test_rule_table_is_table_1_of_the_paper() -> None:
    labels = np.array(["Z", "S", "L", "NS"])[RULES]
    assert labels.tolist() == [["Z", "S", "S"], ["S", "L", "S"], ["Z", "NS", "NS"]]


@pytest.mark.parametrize(
    ("mean_label", "cov_label", "expected"),
    [(0, 0, ZERO), (0, 1, SMALL), (0, 2, SMALL), (1, 0, SMALL), (1, 1, LARGE), (1, 2, SMALL),
     (2, 0, ZERO), (2, 1, NEG), (2, 2, NEG)],
)  # fmt: skip
def test_each_rule_fires_alone_at_its_membership_centres(
    mean_label: int, cov_label: int, expected: float
) -> None:
    """Far from the other centres one rule dominates: alpha is its consequent."""
    fz = FZ.copy()
    fz[FZ_MEAN_S : FZ_MEAN_S + 3] = 0.05  # narrow sets: no overlap
    fz[FZ_COV_S : FZ_COV_S + 3] = 0.05
    m, c = fz[FZ_MEAN_C + mean_label], fz[FZ_COV_C + cov_label]
    assert infer_alpha(m, c, fz, RULES) == pytest.approx(expected, abs=1e-9)


def test_memberships_are_gaussian_with_shoulders() -> None:
    assert membership(1.0, 1.0, 0.5) == 1.0
    assert membership(1.5, 1.0, 0.5) == pytest.approx(math.exp(-0.5))
    mu = memberships(-3.0, FZ, FZ_MEAN_C, FZ_MEAN_S)
    assert mu[0] == 1.0  # below the Zero centre: fully Zero
    mu = memberships(1e3, FZ, FZ_MEAN_C, FZ_MEAN_S)
    assert mu[2] == 1.0  # beyond the Large centre: fully Large
    assert mu[1] < 1e-12


def test_alpha_stays_within_its_bounds_everywhere() -> None:
    grid = np.linspace(-2.0, 50.0, 60)
    alphas = np.array([[infer_alpha(m, c, FZ, RULES) for c in grid] for m in grid])
    assert alphas.min() >= FP.alpha_min
    assert alphas.max() <= FP.alpha_max
    tight = FZ.copy()
    tight[FZ_COV_C : FZ_COV_C + 3] = (0.0, 0.1, 0.2)
    tight[-4] = 0.5  # a steep slope on the covariance input would leave the bounds
    assert infer_alpha(0.0, 40.0, tight, RULES) <= FP.alpha_max


def test_consistent_residuals_leave_the_plain_ekf() -> None:
    assert infer_alpha(0.0, 0.0, FZ, RULES) == pytest.approx(1.0, abs=2e-3)


def test_alpha_grows_with_the_residual_covariance_when_the_mean_is_zero() -> None:
    """Mean Zero row (Z, S, S): more residual covariance never lowers alpha."""
    cov = np.linspace(0.0, 1.5, 40)
    alphas = np.array([infer_alpha(0.0, c, FZ, RULES) for c in cov])
    assert np.all(np.diff(alphas) >= -1e-12)
    assert alphas[-1] > alphas[0]


def test_a_large_residual_mean_lowers_alpha_below_one() -> None:
    """Mean Large with covariance Small/Large -> NS: a measurement bias is trusted less."""
    assert infer_alpha(FP.mean_centers[2], FP.cov_centers[2], FZ, RULES) < 1.0


def test_residual_inputs_are_zero_for_a_consistent_filter_on_average() -> None:
    rng = np.random.default_rng(3)
    mean_in, cov_in = [], []
    for _ in range(400):
        ring = rng.standard_normal((10, 6))
        m, c = residual_inputs(ring, 10)
        mean_in.append(m)
        cov_in.append(c)
    assert np.mean(cov_in) == pytest.approx(0.0, abs=0.03)
    assert np.median(mean_in) < 0.2
    biased = rng.standard_normal((10, 6)) + 2.0
    assert residual_inputs(biased, 10)[0] > 4.0


def test_residual_inputs_skip_missing_components_and_empty_rings() -> None:
    ring = np.full((5, 6), np.nan)
    assert residual_inputs(ring, 0) == (0.0, 0.0)
    ring[0, :3] = (1.0, -1.0, 1.0)
    m, c = residual_inputs(ring, 1)
    assert c == pytest.approx(0.0)
    assert m == pytest.approx(0.0)


def test_params_reject_unordered_centres_and_bad_bounds() -> None:
    with pytest.raises(FieldError):
        FuzzyParams(mean_centers=(0.0, 3.0, 2.0))
    with pytest.raises(FieldError):
        FuzzyParams(alpha_min=1.1)
