"""Each fault scenario's behaviour against the catalogue's pass criteria (bad-inputs.md).

The drives are the seoul_campus synthesizer's (10 s at rest, then driving; fix errors
correlated over 30 s as params.yaml sets them); every fault comes after the filters have
converged on the move (heading and biases), as the catalogue's criteria assume. The faults are
injected by the scenario engine and judged by ``scenarios.criteria``, the same code that
writes ``fault_checks`` into metrics.json.
"""

from __future__ import annotations

import pytest

from navreplay.pipeline.estimation.ins.replay import RunResult, run_filter
from navreplay.pipeline.scenarios.apply import apply_scenario
from navreplay.pipeline.scenarios.config import FaultSpec, ScenarioSpec
from navreplay.pipeline.scenarios.criteria import Check, check_fault
from tests.pipeline.scenarios.drives import drive, params

# fault -> (drive length s, fault time s): long enough for the fault and its aftermath
CASES = {
    "F1": (60.0, 30.0),
    "F2": (90.0, 25.0),
    "F4": (480.0, 120.0),  # the catalogue's 300 s outage
    "F5": (150.0, 60.0),
    "F7": (90.0, 20.0),
    "F9": (90.0, 60.0),
    "F11": (60.0, 30.0),
    "F12": (60.0, 30.0),
}
FILTERS = ("lc_ekf", "tc_ekf", "tc_ukf")

_nominal: dict[tuple[str, float], RunResult] = {}


def checks(kind: str, name: str) -> list[Check]:
    duration, at = CASES[kind]
    tables, sensors = drive(duration)
    p = params().filters.get(name)
    if (name, duration) not in _nominal:
        _nominal[name, duration] = run_filter(tables, sensors, name, p)
    applied = apply_scenario(tables, kind, ScenarioSpec(faults=(FaultSpec(kind, at),)))  # type: ignore[arg-type]
    r = run_filter(applied.tables, sensors, name, p)
    assert r.status == "ok"
    out = check_fault(applied, r, _nominal[name, duration], tables["truth"], p.gating.timeout_s)
    assert out, "no criterion was checked"
    return out


def failed(out: list[Check]) -> list[str]:
    return [f"{c.criterion}: {c.value} (needs {c.threshold})" for c in out if not c.passed]


@pytest.mark.parametrize("name", FILTERS)
@pytest.mark.parametrize("kind", ["F1", "F4", "F5", "F9", "F11", "F12"])
def test_fault_meets_the_catalogue_criteria(kind: str, name: str) -> None:
    assert failed(checks(kind, name)) == []


def test_f2_step_is_followed_after_exactly_one_reset_by_loose_coupling() -> None:
    out = checks("F2", "lc_ekf")
    assert failed(out) == []
    assert {c.criterion for c in out} >= {"resets", "reset delay, s"}


@pytest.mark.parametrize("name", ["tc_ekf", "tc_ukf"])
def test_f2_step_is_followed_after_exactly_one_reset_by_tight_coupling(name: str) -> None:
    assert failed(checks("F2", name)) == []


@pytest.mark.parametrize("name", FILTERS)
def test_f7_meets_the_catalogue_criteria(name: str) -> None:
    """Every filter rejects a sample (a fix, an observation epoch) at the injected fraction,
    10 % +- 20 %, and stays within 3 sigma.

    Per block it rejects the outliers whose error alone exceeds its gate, within 20 %, and no
    more: on 0.8-2 m pseudoranges about a quarter of the N(0, 20 m) errors are inside the gate
    (~4 sigma) and indistinguishable from noise, so tight coupling rejects fewer satellites
    than were hit, while a hit epoch almost always has one beyond the gate.
    """
    out = {c.criterion: c for c in checks("F7", name)}
    raw = out["rejected fraction in the burst"]
    assert raw.passed, raw
    gate = out["rejected blocks vs outliers beyond the gate"]
    assert gate.passed, gate
    assert out["position inside 3 sigma"].passed
