"""One filter replayed under named scenarios: the pure core of ``navreplay run --scenario``.

The tables are read once; each scenario is applied to them (``scenarios.apply``), replayed
(``estimation.replay.run_filter``) and measured (``estimation.metrics.compute_metrics`` with
the scenario's outage windows, against the truth or the withheld fixes). A fault scenario is
also checked against the catalogue's pass criteria (``scenarios.criteria``), which compares
it with the nominal run of the same filter. The scenario (definition, windows, satellites
chosen, faults injected) goes into ``metrics.json`` and the Parquet provenance.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pyarrow as pa

from ingest.meta import META_NAME, SensorMeta, read_meta
from pipeline.estimation.config import InsFilterParams
from pipeline.estimation.metrics import compute_metrics
from pipeline.estimation.replay import Backend, RunResult, run_filter
from pipeline.estimation.run import RunOutput, read_inputs
from pipeline.scenarios.apply import AppliedScenario, apply_scenario
from pipeline.scenarios.config import ScenariosParams
from pipeline.scenarios.criteria import check_fault

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Inputs:
    """A dataset's tables as read once for many runs."""

    dataset: str
    tables: dict[str, pa.Table]
    sensors: SensorMeta | None
    sources: tuple[Path, ...]

    @classmethod
    def read(cls, tables_dir: Path) -> Inputs:
        meta = read_meta(tables_dir)
        tables, sources = read_inputs(tables_dir)
        return cls(meta.dataset, tables, meta.sensors, (*sources, tables_dir / META_NAME))

    @property
    def lever_b(self) -> tuple[float, float, float]:
        if self.sensors is None:
            return (0.0, 0.0, 0.0)
        lx, ly, lz = self.sensors.lever_arm_m
        return (float(lx), float(ly), float(lz))


def scenario_metrics(
    inputs: Inputs,
    applied: AppliedScenario,
    result: RunResult,
    scenarios: ScenariosParams,
) -> dict[str, Any]:
    """``metrics.json`` of a scenario run: the core metrics plus the outage windows."""
    m = compute_metrics(
        result,
        inputs.tables.get("truth"),
        windows=applied.outage_windows,
        t0_ns=applied.t0_ns,
        window_params=scenarios.metrics,
        fixes=inputs.tables.get("gnss"),
        lever_b=inputs.lever_b,
    )
    m["dataset"] = inputs.dataset
    meta = applied.metadata()
    m["scenario_detail"] = meta
    m["windows"] = meta["windows"]
    return m


def run_scenarios(
    inputs: Inputs,
    name: str,
    params: InsFilterParams,
    scenarios: ScenariosParams,
    names: Sequence[str],
    backend: Backend,
) -> Iterator[tuple[str, RunOutput, AppliedScenario]]:
    """Replay filter ``name`` under each scenario of ``names``, in order.

    The nominal run is made first when a fault scenario needs it for its checks (and yielded
    only if ``names`` asks for it).

    Raises:
        KeyError: a name is not in ``scenarios.named``.
        ScenarioError: a scenario needs data the dataset lacks.
        DivergenceError: a run diverged and the filter's params say ``raise``.
    """
    specs = {s: scenarios.get(s) for s in names}
    nominal: RunResult | None = None
    needs_nominal = any(spec.faults for spec in specs.values())
    order = list(names)
    if needs_nominal and "nominal" in order:
        order.remove("nominal")
        order.insert(0, "nominal")
    elif needs_nominal:
        nominal = run_filter(inputs.tables, inputs.sensors, name, params, backend=backend)
    for sname in order:
        applied = apply_scenario(
            inputs.tables, sname, specs[sname], mask_deg=scenarios.selection_mask_deg
        )
        result = run_filter(applied.tables, inputs.sensors, name, params, backend=backend)
        if sname == "nominal":
            nominal = result
        metrics = scenario_metrics(inputs, applied, result, scenarios)
        if applied.injected:
            assert nominal is not None
            checks = check_fault(
                applied, result, nominal, inputs.tables.get("truth"), params.gating.timeout_s
            )
            metrics["fault_checks"] = [c.to_json() for c in checks]
            metrics["fault_checks_passed"] = all(c.passed for c in checks)
        log.info("%s under %s: %s", name, sname, result.status)
        yield sname, RunOutput(result, metrics, inputs.sources), applied
