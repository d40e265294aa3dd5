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
import multiprocessing
from collections.abc import Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from typing import Any

from navreplay.pipeline.estimation.config import InsFilterParams
from navreplay.pipeline.estimation.contract import Backend, RunInputs, RunOutput
from navreplay.pipeline.estimation.metrics import compute_metrics
from navreplay.pipeline.estimation.replay import RunResult, run_filter
from navreplay.pipeline.estimation.run import decode
from navreplay.pipeline.scenarios.apply import AppliedScenario, apply_scenario
from navreplay.pipeline.scenarios.config import ScenariosParams, ScenarioSpec
from navreplay.pipeline.scenarios.criteria import check_fault

log = logging.getLogger(__name__)


def scenario_metrics(
    inputs: RunInputs,
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
    inputs: RunInputs,
    name: str,
    params: InsFilterParams,
    scenarios: ScenariosParams,
    names: Sequence[str],
    backend: Backend,
    workers: int = 1,
) -> Iterator[tuple[str, RunOutput, AppliedScenario]]:
    """Replay filter ``name`` under each scenario of ``names``; yields them in order.

    Scenarios that transform the tables alike (``sats_0`` and a complete outage of the same
    windows) are replayed once. The replays run on ``workers`` processes (forked, so they
    share the tables and compiled kernels) when there are several. The nominal run is made
    when a fault scenario needs it for its checks (and yielded only if ``names`` asks).

    Raises:
        KeyError: a name is not in ``scenarios.named``.
        ScenarioError: a scenario needs data the dataset lacks.
        DivergenceError: a run diverged and the filter's params say ``raise``.
    """
    specs = {s: scenarios.get(s) for s in names}
    if any(spec.faults for spec in specs.values()) and "nominal" not in specs:
        specs = {"nominal": scenarios.get("nominal"), **specs}
    first: dict[tuple[Any, ...], str] = {}
    for sname, spec in specs.items():
        first.setdefault(_transform_key(spec), sname)
    job = _Job(inputs, name, params, scenarios, backend)
    replays = list(first.values())
    if workers > 1 and len(replays) > 1 and "fork" in multiprocessing.get_all_start_methods():
        ctx = multiprocessing.get_context("fork")
        n = min(workers, len(replays))
        with ProcessPoolExecutor(n, mp_context=ctx, initializer=_init, initargs=(job,)) as pool:
            results = list(pool.map(_replay, replays))
    else:
        results = [job.replay(s) for s in replays]
    by_key = {_transform_key(specs[s]): r for s, r in zip(replays, results, strict=True)}
    nominal = by_key.get(_transform_key(specs["nominal"])) if "nominal" in specs else None
    for sname in names:
        applied = job.apply(sname)
        result = by_key[_transform_key(specs[sname])]
        metrics = scenario_metrics(inputs, applied, result, scenarios)
        if applied.injected:
            assert nominal is not None
            checks = check_fault(
                applied, result, nominal, inputs.tables.get("truth"), params.gating.timeout_s
            )
            metrics["fault_checks"] = [c.to_json() for c in checks]
            metrics["fault_checks_passed"] = all(c.passed for c in checks)
        log.info("%s under %s: %s", name, sname, result.status)
        yield sname, decode(result, metrics, inputs.sources), applied


@dataclass(frozen=True)
class _Job:
    """One filter over one dataset's tables: applies a scenario and replays it."""

    inputs: RunInputs
    name: str
    params: InsFilterParams
    scenarios: ScenariosParams
    backend: Backend

    def apply(self, scenario: str) -> AppliedScenario:
        spec = self.scenarios.get(scenario)
        mask = self.scenarios.selection_mask_deg
        return apply_scenario(self.inputs.tables, scenario, spec, mask_deg=mask)

    def replay(self, scenario: str) -> RunResult:
        applied = self.apply(scenario)
        p, i = self.params, self.inputs
        return run_filter(applied.tables, i.sensors, self.name, p, backend=self.backend)


def _transform_key(spec: ScenarioSpec) -> tuple[Any, ...]:
    """What a scenario does to the tables (its description aside): keeping 0 satellites in
    a window is a complete outage of it."""
    sats = spec.satellites
    if sats is not None and sats.keep == 0:
        sats = None
    return (spec.windows, sats, spec.faults)


_JOB: _Job | None = None


def _init(job: _Job) -> None:
    global _JOB  # noqa: PLW0603 -- one job per (forked) worker process, set once by the pool
    _JOB = job


def _replay(scenario: str) -> RunResult:
    assert _JOB is not None
    return _JOB.replay(scenario)
