"""The cascaded filters on either backend: ``make_stepper`` makes the compiled stepper
(``engine.NumbaStepper``) or the filterpy one (``reference.FilterpyStepper``) by name, and
``replay`` runs a whole recording open loop through it (the closed loop, ``closed_loop``,
steps one itself).
"""

from __future__ import annotations

import math
import time
from typing import Protocol

import numpy as np

from navreplay.pipeline.estimation.cascaded import cascade as cs
from navreplay.pipeline.estimation.cascaded.engine import CascadedResult, CascadeSetup, NumbaStepper
from navreplay.pipeline.estimation.core.contract import Backend
from navreplay.pipeline.nav.earth import F64, I64


class Stepper(Protocol):
    """One cascaded filter, one sample at a time (either backend)."""

    @property
    def x(self) -> F64: ...

    @property
    def ok(self) -> bool: ...

    def sample(self, t_ns: int, veh: F64, gps: F64) -> None: ...

    def nav_epoch(self, t_ns: int, gps: F64) -> None: ...

    def set_command(self, u: float) -> None: ...

    def result(self) -> CascadedResult: ...


def make_stepper(setup: CascadeSetup, capacity: int, backend: Backend, n_gps: int = 0
                 ) -> Stepper:  # fmt: skip
    """A stepper of ``backend`` for up to ``capacity`` samples (and ``n_gps`` extra fixes)."""
    if backend == "numba":
        return NumbaStepper(setup, capacity, n_gps)
    from navreplay.pipeline.estimation.cascaded.reference import FilterpyStepper

    return FilterpyStepper(setup, capacity, n_gps)


def replay(
    setup: CascadeSetup, veh_t: I64, veh: F64, gps_t: I64, gps: F64, backend: Backend
) -> CascadedResult:
    """Run a recording open loop: every vehicle sample with the GPS fix of the same time,
    GPS fixes between samples as ``nav_epoch``, the recorded command (``veh[:, V_CMD]``,
    NaN = 0) applied after each sample. Raises ``DivergenceError`` on divergence unless the
    section says ``flag`` (the result then ends there)."""
    t0 = time.perf_counter()
    stepper = make_stepper(setup, veh_t.size, backend, gps_t.size)
    nan3 = np.full(cs.GPS_COLS, math.nan)
    j, m = 0, gps_t.size
    for k in range(veh_t.size):
        t = int(veh_t[k])
        while j < m and gps_t[j] < t:
            stepper.nav_epoch(int(gps_t[j]), gps[j])
            j += 1
        g = nan3
        if j < m and gps_t[j] == t:
            g = gps[j]
            j += 1
        stepper.sample(t, veh[k], g)
        if not stepper.ok:
            break
        cmd = float(veh[k, cs.V_CMD])
        stepper.set_command(cmd if math.isfinite(cmd) else 0.0)
    result = stepper.result()
    result.runtime_s = time.perf_counter() - t0
    return result
