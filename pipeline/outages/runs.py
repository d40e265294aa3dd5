"""One filter of any family replayed under named scenarios: the core of ``navreplay run
--scenario``.

The tables are read once; each scenario is applied to them (``scenarios.apply``: outage
windows, satellites kept, faults), the filter's family runs on the result
(``estimation.core.contract.Family.run``) and the outage windows are measured on the run's error
track (``Family.track``, ``estimation.core.windows.window_metrics``) against the truth or the
withheld fixes; a smoothed INS filter on a log without truth measures them against its
smoothed nominal run instead (``SMOOTHED_NOMINAL``), the withheld fixes' measure beside it.
A fault scenario of an INS filter is also checked against the catalogue's pass criteria
(``scenarios.criteria``), which compares it with the nominal run of the same filter. The
scenario (definition, windows, satellites chosen, faults injected) goes into
``metrics.json`` and the Parquet provenance.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, replace
from typing import Any

import pyarrow as pa

from navreplay.pipeline.compute import ComputeParams, TaskError, run_tasks
from navreplay.pipeline.estimation.core.contract import Backend, Family, RunInputs, RunOutput
from navreplay.pipeline.estimation.core.windows import ErrorTrack, window_metrics
from navreplay.pipeline.estimation.families import family_of
from navreplay.pipeline.estimation.ins.replay import RunResult
from navreplay.pipeline.scenarios.apply import AppliedScenario, apply_scenario
from navreplay.pipeline.scenarios.config import ScenariosParams, ScenarioSpec
from navreplay.pipeline.scenarios.criteria import check_fault
from navreplay.pipeline.scenarios.faults import ScenarioError

log = logging.getLogger(__name__)


#: ``ErrorTrack.reference`` of windows measured against the smoothed nominal run
SMOOTHED_NOMINAL = "smoothed_nominal"


def scenario_metrics(
    inputs: RunInputs,
    family: Family,
    applied: AppliedScenario,
    run: RunOutput,
    scenarios: ScenariosParams,
    reference: pa.Table | None = None,
) -> dict[str, Any]:
    """``metrics.json`` of a scenario run: the family's metrics plus the outage windows,
    measured against the unmodified ``inputs`` (the withheld fixes are the reference where
    there is no truth). ``reference``: the smoothed nominal run's estimate of a log without
    truth; the windows are then measured against it (``reference`` ``smoothed_nominal``), and
    against the withheld fixes under ``outage_windows_vs_fixes``."""
    m = dict(run.metrics)
    if applied.outage_windows:
        m.update(_outage_metrics(inputs, family, applied, run, scenarios, reference))
        if run.smoothed is not None and "smoothed" in m:
            smoothed = replace(run, result=run.smoothed[1], smoothed=None)
            windows = _outage_metrics(inputs, family, applied, smoothed, scenarios, reference)
            m["smoothed"] = dict(m["smoothed"], **windows)
    meta = applied.metadata()
    m["scenario_detail"] = meta
    m["windows"] = meta["windows"]
    return m


def _outage_metrics(
    inputs: RunInputs,
    family: Family,
    applied: AppliedScenario,
    run: RunOutput,
    scenarios: ScenariosParams,
    reference: pa.Table | None,
) -> dict[str, list[dict[str, Any]]]:
    """``outage_windows`` of ``run`` against the truth or the withheld fixes, or against the
    smoothed nominal run ``reference`` (``outage_windows_vs_fixes`` then holds the withheld
    fixes' measure)."""
    by_inputs = _windows(family.track(run, inputs), applied, scenarios)
    if reference is None:
        return {"outage_windows": by_inputs}
    by_smoothed = replace(inputs, tables={**inputs.tables, "truth": reference})
    track = family.track(run, by_smoothed)
    track = None if track is None else replace(track, reference=SMOOTHED_NOMINAL)
    return {
        "outage_windows": _windows(track, applied, scenarios),
        "outage_windows_vs_fixes": by_inputs,
    }


def _windows(
    track: ErrorTrack | None, applied: AppliedScenario, scenarios: ScenariosParams
) -> list[dict[str, Any]]:
    """The outage-window metrics of an error track ([] without one)."""
    if track is None:
        return []
    return window_metrics(track, applied.outage_windows, applied.t0_ns, scenarios.metrics)


def run_scenarios(
    inputs: RunInputs,
    name: str,
    params: Any,
    scenarios: ScenariosParams,
    names: Sequence[str],
    backend: Backend,
    workers: int = 1,
    scheduler: str = "processes",
    compute: ComputeParams | None = None,
) -> Iterator[tuple[str, RunOutput, AppliedScenario]]:
    """Replay filter ``name`` (of any family; ``params`` its section) under each scenario of
    ``names``; yields them in order.

    Scenarios that transform the tables alike (``sats_0`` and a complete outage of the same
    windows) are replayed once. The replays are tasks of ``compute.run_tasks`` on
    ``scheduler``: by default ``workers`` forked processes when there are several (they
    share the tables and compiled kernels), or a Dask cluster. The nominal run is made
    when a fault scenario needs it for its checks (and yielded only if ``names`` asks).

    Raises:
        KeyError: a name is not in ``scenarios.named``.
        ScenarioError: a scenario needs data the dataset lacks, or has faults and the
            filter is not an INS filter (the pass criteria read the INS state).
        DivergenceError: a run diverged and the filter's params say ``raise``.
    """
    family = family_of(name)
    specs = {s: scenarios.get(s) for s in names}
    faulty = [s for s, spec in specs.items() if spec.faults]
    if faulty and family.name != "ins":
        raise ScenarioError(
            f"{name}: fault scenarios ({', '.join(faulty)}) are checked against pass criteria "
            f"on the INS state; {family.name} filters run the outage and satellite scenarios"
        )
    smoothed_reference = (
        getattr(params, "smooth", False) and not _has_truth(inputs)
        and any(spec.windows for spec in specs.values())
    )  # fmt: skip
    needs_nominal = smoothed_reference or any(spec.faults for spec in specs.values())
    if needs_nominal and "nominal" not in specs:
        specs = {"nominal": scenarios.get("nominal"), **specs}
    first: dict[tuple[Any, ...], str] = {}
    for sname, spec in specs.items():
        first.setdefault(_transform_key(spec), sname)
    job = _Job(inputs, family, name, params, scenarios, backend)
    replays = list(first.values())
    results: list[RunOutput] = []
    for r in run_tasks(_replay, job, replays, scheduler=scheduler, workers=workers,
                       params=compute, label=f"run {name}"):  # fmt: skip
        if isinstance(r, TaskError):
            r.reraise()  # a replay that failed fails the run, as it would in one process
        else:
            results.append(r)
    by_key = {_transform_key(specs[s]): r for s, r in zip(replays, results, strict=True)}
    nominal = by_key.get(_transform_key(specs["nominal"])) if "nominal" in specs else None
    reference = None
    if smoothed_reference and nominal is not None and nominal.smoothed is not None:
        reference = nominal.smoothed[0]
        log.info("no truth: outage windows measured against the smoothed nominal run")
    for sname in names:
        applied = job.apply(sname)
        run = by_key[_transform_key(specs[sname])]
        metrics = scenario_metrics(inputs, family, applied, run, scenarios, reference)
        if applied.injected:
            assert nominal is not None
            result, reference = run.result, nominal.result
            assert isinstance(result, RunResult)
            assert isinstance(reference, RunResult)
            truth = inputs.tables.get("truth")
            checks = check_fault(applied, result, reference, truth, params.gating.timeout_s)
            metrics["fault_checks"] = [c.to_json() for c in checks]
            metrics["fault_checks_passed"] = all(c.passed for c in checks)
        log.info("%s under %s: %s", name, sname, run.status)
        yield sname, replace(run, metrics=metrics), applied


@dataclass(frozen=True)
class _Job:
    """One filter over one dataset's tables: applies a scenario and replays it."""

    inputs: RunInputs
    family: Family
    name: str
    params: Any
    scenarios: ScenariosParams
    backend: Backend

    def apply(self, scenario: str) -> AppliedScenario:
        spec = self.scenarios.get(scenario)
        mask = self.scenarios.selection_mask_deg
        return apply_scenario(self.inputs.tables, scenario, spec, mask_deg=mask)

    def replay(self, scenario: str) -> RunOutput:
        tables = dict(self.apply(scenario).tables)
        inputs = replace(self.inputs, tables=tables, log_tables=self.inputs.tables)
        return self.family.run(inputs, self.name, self.params, self.backend)


def _has_truth(inputs: RunInputs) -> bool:
    truth = inputs.tables.get("truth")
    return truth is not None and truth.num_rows > 0


def _transform_key(spec: ScenarioSpec) -> tuple[Any, ...]:
    """What a scenario does to the tables (its description aside): keeping 0 satellites in
    a window is a complete outage of it."""
    sats = spec.satellites
    if sats is not None and sats.keep == 0:
        sats = None
    return (spec.windows, sats, spec.faults)


def _replay(job: _Job, scenario: str) -> RunOutput:
    """One scenario's replay (a ``compute.run_tasks`` task)."""
    return job.replay(scenario)
