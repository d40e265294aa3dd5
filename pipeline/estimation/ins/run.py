"""The INS/GNSS family (``lc_*``, ``tc_*``, ``fwekf``) under the run contract.

``INS.run`` replays a filter over the tables (``replay.run_filter``: prepare the inputs, run
the kernel), measures it (``metrics.compute_metrics``) and decodes the result into the
contract's ``RunOutput`` (``decode``: the tables of ``outputs``). The scenario driver
(``pipeline.outages.runs``) decodes its scenario runs with the same ``decode``.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import pyarrow as pa

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


#: the keys of an INS run's metrics that ``metrics["smoothed"]`` repeats for the smoothed run
SMOOTHED_KEYS = (
    "truth", "pos_err_h_rms_m", "pos_err_v_rms_m", "pos_err_3d_rms_m", "pos_err_3d_max_m",
    "vel_err_3d_rms_mps", "att_err_rms_rad", "pos_h_within_3sigma", "nees_mean", "nees_dof",
    "nees_states", "nees_full_mean", "nees_full_dof",
)  # fmt: skip


def decode(
    result: RunResult,
    metrics: dict[str, Any],
    sources: tuple[Path, ...],
    integrity: IntegrityParams,
    truth: pa.Table | None = None,
) -> RunOutput:
    """The contract's record of an INS run, with its smoothed run (measured against
    ``truth``) if it was smoothed."""
    out = RunOutput.decode(
        result, estimate_table(result), innovations_table(result), metrics, sources, integrity
    )
    if result.smoothing is None:
        return out
    smoothed = result.smoothed_run()
    m: dict[str, Any] = {"smoothing": result.smoothing.to_json()}
    if smoothed is None:
        return replace(out, metrics=dict(out.metrics, smoothed=m))
    full = compute_metrics(smoothed, truth)
    m.update({k: full[k] for k in SMOOTHED_KEYS if k in full})
    return replace(
        out, metrics=dict(out.metrics, smoothed=m), smoothed=(estimate_table(smoothed), smoothed)
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
        truth = inputs.tables.get("truth")
        metrics = compute_metrics(result, truth)
        metrics["dataset"] = inputs.dataset
        return decode(result, metrics, inputs.sources, section.integrity, truth)

    def track(self, run: RunOutput, inputs: RunInputs) -> ErrorTrack | None:
        return self._track(run.result, inputs)

    def smoothed_track(self, run: RunOutput, inputs: RunInputs) -> ErrorTrack | None:
        """``track`` of the run's smoothed estimate (None if it was not smoothed)."""
        return None if run.smoothed is None else self._track(run.smoothed[1], inputs)

    def _track(self, result: object, inputs: RunInputs) -> ErrorTrack | None:
        assert isinstance(result, RunResult)
        tables = inputs.tables
        return ins_track(result, tables.get("truth"), tables.get("gnss"), inputs.lever_b)


INS = InsFamily()
