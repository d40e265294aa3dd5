"""Run set-up, run state and the compiled stepper of the cascaded filters.

``make_setup`` packs a ``filters.cascaded_*`` section into the arrays the kernels take;
``CascadeState`` allocates one run's state and logs; a *stepper* processes one sample at a
time, which is what the closed loop needs (the plant is stepped in Python between samples):

- ``NumbaStepper`` calls the compiled ``cascade.cascade_sample``;
- ``reference.FilterpyStepper`` does the same with filterpy's filters.

Both expose ``x`` (the current estimate, (12,)), ``ok``, ``sample(t_ns, veh, gps)``,
``nav_epoch(t_ns, gps)``, ``set_command(u)`` and ``result()`` (``backends.Stepper``).
``backends.make_stepper`` picks one by backend name and ``backends.replay`` runs a whole
recording through either.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from navreplay.pipeline.distributions import chi2_ppf
from navreplay.pipeline.errors import DivergenceError, PipelineError
from navreplay.pipeline.estimation.cascaded import cascade as cs
from navreplay.pipeline.estimation.cascaded.config import (
    CASCADED_KINDS,
    NAV_STATE_NAMES,
    CascadedFilterParams,
)
from navreplay.pipeline.estimation.cascaded.filters import EST_EKF, EST_HYBRID, EST_UKF, Unscented
from navreplay.pipeline.estimation.cascaded.model import NX, ctl_discretize, model_params
from navreplay.pipeline.estimation.core import gating as gt
from navreplay.pipeline.estimation.core import runlog as rl
from navreplay.pipeline.estimation.core.runlog import RunLog
from navreplay.pipeline.estimation.core.tables import Event
from navreplay.pipeline.estimation.core.unscented import ukf_weights
from navreplay.pipeline.nav.earth import F64, I64

_EST_CODE = {"ekf": EST_EKF, "ukf": EST_UKF, "hybrid": EST_HYBRID}
EVENT_NAMES = {**gt.EVENT_NAMES, cs.EV_GAP: "input_gap"}
_NAN4 = np.full(cs.VEH_COLS, math.nan)


@dataclass(frozen=True)
class CascadeSetup:
    """Everything a backend needs besides the data: the kernel's ``settings``
    (``cascade.CascadeSettings``), the initial state ``x0`` (2 NX,) and covariances ``P0``
    (2, NX, NX), what to do on divergence, and the unscented transform's ``(alpha, beta,
    kappa)`` (the filterpy backend's sigma points)."""

    name: str
    settings: cs.CascadeSettings
    x0: F64
    P0: F64
    on_divergence: str
    ut_params: tuple[float, float, float]  # alpha, beta, kappa (UKF and hybrid)


def make_setup(name: str, params: CascadedFilterParams) -> CascadeSetup:
    """Pack filter ``name`` (a key of ``CASCADED_KINDS``) with its section ``params``."""
    wm = wc = np.ones(2 * NX + 1)
    gamma = 0.0
    ut = (1.0, 2.0, 0.0)
    if params.ukf is not None:
        ut = (params.ukf.alpha, params.ukf.beta, params.ukf.kappa)
        wm, wc, gamma = ukf_weights(NX, *ut)
    pn = params.process_noise
    sn = params.sensor_noise
    lin = params.linearization
    m = params.model
    par = model_params(
        m.omega_n_radps,
        m.zeta,
        m.k_r,
        m.k_v,
        m.tau_v_s,
        jacobian_at_desired=lin is not None and lin.jacobian_at == "desired_heading",
        desired_heading_rad=math.radians(lin.desired_heading_deg) if lin is not None else 0.0,
    )
    ekf_mean = np.zeros(NX, np.int64)
    if params.hybrid is not None:
        for s in params.hybrid.ekf_mean:
            ekf_mean[NAV_STATE_NAMES.index(s)] = 1
    gate = np.array([math.inf] + [chi2_ppf(params.gating.probability, d) for d in (1, 2, 3)])
    settings = cs.CascadeSettings(
        est=_EST_CODE[CASCADED_KINDS[name]],
        q=np.array([pn.navigation.values(), pn.control.values()]),
        noise_interval_s=float(pn.interval_s),
        r=np.array([sn.nav(), sn.ctl()]),
        par=par,
        ut=Unscented(wm, wc, float(gamma)),
        gate=gate,
        timeout_s=float(params.gating.timeout_s),
        ekf_mean=ekf_mean,
        max_step_s=float(params.step.max_step_s),
        gap_s=float(params.step.gap_s),
        max_pos_sigma_m=float(params.divergence.max_pos_sigma_m),
    )
    P0 = np.zeros((2, NX, NX))
    P0[0] = np.diag(params.initial.navigation.values())
    P0[1] = np.diag(params.initial.control.values())
    return CascadeSetup(name, settings, np.zeros(2 * NX), P0, params.divergence.on_divergence, ut)


@dataclass
class CascadedResult:
    """The outcome of one cascaded run.

    Attributes:
        filter, backend: names. t_ns: output times (K,). x: ``[X1, X2]`` per output (K, 12).
        P: covariances (K, 2, 6, 6). inn_i (J, 5), inn_f (J, 8): innovations
            (``core.gating`` layout; streams ``cascade.STREAM_NAMES``). events: by time.
        status: ``ok`` or ``diverged``; failure: what and when. runtime_s: wall time of the
            filter. duration_s: time span processed. extra: free-form (closed loop, frame).
    """

    filter: str
    backend: str
    t_ns: I64
    x: F64
    P: F64
    inn_i: I64
    inn_f: F64
    events: list[Event]
    status: str = "ok"
    failure: str | None = None
    runtime_s: float = 0.0
    duration_s: float = 0.0
    extra: dict[str, Any] = field(default_factory=dict)


class CascadeState:
    """The arrays of one run: state, memory and logs for up to ``capacity`` samples."""

    def __init__(self, setup: CascadeSetup, capacity: int, n_gps: int = 0) -> None:
        self.setup = setup
        self.x = setup.x0.copy()
        self.P = setup.P0.copy()
        self.mem = np.zeros(cs.MEM_DIM)
        self.mem[cs.M_DISC] = math.nan
        self._discs: dict[int, F64] = {}
        self.imem = np.zeros(cs.IMEM_DIM, np.int64)
        self.imem[cs.I_REJ :] = -1
        n_inn = 5 * capacity + 2 * n_gps + 8
        n_ev = n_inn + 2 * (capacity + n_gps) + 16
        self.out_t = np.zeros(capacity, np.int64)
        self.out_x = np.zeros((capacity, 2 * NX))
        self.out_P = np.zeros((capacity, 2, NX, NX))
        self.inn_i = np.zeros((n_inn, rl.INN_I_COLS), np.int64)
        self.inn_f = np.zeros((n_inn, rl.INN_F_COLS))
        self.ev_i = np.zeros((n_ev, 4), np.int64)
        self.ev_f = np.zeros(n_ev)
        self.counts = np.zeros(rl.CNT_DIM, np.int64)
        self.log = RunLog(self.out_t, self.out_x, self.out_P, self.inn_i, self.inn_f, self.ev_i,
                          self.ev_f, self.counts)  # fmt: skip

    def prepare(self, t_ns: int) -> None:
        """Place the control discretization (eq. 14) of the step to ``t_ns`` in ``mem``,
        computed once per distinct step length."""
        if not self.imem[cs.I_STARTED]:
            return
        dt_ns = int(t_ns - self.imem[cs.I_T_CTL])
        if dt_ns <= 0 or self.mem[cs.M_DISC] == dt_ns * 1e-9:
            return
        disc = self._discs.get(dt_ns)
        if disc is None:
            disc = self._discs[dt_ns] = ctl_discretize(self.setup.settings.par, dt_ns * 1e-9)
        self.mem[cs.M_DISC :] = disc

    def args(self) -> tuple[cs.CascadeRun, cs.CascadeSettings, RunLog]:
        """The records ``cascade_sample`` takes after ``(t, veh, gps, nav_only)``: they hold
        this state's arrays themselves (the kernel updates them in place)."""
        return cs.CascadeRun(self.x, self.P, self.mem, self.imem), self.setup.settings, self.log

    def result(self, backend: str, status: int, runtime_s: float) -> CascadedResult:
        """Collect the logs into a ``CascadedResult``.

        Raises:
            PipelineError: the run wanted more rows than its logs hold (the capacity is sized
                from the samples, so this is a bug, never a silent truncation).
        """
        k_out, k_inn, k_ev = (int(self.counts[c]) for c in (rl.CNT_OUT, rl.CNT_INN, rl.CNT_EV))
        have = (self.out_t.size, self.inn_i.shape[0], self.ev_i.shape[0])
        if k_out > have[0] or k_inn > have[1] or k_ev > have[2]:
            raise PipelineError(
                f"cascaded run log overflow: {(k_out, k_inn, k_ev)} rows wanted, {have} held "
                "(outputs, innovations, events)"
            )
        events = [
            Event(
                int(self.ev_i[j, 0]),
                EVENT_NAMES.get(int(self.ev_i[j, 1]), str(self.ev_i[j, 1])),
                cs.STREAM_NAMES[self.ev_i[j, 2]] if self.ev_i[j, 2] >= 0 else "",
                "",
                float(self.ev_f[j]),
            )
            for j in range(k_ev)
        ]
        t = self.out_t[:k_out].copy()
        failure = None
        if status != gt.STATUS_OK:
            failure = f"{gt.STATUS_TEXT[status]} at t_ns={int(self.counts[rl.CNT_T_FAIL])}"
        return CascadedResult(
            filter=self.setup.name,
            backend=backend,
            t_ns=t,
            x=self.out_x[:k_out].copy(),
            P=self.out_P[:k_out].copy(),
            inn_i=self.inn_i[:k_inn].copy(),
            inn_f=self.inn_f[:k_inn].copy(),
            events=events,
            status="ok" if status == gt.STATUS_OK else "diverged",
            failure=failure,
            runtime_s=runtime_s,
            duration_s=float((t[-1] - t[0]) * 1e-9) if t.size else 0.0,
        )


class StepperBase:
    """What both backends' steppers share (``backends.Stepper``): the run's ``state``
    (``CascadeState``), its status and wall time, ``x``, ``ok``, ``set_command`` and
    ``result``. On divergence ``_set_status`` raises ``DivergenceError`` unless the section
    says ``on_divergence: flag``, in which case later samples are ignored and ``result``
    reports the run as diverged."""

    backend = ""

    def __init__(self, setup: CascadeSetup, capacity: int, n_gps: int = 0) -> None:
        self.setup = setup
        self.state = CascadeState(setup, capacity, n_gps)
        self.status = gt.STATUS_OK
        self.wall = 0.0

    @property
    def x(self) -> F64:
        return self.state.x

    @property
    def ok(self) -> bool:
        return self.status == gt.STATUS_OK

    def set_command(self, u: float) -> None:
        self.state.mem[cs.M_CMD] = u

    def result(self) -> CascadedResult:
        return self.state.result(self.backend, self.status, self.wall)

    def _set_status(self, status: int) -> None:
        self.status = status
        if status != gt.STATUS_OK:
            raise_if_diverged(self.setup, self.state.result(self.backend, status, 0.0))


class NumbaStepper(StepperBase):
    """The compiled backend, one ``cascade_sample`` per call (``x`` is live, not a copy)."""

    backend = "numba"

    def __init__(self, setup: CascadeSetup, capacity: int, n_gps: int = 0) -> None:
        super().__init__(setup, capacity, n_gps)
        self._args = self.state.args()

    def sample(self, t_ns: int, veh: F64, gps: F64) -> None:
        self._call(t_ns, veh, gps, False)

    def nav_epoch(self, t_ns: int, gps: F64) -> None:
        """A GPS fix between vehicle samples."""
        self._call(t_ns, _NAN4, gps, True)

    def _call(self, t_ns: int, veh: F64, gps: F64, nav_only: bool) -> None:
        if self.status != gt.STATUS_OK:
            return
        t0 = time.perf_counter()
        if not nav_only:
            self.state.prepare(t_ns)
        status = int(cs.cascade_sample(t_ns, veh, gps, nav_only, *self._args))
        self.wall += time.perf_counter() - t0
        self._set_status(status)


def raise_if_diverged(setup: CascadeSetup, result: CascadedResult) -> None:
    """``DivergenceError`` for a diverged run whose section says ``on_divergence: raise``."""
    if setup.on_divergence == "raise":
        raise DivergenceError(
            f"filter {setup.name} ({result.backend}) diverged: {result.failure}; set "
            f"filters.{setup.name}.divergence.on_divergence: flag to keep the output up to it"
        )
