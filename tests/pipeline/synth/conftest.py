"""Shared fixtures: the repository's seoul_campus parameters and a short drive."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from navreplay.pipeline.params import Params, load_params
from navreplay.pipeline.synth import SynthResult
from navreplay.pipeline.synth.seoul_campus import SeoulCampusParams, simulate

REPO = Path(__file__).resolve().parents[3]


@pytest.fixture(scope="session")
def repo_params() -> Params:
    return load_params(REPO / "params.yaml")


@pytest.fixture(scope="session")
def seoul(repo_params: Params) -> SeoulCampusParams:
    return repo_params.synth.seoul_campus


@pytest.fixture(scope="session")
def short_params(seoul: SeoulCampusParams) -> SeoulCampusParams:
    """Two minutes: 20 s at rest, then the first legs (a 90 deg turn, a hill, the cw loop)."""
    return dataclasses.replace(seoul, duration_s=120.0, stationary_s=20.0)


@pytest.fixture(scope="session")
def short_noisy(short_params: SeoulCampusParams) -> SynthResult:
    return simulate(short_params, seed=7, variant="cw")


@pytest.fixture(scope="session")
def short_clean(short_params: SeoulCampusParams) -> SynthResult:
    return simulate(dataclasses.replace(short_params, noise_free=True), seed=7, variant="cw")
