"""The tractor experiment end to end on a short scenario: every output, byte-stable, and
independent of the number of worker processes."""

from __future__ import annotations

import csv
import dataclasses
import json
from pathlib import Path

import pytest

from navreplay.pipeline.estimation.cascaded.config import CASCADED_KINDS, CascadedFilterParams
from navreplay.pipeline.experiments.tractor_cascaded.artifacts import write_experiment
from navreplay.pipeline.experiments.tractor_cascaded.config import TractorExperimentParams
from navreplay.pipeline.experiments.tractor_cascaded.runs import (
    ExperimentInputs,
    mean_ci,
)
from navreplay.pipeline.params import load_params
from navreplay.pipeline.synth.tractor import TractorStraightParams

REPO = Path(__file__).resolve().parents[3]


@pytest.fixture(scope="module")
def sim_params() -> TractorStraightParams:
    return load_params(REPO / "params.yaml").synth.tractor_straight


@pytest.fixture(scope="module")
def sections() -> dict[str, CascadedFilterParams]:
    filters = load_params(REPO / "params.yaml").filters
    return {n: filters.cascaded(n) for n in CASCADED_KINDS}


def small(sim: TractorStraightParams, sections: dict[str, CascadedFilterParams],
          workers: int) -> ExperimentInputs:  # fmt: skip
    exp = TractorExperimentParams(
        seeds=2, outage_start_s=8.0, outage_lengths_s=(3.0,), settle_s=4.0, workers=workers,
        timeseries_rate_hz=5.0,
    )  # fmt: skip
    return ExperimentInputs(dataclasses.replace(sim, duration_s=14.0), sections, exp, seed=1)


def test_the_experiment_writes_its_tables_and_figures_byte_stable_for_any_worker_count(
    tmp_path: Path, sim_params: TractorStraightParams,
    sections: dict[str, CascadedFilterParams],
) -> None:  # fmt: skip
    docs = [
        write_experiment(tmp_path / f"w{w}", small(sim_params, sections, w), dpi=40) for w in (1, 2)
    ]
    files = sorted(p.relative_to(tmp_path / "w1") for p in (tmp_path / "w1").rglob("*.*"))
    names = {str(p) for p in files}
    for expected in ("summary.json", "paper_comparison.csv", "convergence.csv", "tracking.csv",
                     "outage_drift.csv", "paired.csv", "runs.csv", "timeseries_nominal.csv",
                     "timeseries_outage_3s.csv", "timing.json", "figures/tracking.png",
                     "figures/tracking.svg", "figures/outage_outage_3s.svg",
                     "figures/monte_carlo.png", "vs_paper.md"):  # fmt: skip
        assert expected in names
    for rel in files:
        if rel.name != "timing.json":  # wall-clock, the only machine-dependent file
            assert (tmp_path / "w1" / rel).read_bytes() == (tmp_path / "w2" / rel).read_bytes()
    doc = docs[0]
    assert doc["labels"] == ["cascaded_ekf", "cascaded_ekf_psi_d", "cascaded_ukf",
                             "cascaded_hybrid", "cascaded_ekf@q0.02s", "cascaded_ukf@q0.02s",
                             "cascaded_hybrid@q0.02s"]  # fmt: skip
    runs = list(csv.DictReader((tmp_path / "w1" / "runs.csv").open()))
    assert len(runs) == 2 * (7 + 6)  # every label nominal, all but psi_d in the outage
    readings = [r["reading"] for r in doc["paper_comparison"]]
    assert readings[:2] == ["Table 1 per second (default)", "Table 1 per 0.02 s step (literal)"]
    assert readings.count(readings[0]) == readings.count(readings[1]) == len(readings) // 2
    note = (tmp_path / "w1" / "vs_paper.md").read_text()
    assert "| Table 1 per second (default) | Table 1 per 0.02 s step (literal) |" in note
    m = "pos_err_n_rms_m"  # a variant is paired with the EKF of its own reading
    st = {lb: doc["stats"][lb]["nominal"][m]["mean"] for lb in doc["labels"]}
    paired = doc["paired"]["cascaded_ukf@q0.02s"]["nominal"][m]["mean"]
    assert paired == pytest.approx(st["cascaded_ukf@q0.02s"] - st["cascaded_ekf@q0.02s"])
    assert st["cascaded_ekf@q0.02s"] != st["cascaded_ekf"]
    verdicts = {r["verdict"] for r in doc["paper_comparison"]}
    assert verdicts <= {"reproduced", "contradicted", "not distinguishable",
                        "no practical difference", "not measurable"}  # fmt: skip
    summary = json.loads((tmp_path / "w1" / "summary.json").read_text())
    stat = summary["stats"]["cascaded_ekf"]["outage_3s"]["drift_end_m"]
    assert stat["n"] == 2
    assert stat["ci_low"] <= stat["mean"] <= stat["ci_high"]


def test_mean_ci_is_the_t_interval_and_ignores_non_converged_runs() -> None:
    import numpy as np

    ci = mean_ci(np.array([1.0, 2.0, 3.0, np.nan]), 0.95)
    assert ci["n"] == 3
    assert ci["mean"] == pytest.approx(2.0)
    assert ci["ci_high"] == pytest.approx(2.0 + 4.302652729911275 * 1.0 / np.sqrt(3))
    assert mean_ci(np.array([np.nan]), 0.95)["mean"] is None
