"""Fixtures of the cascaded-filter tests: the repository's params and short recordings."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pyarrow as pa
import pytest

from navreplay.pipeline.estimation.cascaded.config import CASCADED_KINDS, CascadedFilterParams
from navreplay.pipeline.params import Params, load_params
from navreplay.pipeline.synth.tractor import TractorStraightParams
from navreplay.pipeline.synth.tractor_log import synthesize

REPO = Path(__file__).resolve().parents[4]
CASCADED = tuple(CASCADED_KINDS)


@pytest.fixture(scope="session")
def params() -> Params:
    return load_params(REPO / "params.yaml")


@pytest.fixture(scope="session")
def sections(params: Params) -> dict[str, CascadedFilterParams]:
    """The ``filters.cascaded_*`` sections of the repository's params.yaml."""
    return {n: params.filters.cascaded(n) for n in CASCADED}


@pytest.fixture(scope="session")
def sim_params(params: Params) -> TractorStraightParams:
    """The paper's scenario (``synth.tractor_straight``)."""
    return params.synth.tractor_straight


@pytest.fixture(scope="session")
def recording20(sim_params: TractorStraightParams) -> dict[str, pa.Table]:
    """The first 20 s of the ``tractor_straight`` recording, as canonical tables."""
    short = dataclasses.replace(sim_params, duration_s=20.0)
    return dict(synthesize(short, seed=11).tables)
