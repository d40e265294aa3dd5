"""One sample of the cascade and the compiled replay loop (numba, ``cache=True``).

A *sample* is one reading of the vehicle sensors at ``t`` (radar speed, FOG yaw rate, steer
potentiometer), with the GPS fix (East, North, heading; NaN while unavailable) taken at the
same instant. ``cascade_sample`` processes it in the paper's order (section 7: measurement
update, then the time update to the next sample, here run at the start of the next call):

1. both filters predicted from their last time to ``t``: the navigation filter with the
   radar speed and gyro rate held from the previous sample (Euler steps of at most
   ``max_step_s``), the control filter with the steering command applied since then;
2. navigation update with the GPS rows present (``Y1``; none during an outage: ``C1 = 0``);
3. control update with ``Y2 = [gyro - g_b_hat, radar - r_b_hat, pot]``: the yaw rate and the
   speed corrected with the navigation filter's *just updated* bias estimates (the cascade);
4. covariance symmetry and positive definiteness, the NaN barrier, the output row.

The steering command applied from ``t`` on is written into ``mem[M_CMD]`` by the caller
after the call: the recorded command in a replay, the LQR's command computed from these
estimates in the closed loop (``closed_loop``). A GPS fix between two vehicle samples is a
``nav_only`` call (navigation predict and update only). The caller also places the control
discretization of the coming step in ``mem`` (``engine.CascadeState.prepare``: eq. 14 is
computed with scipy outside the compiled code). The loop over samples is Python
(``engine``): a call costs about 5 us of dispatch, and one compiled entry point keeps the
cold compilation short. The run state lives in plain arrays (``engine.CascadeState``
allocates them):

- ``x`` (12,): ``X1`` then ``X2``; ``P`` (2, 6, 6): their covariances;
- ``mem`` (float, ``MEM_DIM``): held inputs and the control discretization cache;
- ``imem`` (int, ``IMEM_DIM``): filter times (ns), started flag, gate clocks per stream;
- the settings (``CascadeSettings``): Table 1 and 2, the model, the unscented set-up, gating,
  step and divergence limits;
- logs (``records.RunLog``): ``out_t``, ``out_x`` (K, 12), ``out_P`` (K, 2, 6, 6),
  innovations, events, counts.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from navreplay.pipeline._jit import njit
from navreplay.pipeline.estimation.cascaded.filters import (
    EST_EKF,
    EST_UKF,
    Filter,
    Gating,
    Measurement,
    Step,
    Unscented,
    apply_update,
    predict,
    prepare_update,
)
from navreplay.pipeline.estimation.cascaded.model import (
    DISC_DIM,
    MODEL_CTL,
    MODEL_NAV,
    NAV_E,
    NAV_GB,
    NAV_N,
    NAV_RB,
    NX,
    model_noise,
)
from navreplay.pipeline.estimation.cascaded.numerics import check_filter
from navreplay.pipeline.estimation.core.gating import (
    STATUS_INDEFINITE,
    STATUS_LIMIT,
    STATUS_OK,
    fail,
    keep_pd,
    record_event,
)
from navreplay.pipeline.estimation.core.runlog import CNT_OUT, CNT_STOP, RunLog
from navreplay.pipeline.nav.earth import F64, I64

# measurement streams (innovations.parquet ``stream``)
S_GPS_POS, S_GPS_HEADING, S_YAW_RATE, S_SPEED, S_STEER = 0, 1, 2, 3, 4
STREAM_NAMES = ("gnss_pos", "gnss_heading", "yaw_rate", "speed", "steer")
STREAM_UNITS = ("m", "rad", "rad/s", "m/s", "rad")
N_STREAMS = 5

#: event kind beyond ``core.gating``'s: an input interval longer than ``gap_s``
EV_GAP = 5

# vehicle sample columns (``veh``) and GPS columns (``gps``)
V_RADAR, V_GYRO, V_POT, V_CMD = 0, 1, 2, 3
VEH_COLS = 4
G_E, G_N, G_PSI = 0, 1, 2
GPS_COLS = 3

# float memory, int memory
M_RADAR, M_GYRO, M_CMD, M_DISC = 0, 1, 2, 3
MEM_DIM = M_DISC + DISC_DIM
I_T_NAV, I_T_CTL, I_STARTED, I_REJ = 0, 1, 2, 3
IMEM_DIM = I_REJ + N_STREAMS


class CascadeRun(NamedTuple):
    """The live state of a run (module docstring): both filters' states ``x`` (2 NX,) and
    covariances ``P`` (2, NX, NX), the held inputs and discretization ``mem`` and the
    integer memory ``imem`` (times, started flag, per-stream rejection clocks)."""

    x: F64
    P: F64
    mem: F64
    imem: I64


class CascadeSettings(NamedTuple):
    """A cascaded filter's settings (``engine.make_setup``).

    Attributes:
        est: the estimator, ``filters.EST_*``.
        q: process noise (2, NX), Table 1 (navigation, control), accumulating over
            ``noise_interval_s`` (``model.model_noise``).
        r: measurement variances (2, 3), Table 2 (navigation, control).
        par: the model's parameters (``model.model_params``).
        ut: the sigma points (``filters.Unscented``; UKF and hybrid).
        gate: chi-square threshold by block dimension; timeout_s: a stream rejected this
            long is reset, s.
        ekf_mean: (NX,) the hybrid's navigation states whose mean is the EKF's.
        max_step_s: longest navigation Euler step, s; gap_s: an input interval longer than
            this is logged (``EV_GAP``), s.
        max_pos_sigma_m: divergence limit on the horizontal position 1-sigma, m.
    """

    est: int
    q: F64
    noise_interval_s: float
    r: F64
    par: F64
    ut: Unscented
    gate: F64
    timeout_s: float
    ekf_mean: I64
    max_step_s: float
    gap_s: float
    max_pos_sigma_m: float


NAV_BLOCK_OF_ROW = np.array([0, 0, 1], np.int64)  # E and N one block, heading another
NAV_STREAMS = np.array([S_GPS_POS, S_GPS_HEADING], np.int64)
CTL_BLOCK_OF_ROW = np.array([0, 1, 2], np.int64)  # each vehicle sensor its own block
CTL_STREAMS = np.array([S_YAW_RATE, S_SPEED, S_STEER], np.int64)
NO_EKF_MEAN = np.zeros(NX, np.int64)  # the control filter: every mean unscented


@njit(cache=True, error_model="numpy", inline="always")
def filters_of(x: F64, P: F64, est: int) -> tuple[Filter, Filter]:
    """The navigation and control ``Filter`` of a run's state ``x`` (2 NX,) and ``P``
    (2, NX, NX) (views) under estimator ``est``: the control filter is the EKF but for the
    UKF (its model is linear: see ``filters``)."""
    return (
        Filter(MODEL_NAV, est, x[:NX], P[0]),
        Filter(MODEL_CTL, EST_UKF if est == EST_UKF else EST_EKF, x[NX:], P[1]),
    )


@njit(cache=True, error_model="numpy", inline="always")
def _nav_predict(t_ns: int, f1: Filter, run: CascadeRun, cset: CascadeSettings, log: RunLog
                 ) -> bool:  # fmt: skip
    """Navigation time update from ``imem[I_T_NAV]`` to ``t_ns`` with the held inputs."""
    mem, imem = run.mem, run.imem
    dt = (t_ns - imem[I_T_NAV]) * 1e-9
    if dt <= 0.0:
        return True
    if dt > cset.gap_s:
        record_event(log.ev_i, log.ev_f, log.counts, t_ns, EV_GAP, -1, -1, dt)
    n_sub = max(1, math.ceil(dt / cset.max_step_s - 1e-9))
    h = dt / n_sub
    Q = np.empty((NX, NX))
    model_noise(cset.q[0], h, cset.noise_interval_s, Q)
    step = Step(mem[M_RADAR : M_GYRO + 1], h, cset.par, mem[M_DISC : M_DISC + DISC_DIM], Q)
    for _ in range(n_sub):
        if not predict(f1, step, cset.ut, cset.ekf_mean):
            return False
    imem[I_T_NAV] = t_ns
    return True


@njit(cache=True, error_model="numpy", inline="always")
def _ctl_predict(t_ns: int, f2: Filter, run: CascadeRun, cset: CascadeSettings) -> bool:
    """Control time update from ``imem[I_T_CTL]`` to ``t_ns`` (exact ZOH, held command)."""
    mem, imem = run.mem, run.imem
    dt = (t_ns - imem[I_T_CTL]) * 1e-9
    if dt <= 0.0:
        return True
    disc = mem[M_DISC : M_DISC + DISC_DIM]
    if disc[0] != dt:
        raise ValueError("cascade: the control discretization was not prepared for this step")
    Q = np.empty((NX, NX))
    model_noise(cset.q[1], dt, cset.noise_interval_s, Q)
    if not predict(f2, Step(mem[M_CMD : M_CMD + 1], dt, cset.par, disc, Q), cset.ut,
                   NO_EKF_MEAN):  # fmt: skip
        return False
    imem[I_T_CTL] = t_ns
    return True


@njit(cache=True, error_model="numpy")
def finish(t_ns: int, x: F64, P: F64, cset: CascadeSettings, log: RunLog) -> int:
    """Positive definiteness of both covariances and the NaN barrier; a status code."""
    ev_i, ev_f, counts = log.ev_i, log.ev_f, log.counts
    L = np.empty((NX, NX))
    for f in range(2):
        if not keep_pd(P[f], NX, L, t_ns, ev_i, ev_f, counts):
            return fail(t_ns, STATUS_INDEFINITE, ev_i, ev_f, counts)
    if not check_filter(x[:NX], P[0], NX, NAV_E, NAV_N, cset.max_pos_sigma_m):
        return fail(t_ns, STATUS_LIMIT, ev_i, ev_f, counts)
    if not check_filter(x[NX:], P[1], NX, -1, -1, cset.max_pos_sigma_m):
        return fail(t_ns, STATUS_LIMIT, ev_i, ev_f, counts)
    return STATUS_OK


@njit(cache=True, error_model="numpy", inline="always")
def _update(t_ns: int, f: Filter, meas: Measurement, gating: Gating, ut: Unscented,
            log: RunLog) -> bool:  # fmt: skip
    """``prepare_update`` then ``apply_update``; False if a UKF prior was not PD."""
    ur, acc, ma = prepare_update(t_ns, f, meas, gating, ut, log)
    if ma < 0:
        return False
    apply_update(f, ur, acc, ma)
    return True


@njit(cache=True, error_model="numpy")
def cascade_sample(
    t_ns: int, veh: F64, gps: F64, nav_only: bool, run: CascadeRun, cset: CascadeSettings,
    log: RunLog,
) -> int:  # fmt: skip
    """Process one vehicle sample (and the GPS fix at the same time) through the cascade,
    or with ``nav_only`` a GPS fix alone (no output row).

    Args:
        t_ns: sample time; veh: (4,) radar speed, gyro rate, potentiometer, command (the
            command column is not read here; see the module docstring); gps: (3,) East,
            North (m, local frame), heading (rad), NaN where unavailable.
        run: the live state; cset: the settings; log: outputs, innovations, events.

    Returns:
        a ``kernels.common.STATUS_*`` code.
    """
    x, P, mem, imem = run
    f1, f2 = filters_of(x, P, cset.est)
    gating = Gating(cset.gate, cset.timeout_s, imem[I_REJ:])
    if imem[I_STARTED] == 0:
        if nav_only:
            return STATUS_OK
        imem[I_T_NAV] = t_ns
        imem[I_T_CTL] = t_ns
        imem[I_STARTED] = 1
        ok = True
    else:
        ok = _nav_predict(t_ns, f1, run, cset, log)
        if ok and not nav_only:
            ok = _ctl_predict(t_ns, f2, run, cset)
    nav = Measurement(gps, cset.r[0], NAV_BLOCK_OF_ROW, NAV_STREAMS)
    ok = ok and _update(t_ns, f1, nav, gating, cset.ut, log)
    if ok and not nav_only:
        radar, gyro = veh[V_RADAR], veh[V_GYRO]
        if math.isfinite(radar):
            mem[M_RADAR] = radar
        if math.isfinite(gyro):
            mem[M_GYRO] = gyro
        z2 = np.empty(3)
        z2[0], z2[1], z2[2] = gyro - f1.x[NAV_GB], radar - f1.x[NAV_RB], veh[V_POT]
        ctl = Measurement(z2, cset.r[1], CTL_BLOCK_OF_ROW, CTL_STREAMS)
        ok = _update(t_ns, f2, ctl, gating, cset.ut, log)
    if not ok:
        return fail(t_ns, STATUS_INDEFINITE, log.ev_i, log.ev_f, log.counts)
    status = finish(t_ns, x, P, cset, log)
    if status == STATUS_OK and not nav_only:
        _record(t_ns, x, P, log)
    return status


@njit(cache=True, error_model="numpy")
def _record(t_ns: int, x: F64, P: F64, log: RunLog) -> None:
    """Append the output row of a sample (counted past the capacity)."""
    out_t, out_x, out_P, counts = log.out_t, log.out_x, log.out_P, log.counts
    k = counts[CNT_OUT]
    if k < out_t.shape[0]:
        out_t[k] = t_ns
        for i in range(2 * NX):
            out_x[k, i] = x[i]
        for f in range(2):
            for i in range(NX):
                for j in range(NX):
                    out_P[k, f, i, j] = P[f, i, j]
    counts[CNT_OUT] = k + 1
    counts[CNT_STOP] += 1
