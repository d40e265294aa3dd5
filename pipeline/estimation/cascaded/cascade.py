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
- ``cfg`` (``C_*``), ``q`` (2, 6) Table 1, ``r`` (2, 3) Table 2, ``par`` (model), ``wm``,
  ``wc`` (unscented weights), ``gate`` (chi-square by dimension), ``ekf_mean`` (hybrid);
- logs: ``out_t``, ``out_x`` (K, 12), ``out_P`` (K, 2, 6, 6), innovations, events, counts.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from navreplay.pipeline._jit import njit
from navreplay.pipeline.estimation.cascaded.filters import (
    EST_EKF,
    EST_UKF,
    apply_update,
    ekf_predict,
    prepare_update,
    ukf_predict,
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
from navreplay.pipeline.estimation.kernels.common import (
    CNT_OUT,
    CNT_STOP,
    STATUS_INDEFINITE,
    STATUS_LIMIT,
    STATUS_OK,
    fail,
    keep_pd,
    record_event,
)
from navreplay.pipeline.estimation.kernels.records import RunLog
from navreplay.pipeline.nav.earth import F64, I64

# measurement streams (innovations.parquet ``stream``)
S_GPS_POS, S_GPS_HEADING, S_YAW_RATE, S_SPEED, S_STEER = 0, 1, 2, 3, 4
STREAM_NAMES = ("gnss_pos", "gnss_heading", "yaw_rate", "speed", "steer")
STREAM_UNITS = ("m", "rad", "rad/s", "m/s", "rad")
N_STREAMS = 5

#: event kind beyond ``kernels.common``'s: an input interval longer than ``gap_s``
EV_GAP = 5

# vehicle sample columns (``veh``) and GPS columns (``gps``)
V_RADAR, V_GYRO, V_POT, V_CMD = 0, 1, 2, 3
VEH_COLS = 4
G_E, G_N, G_PSI = 0, 1, 2
GPS_COLS = 3

# float memory, int memory, settings
M_RADAR, M_GYRO, M_CMD, M_DISC = 0, 1, 2, 3
MEM_DIM = M_DISC + DISC_DIM
I_T_NAV, I_T_CTL, I_STARTED, I_REJ = 0, 1, 2, 3
IMEM_DIM = I_REJ + N_STREAMS
C_EST, C_GAMMA, C_TIMEOUT, C_NOISE_DT, C_MAX_STEP, C_GAP, C_MAX_POS_SIGMA = 0, 1, 2, 3, 4, 5, 6
CFG_DIM = 7


class CascadeRun(NamedTuple):
    """The live state of a run (module docstring): both filters' states ``x`` (2 NX,) and
    covariances ``P`` (2, NX, NX), the held inputs and discretization ``mem`` and the
    integer memory ``imem`` (times, started flag, per-stream rejection clocks)."""

    x: F64
    P: F64
    mem: F64
    imem: I64


class CascadeSettings(NamedTuple):
    """A cascaded filter's settings (``engine.make_setup``): ``cfg`` (``C_*``), process
    noise densities ``q`` (2, NX), measurement variances ``r`` (2, 3), the model
    parameters ``par``, the unscented weights ``wm``, ``wc``, the chi-square ``gate`` by
    dimension, and ``ekf_mean`` (the hybrid's states propagated through the mean)."""

    cfg: F64
    q: F64
    r: F64
    par: F64
    wm: F64
    wc: F64
    gate: F64
    ekf_mean: I64


NAV_BLOCK_OF_ROW = np.array([0, 0, 1], np.int64)  # E and N one block, heading another
NAV_STREAMS = np.array([S_GPS_POS, S_GPS_HEADING], np.int64)
CTL_BLOCK_OF_ROW = np.array([0, 1, 2], np.int64)  # each vehicle sensor its own block
CTL_STREAMS = np.array([S_YAW_RATE, S_SPEED, S_STEER], np.int64)


@njit(cache=True, error_model="numpy")
def _nav_predict(
    t_ns: int, x1: F64, P1: F64, mem: F64, imem: I64, cfg: F64, q: F64, par: F64, wm: F64,
    wc: F64, ekf_mean: I64, ev_i: I64, ev_f: F64, counts: I64,
) -> bool:  # fmt: skip
    """Navigation time update from ``imem[I_T_NAV]`` to ``t_ns`` with the held inputs."""
    dt = (t_ns - imem[I_T_NAV]) * 1e-9
    if dt <= 0.0:
        return True
    if dt > cfg[C_GAP]:
        record_event(ev_i, ev_f, counts, t_ns, EV_GAP, -1, -1, dt)
    n_sub = max(1, math.ceil(dt / cfg[C_MAX_STEP] - 1e-9))
    h = dt / n_sub
    u = mem[M_RADAR : M_GYRO + 1]
    disc = mem[M_DISC : M_DISC + DISC_DIM]
    Q = np.empty((NX, NX))
    model_noise(q, h, cfg[C_NOISE_DT], Q)
    est = int(cfg[C_EST])
    for _ in range(n_sub):
        if est == EST_EKF:
            ekf_predict(MODEL_NAV, x1, P1, u, h, par, disc, Q)
        elif not ukf_predict(MODEL_NAV, x1, P1, u, h, par, disc, Q, wm, wc, cfg[C_GAMMA],
                             ekf_mean):  # fmt: skip
            return False
    imem[I_T_NAV] = t_ns
    return True


@njit(cache=True, error_model="numpy")
def _ctl_predict(
    t_ns: int, x2: F64, P2: F64, mem: F64, imem: I64, cfg: F64, q: F64, par: F64, wm: F64,
    wc: F64,
) -> bool:  # fmt: skip
    """Control time update from ``imem[I_T_CTL]`` to ``t_ns`` (exact ZOH, held command)."""
    dt = (t_ns - imem[I_T_CTL]) * 1e-9
    if dt <= 0.0:
        return True
    disc = mem[M_DISC : M_DISC + DISC_DIM]
    if disc[0] != dt:
        raise ValueError("cascade: the control discretization was not prepared for this step")
    u = mem[M_CMD : M_CMD + 1]
    Q = np.empty((NX, NX))
    model_noise(q, dt, cfg[C_NOISE_DT], Q)
    if int(cfg[C_EST]) == EST_UKF:
        none = np.zeros(NX, np.int64)
        if not ukf_predict(MODEL_CTL, x2, P2, u, dt, par, disc, Q, wm, wc, cfg[C_GAMMA], none):
            return False
    else:
        ekf_predict(MODEL_CTL, x2, P2, u, dt, par, disc, Q)
    imem[I_T_CTL] = t_ns
    return True


@njit(cache=True, error_model="numpy")
def finish(t_ns: int, x: F64, P: F64, cfg: F64, ev_i: I64, ev_f: F64, counts: I64) -> int:
    """Positive definiteness of both covariances and the NaN barrier; a status code."""
    L = np.empty((NX, NX))
    for f in range(2):
        if not keep_pd(P[f], NX, L, t_ns, ev_i, ev_f, counts):
            return fail(t_ns, STATUS_INDEFINITE, ev_i, ev_f, counts)
    if not check_filter(x[:NX], P[0], NX, NAV_E, NAV_N, cfg[C_MAX_POS_SIGMA]):
        return fail(t_ns, STATUS_LIMIT, ev_i, ev_f, counts)
    if not check_filter(x[NX:], P[1], NX, -1, -1, cfg[C_MAX_POS_SIGMA]):
        return fail(t_ns, STATUS_LIMIT, ev_i, ev_f, counts)
    return STATUS_OK


@njit(cache=True, error_model="numpy")
def _update(
    model: int, est: int, t_ns: int, x: F64, P: F64, z: F64, r: F64, block_of_row: I64,
    streams: I64, gate: F64, cfg: F64, rej: I64, wm: F64, wc: F64, inn_i: I64, inn_f: F64,
    ev_i: I64, ev_f: F64, counts: I64,
) -> bool:  # fmt: skip
    """``prepare_update`` then ``apply_update``; False if a UKF prior was not PD."""
    m, _, Hm, rm, nu, S, Pxz, acc, ma = prepare_update(
        model, est, t_ns, x, P, z, r, block_of_row, streams, gate, cfg[C_TIMEOUT], rej, wm,
        wc, cfg[C_GAMMA], inn_i, inn_f, ev_i, ev_f, counts,
    )  # fmt: skip
    if m < 0:
        return False
    apply_update(est, x, P, Hm, rm, nu, S, Pxz, acc, ma)
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
    cfg, q, r, par, wm, wc, gate, ekf_mean = cset
    out_t, out_x, out_P, inn_i, inn_f, ev_i, ev_f, counts = log
    x1, x2, P1, P2 = x[:NX], x[NX:], P[0], P[1]
    est = int(cfg[C_EST])
    upd = EST_UKF if est == EST_UKF else EST_EKF
    rej = imem[I_REJ:]
    if imem[I_STARTED] == 0:
        if nav_only:
            return STATUS_OK
        imem[I_T_NAV] = t_ns
        imem[I_T_CTL] = t_ns
        imem[I_STARTED] = 1
        ok = True
    else:
        ok = _nav_predict(t_ns, x1, P1, mem, imem, cfg, q[0], par, wm, wc, ekf_mean, ev_i,
                          ev_f, counts)  # fmt: skip
        if ok and not nav_only:
            ok = _ctl_predict(t_ns, x2, P2, mem, imem, cfg, q[1], par, wm, wc)
    ok = ok and _update(MODEL_NAV, upd, t_ns, x1, P1, gps, r[0], NAV_BLOCK_OF_ROW, NAV_STREAMS,
                        gate, cfg, rej, wm, wc, inn_i, inn_f, ev_i, ev_f, counts)  # fmt: skip
    if ok and not nav_only:
        radar, gyro = veh[V_RADAR], veh[V_GYRO]
        if math.isfinite(radar):
            mem[M_RADAR] = radar
        if math.isfinite(gyro):
            mem[M_GYRO] = gyro
        z2 = np.empty(3)
        z2[0], z2[1], z2[2] = gyro - x1[NAV_GB], radar - x1[NAV_RB], veh[V_POT]
        ok = _update(MODEL_CTL, upd, t_ns, x2, P2, z2, r[1], CTL_BLOCK_OF_ROW, CTL_STREAMS, gate,
                     cfg, rej, wm, wc, inn_i, inn_f, ev_i, ev_f, counts)  # fmt: skip
    if not ok:
        return fail(t_ns, STATUS_INDEFINITE, ev_i, ev_f, counts)
    status = finish(t_ns, x, P, cfg, ev_i, ev_f, counts)
    if status == STATUS_OK and not nav_only:
        _record(t_ns, x, P, out_t, out_x, out_P, counts)
    return status


@njit(cache=True, error_model="numpy")
def _record(t_ns: int, x: F64, P: F64, out_t: I64, out_x: F64, out_P: F64, counts: I64) -> None:
    """Append the output row of a sample (counted past the capacity)."""
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
