"""The INS/GNSS family (``lc_*``, ``tc_*``, ``fwekf``) under the run contract.

``INS.run`` replays a filter over the tables (``replay.run_filter``: prepare the inputs, run
the kernel), measures it (``metrics.compute_metrics``) and decodes the result into the
contract's ``RunOutput`` (``decode``: the tables of ``outputs``). The scenario driver
(``pipeline.outages.runs``) decodes its scenario runs with the same ``decode``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from navreplay.ingest.schema import TableName
from navreplay.pipeline.estimation.core.contract import (
    Backend,
    RunInputs,
    RunOutput,
)
from navreplay.pipeline.estimation.core.integrity import IntegrityParams
from navreplay.pipeline.estimation.core.windows import ErrorTrack
from navreplay.pipeline.estimation.ins.config import FILTER_KINDS, InsFilterParams
from navreplay.pipeline.estimation.ins.inputs import prepare_fixes, prepare_obs
from navreplay.pipeline.estimation.ins.metrics import compute_metrics
from navreplay.pipeline.estimation.ins.outputs import estimate_table, innovations_table
from navreplay.pipeline.estimation.ins.replay import RunResult, run_filter
from navreplay.pipeline.estimation.ins.tracks import ins_track

INPUTS = (TableName.IMU, TableName.GNSS, TableName.GNSS_OBS, TableName.MAG, TableName.TRUTH)


def decode(
    result: RunResult,
    metrics: dict[str, Any],
    sources: tuple[Path, ...],
    integrity: IntegrityParams,
) -> RunOutput:
    """The contract's record of an INS run."""
    return RunOutput.decode(
        result, estimate_table(result), innovations_table(result), metrics, sources, integrity
    )


class InsFamily:
    """The INS/GNSS filters of paper 001 and the fuzzy-adaptive EKF of paper 004."""

    name = "ins"
    filters = tuple(FILTER_KINDS)
    inputs = INPUTS

    def run(
        self, inputs: RunInputs, name: str, section: InsFilterParams, backend: Backend
    ) -> RunOutput:
        log = inputs.log_tables or {}
        fixes, obs = log.get("gnss"), log.get("gnss_obs")
        result = run_filter(
            inputs.tables, inputs.sensors, name, section, backend=backend,
            fix_noise=None if fixes is None else prepare_fixes(fixes, section.gnss).noise,
            obs_noise=None if obs is None else prepare_obs(obs, section.gnss).noise,
        )  # fmt: skip
        metrics = compute_metrics(result, inputs.tables.get("truth"))
        metrics["dataset"] = inputs.dataset
        return decode(result, metrics, inputs.sources, section.integrity)

    def track(self, run: RunOutput, inputs: RunInputs) -> ErrorTrack | None:
        result = run.result
        assert isinstance(result, RunResult)
        tables = inputs.tables
        return ins_track(result, tables.get("truth"), tables.get("gnss"), inputs.lever_b)


INS = InsFamily()
