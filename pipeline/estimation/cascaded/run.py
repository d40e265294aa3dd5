"""The cascaded family (paper 000: navigation + control filters) under the run contract.

``CASCADED.run`` replays a recording open loop (the recorded steering command drives the
control filter) over the ``vehicle`` and ``gnss`` tables, measures it against the truth in the
local map, and decodes it into the contract's ``RunOutput`` (``estimation.core.contract``).
"""

from __future__ import annotations

import logging

from navreplay.ingest.schema import TableName
from navreplay.ingest.typed import to_plain
from navreplay.pipeline.estimation.cascaded.backends import replay
from navreplay.pipeline.estimation.cascaded.config import CASCADED_KINDS, CascadedFilterParams
from navreplay.pipeline.estimation.cascaded.engine import make_setup
from navreplay.pipeline.estimation.cascaded.inputs import prepare_inputs
from navreplay.pipeline.estimation.cascaded.metrics import compute_metrics, truth_from_table
from navreplay.pipeline.estimation.cascaded.outputs import estimate_table, innovations_table
from navreplay.pipeline.estimation.core.contract import (
    Backend,
    RunInputs,
    RunOutput,
)
from navreplay.pipeline.estimation.core.windows import ErrorTrack, table_track

log = logging.getLogger(__name__)

INPUTS = (TableName.VEHICLE, TableName.GNSS, TableName.TRUTH)


class CascadedFamily:
    """The cascaded EKF, UKF and hybrid filters of paper 000."""

    name = "cascaded"
    filters = tuple(CASCADED_KINDS)
    inputs = INPUTS

    def run(
        self, inputs: RunInputs, name: str, section: CascadedFilterParams, backend: Backend
    ) -> RunOutput:
        """Raises ``ReplayInputError`` when the vehicle or gnss table is missing or unusable,
        ``DivergenceError`` when the filter diverged and ``on_divergence`` is ``raise``."""
        inp = prepare_inputs(inputs.tables, name)
        result = replay(make_setup(name, section), inp.veh_t, inp.veh, inp.gps_t, inp.gps, backend)
        result.events = sorted([*inp.events, *result.events], key=lambda e: e.t_ns)
        truth = inputs.tables.get("truth")
        truth_x = truth_from_table(truth, inp.frame, result.t_ns) if truth is not None else None
        metrics = compute_metrics(result, truth_x, section.convergence_band)
        metrics["dataset"] = inputs.dataset
        metrics["frame_origin"] = to_plain(inp.frame)
        estimate, innovations = estimate_table(result, inp.frame), innovations_table(result)
        return RunOutput.decode(
            result, estimate, innovations, metrics, inputs.sources, section.integrity
        )

    def track(self, run: RunOutput, inputs: RunInputs) -> ErrorTrack | None:
        """Planar errors read from ``estimate.parquet`` (``windows.table_track``)."""
        tables = inputs.tables
        return table_track(run.tables.estimate, tables.get("truth"), tables.get("gnss"))


CASCADED = CascadedFamily()
