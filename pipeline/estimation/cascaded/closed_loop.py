"""Closed loop: the paper's LQR steers the simulated tractor from a filter's estimates.

Each sample (paper 000 sections 5-6, 9): the simulator's readings at ``t`` go through the
cascade (a ``backends`` stepper, either backend); the straight-line LQR of eq. 8-14
(``pipeline.control.lqr``, gain from the plant model discretized with eq. 14 at the sample
period) computes ``u = -K_c X_c_hat`` from the *estimates* (``X_c_hat`` from the navigation
filter's East, North and heading and the control filter's yaw rate, yaw acceleration, steer
angle and steer rate); ``u`` is the control filter's input and drives the plant to the next
sample. Every filter therefore produces its own trajectory.

GPS outages are the simulator's (``TractorSim(gps_outages_s=...)``): the fix and heading are
NaN inside a window, so the navigation filter has no update (``C1 = 0``). The plant noise of a
seed is the same whatever the outages or the filter (the simulator draws every sensor every
step), so runs of one seed are paired.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from navreplay.pipeline.control.lqr import lqr_command, tractor_lqr_gain
from navreplay.pipeline.estimation.cascaded import cascade as cs
from navreplay.pipeline.estimation.cascaded.backends import make_stepper
from navreplay.pipeline.estimation.cascaded.engine import CascadedResult, CascadeSetup
from navreplay.pipeline.estimation.cascaded.model import (
    CTL_DEL,
    CTL_DELD,
    CTL_PD,
    CTL_PDD,
    NAV_E,
    NAV_N,
    NAV_PSI,
    NX,
)
from navreplay.pipeline.estimation.core.contract import Backend
from navreplay.pipeline.nav.earth import F64
from navreplay.pipeline.synth.tractor import TractorSim, TractorState, TractorStraightParams


@dataclass(frozen=True)
class ClosedLoopRun:
    """One closed-loop run.

    Attributes:
        result: the filter's outputs (one row per sample while it ran).
        t_s: sample times from the start (K,).
        truth: true plant states per sample (K, 9), ``TractorState`` fields.
        truth_x: the filters' states from the truth, ``[X1, X2]`` (K, 12).
        u: the command applied after each sample (K,).
        gps_valid: whether GPS was available at each sample (K,).
        lateral_err_m: true lateral error to the desired line (eq. 9), m (K,).
        outages_s: the GPS outage windows.
    """

    result: CascadedResult
    t_s: F64
    truth: F64
    truth_x: F64
    u: F64
    gps_valid: np.ndarray
    lateral_err_m: F64
    outages_s: tuple[tuple[float, float], ...]


def truth_states(truth: F64, params: TractorStraightParams) -> F64:
    """``[X1, X2]`` from true plant states (K, 9) and the simulated biases, (K, 12)."""
    b = params.biases
    k = truth.shape[0]
    f = {name: truth[:, i] for i, name in enumerate(TractorState._fields)}
    ones = np.ones(k)
    return np.column_stack(
        [
            f["east_m"], f["north_m"], b.radar_mps * ones, f["heading_rad"],
            b.gyro_radps * ones, b.heading_rad * ones,
            f["yaw_rate_radps"], f["yaw_accel_radps2"], f["speed_mps"], f["steer_rad"],
            f["steer_rate_radps"], b.steer_rad * ones,
        ]
    )  # fmt: skip


class _Loop:
    """The closed loop of one seed, advanced sample by sample; ``fork`` copies it whole.

    The simulator is stepped lazily at the start of the next sample (with the command of the
    previous one), so a copy taken between samples can still change the outage windows of
    the readings it has not drawn yet.
    """

    def __init__(self, setup: CascadeSetup, params: TractorStraightParams,
                 seed: int | np.random.SeedSequence, backend: Backend) -> None:  # fmt: skip
        self.params = params
        self.sim = TractorSim(params, seed)
        self.gain = tractor_lqr_gain(params.speed_mps, params.dt_s, params.model)
        self.line = params.line()
        n = params.steps + 1
        self.stepper = make_stepper(setup, n, backend)
        self.truth = np.empty((n, 9))
        self.u = np.zeros(n)
        self.valid = np.zeros(n, bool)
        self.k = 0  # next sample to process
        self.k_end = n
        self.outages: tuple[tuple[float, float], ...] = ()

    def set_outages(self, windows: Sequence[tuple[float, float]]) -> None:
        """GPS outage windows of the readings not drawn yet (half-open, s from the start)."""
        self.outages = tuple((float(a), float(b)) for a, b in windows)
        for a, b in self.outages:
            if not b > a:
                raise ValueError(f"GPS outage window ({a}, {b}) must have end > start")
        self.sim.gps_outages_s = self.outages

    def run(self, k_stop: int) -> None:
        """Process samples ``k`` up to ``k_stop`` (exclusive) or the end of the run."""
        sim, stepper, line, x = self.sim, self.stepper, self.line, self.stepper.x
        dt_ns = self.params.dt_ns
        veh = np.full(cs.VEH_COLS, math.nan)
        gps = np.empty(cs.GPS_COLS)
        for k in range(self.k, min(k_stop, self.k_end)):
            if k > 0:
                sim.step(self.u[k - 1])
            z = sim.measurement
            self.truth[k] = sim.truth
            self.valid[k] = z.gps_valid
            veh[cs.V_RADAR], veh[cs.V_GYRO], veh[cs.V_POT] = (
                z.speed_mps,
                z.yaw_rate_radps,
                z.steer_rad,
            )
            gps[cs.G_E], gps[cs.G_N], gps[cs.G_PSI] = z.east_m, z.north_m, z.heading_rad
            stepper.sample(k * dt_ns, veh, gps)
            if not stepper.ok:
                self.k_end = k
                break
            xc = line.control_state(
                x[NAV_E], x[NAV_N], x[NAV_PSI], x[NX + CTL_PD], x[NX + CTL_PDD],
                x[NX + CTL_DEL], x[NX + CTL_DELD],
            )  # fmt: skip
            self.u[k] = lqr_command(self.gain, xc)
            stepper.set_command(self.u[k])
            self.k = k + 1

    def fork(self) -> _Loop:
        """An independent copy (simulator, noise generator, filter state, logs)."""
        return copy.deepcopy(self)

    def finish(self) -> ClosedLoopRun:
        result = self.stepper.result()
        k_end = min(self.k_end, self.k, result.t_ns.size)
        truth = self.truth[:k_end]
        line = self.line
        c, s = math.cos(line.heading_rad), math.sin(line.heading_rad)
        lateral = (truth[:, 1] - line.east_m) * c - (truth[:, 2] - line.north_m) * s  # eq. 9
        return ClosedLoopRun(
            result=result,
            t_s=truth[:, 0].copy(),
            truth=truth,
            truth_x=truth_states(truth, self.params),
            u=self.u[:k_end].copy(),
            gps_valid=self.valid[:k_end].copy(),
            lateral_err_m=lateral,
            outages_s=self.outages,
        )


def run_closed_loop(
    setup: CascadeSetup,
    params: TractorStraightParams,
    seed: int | np.random.SeedSequence,
    *,
    gps_outages_s: Sequence[tuple[float, float]] = (),
    backend: Backend = "numba",
) -> ClosedLoopRun:
    """Simulate ``params.duration_s`` with the LQR closed on filter ``setup``'s estimates.

    A filter that diverges (``on_divergence: flag``) ends the run at that sample (the
    result says ``diverged``); with ``raise`` its ``DivergenceError`` propagates.
    """
    loop = _Loop(setup, params, seed, backend)
    loop.set_outages(gps_outages_s)
    loop.run(params.steps + 1)
    return loop.finish()


def run_closed_loop_scenarios(
    setup: CascadeSetup,
    params: TractorStraightParams,
    seed: int | np.random.SeedSequence,
    scenarios: Mapping[str, Sequence[tuple[float, float]]],
    *,
    backend: Backend = "numba",
) -> dict[str, ClosedLoopRun]:
    """``run_closed_loop`` for several outage scenarios of one seed, sharing the samples
    before the first outage: the loop runs once up to it and is then copied per scenario
    (identical to separate runs, since the noise of a seed does not depend on the outages;
    saves a third of the work for a nominal run and two outages starting halfway)."""
    starts = [a for windows in scenarios.values() for a, _ in windows]
    k_fork = math.ceil(min(starts) / params.dt_s - 1e-9) if starts else params.steps + 1
    trunk = _Loop(setup, params, seed, backend)
    trunk.run(k_fork)
    out: dict[str, ClosedLoopRun] = {}
    for name, windows in scenarios.items():
        branch = trunk.fork()
        branch.set_outages(windows)
        branch.run(params.steps + 1)
        out[name] = branch.finish()
    return out
