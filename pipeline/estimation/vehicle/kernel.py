"""Replay loops of the vehicle-model filters (paper 003), compiled whole with numba.

One loop serves the four filters, selected by ``VehicleSettings.mode``:

- ``MODE_KINEMATIC`` / ``MODE_DYNAMIC``: one EKF on that model (``vehicle.model``);
- ``MODE_SWITCHED``: one EKF whose process and yaw-rate models are chosen per step by the
  wheel speed with hysteresis (dynamic above ``v_up_mps``, back to kinematic below
  ``v_down_mps``; the paper selects the model by the speed range);
- ``MODE_IMM``: an interacting multiple model filter of both EKFs (Markov switching matrix,
  mixing, model likelihoods; the same arithmetic as filterpy's ``IMMEstimator``).

Array layouts (filled by ``pipeline.estimation.vehicle.replay``):

- ``stops`` (S, ``VS_COLS``): time (ns), vehicle-sample index (-1 = none), fix index (-1 =
  none), output flag. Between stops the state is predicted with the last vehicle input held
  (zero order), in sub-steps of at most ``max_step_s``.
- ``veh`` (V, ``VH_COLS``): wheel speed, steering of the kinematic and of the dynamic model
  (equal when the log has a steering angle; per-model virtual steering from the yaw rate
  otherwise), measured yaw rate and its flag (1 = fuse it).
- ``fix`` (M, ``FX_COLS``): north, east (m, local), GPS speed (m/s), course (rad), their
  1-sigma and usable flags.

Updates: every block (the north/east pair, speed, course, yaw rate) is chi-square gated on its
prior NIS (``core.gating.gate_blocks``) and the accepted rows are fused jointly in Joseph
form (``kernels.ekf.joseph_update``); innovations and rejections are recorded with
``core.gating``. The IMM gates with the model that has the larger predicted probability and
applies the same rows to both models.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from navreplay.pipeline._jit import njit
from navreplay.pipeline.estimation.core.gating import (
    EV_RESET,
    STATUS_INDEFINITE,
    STATUS_LIMIT,
    STATUS_NONFINITE,
    STATUS_OK,
    accepted_rows,
    fail,
    gate_blocks,
    keep_pd,
    record_event,
    record_innovations,
    streams_to_reset,
    update_reject_since,
)
from navreplay.pipeline.estimation.core.linalg import cholesky, joseph_update, symmetrize
from navreplay.pipeline.estimation.core.runlog import CNT_OUT, CNT_STOP, GatedBlocks, RunLog
from navreplay.pipeline.estimation.vehicle import model as vm
from navreplay.pipeline.nav.earth import F64, I64


class VehicleSchedule(NamedTuple):
    """What a vehicle-filter run replays: its start, the stops and the data.

    Attributes:
        t0: start time, ns; u0: the vehicle input row at ``t0``.
        stops, veh, fix: the schedule, vehicle rows and GNSS fixes (module docstring).
    """

    t0: int
    u0: F64
    stops: I64
    veh: F64
    fix: F64


class VehicleSettings(NamedTuple):
    """A vehicle filter's model and settings (``VehicleFilterParams``, resolved).

    Attributes:
        vp: the vehicle (``models.vehicle.VP_*``); q: model-error densities (5,).
        gate: chi-square threshold by block dimension.
        mode: ``MODE_*``: which filter the loop runs.
        max_step_s: longest model integration step, s.
        v_up_mps, v_down_mps: the switched filter's hysteresis (dynamic above ``v_up_mps``,
            kinematic again below ``v_down_mps``).
        sig_wheel_speed_mps, sig_steer_rad, sig_yaw_rate_radps: input and yaw-rate 1-sigma.
        p_stay_kinematic, p_stay_dynamic, mu0_dynamic: the IMM's Markov chain and start.
        max_pos_sigma_m: divergence limit; likelihood_floor: the IMM's least likelihood.
        timeout_s: a stream rejected this long is reset.
    """

    vp: F64
    q: F64
    gate: F64
    mode: int
    max_step_s: float
    v_up_mps: float
    v_down_mps: float
    sig_wheel_speed_mps: float
    sig_steer_rad: float
    sig_yaw_rate_radps: float
    p_stay_kinematic: float
    p_stay_dynamic: float
    mu0_dynamic: float
    max_pos_sigma_m: float
    likelihood_floor: float
    timeout_s: float


MODE_KINEMATIC, MODE_DYNAMIC, MODE_SWITCHED, MODE_IMM = 0, 1, 2, 3
MODE_NAMES = {
    "vehicle_kinematic": MODE_KINEMATIC,
    "vehicle_dynamic": MODE_DYNAMIC,
    "vehicle_switched": MODE_SWITCHED,
    "vehicle_imm": MODE_IMM,
}

VS_T, VS_VEH, VS_FIX, VS_OUT = 0, 1, 2, 3
VS_COLS = 4
VH_V, VH_D_KIN, VH_D_DYN, VH_YAW, VH_YAW_OK = 0, 1, 2, 3, 4
VH_COLS = 5
FX_N, FX_E, FX_SPEED, FX_COURSE = 0, 1, 2, 3
FX_SIG_POS, FX_SIG_SPEED, FX_SIG_COURSE, FX_POS_OK, FX_SPEED_OK, FX_COURSE_OK = 4, 5, 6, 7, 8, 9
FX_COLS = 10


S_POS, S_SPEED, S_COURSE, S_YAW = 0, 1, 2, 3
STREAM_NAMES = ("gnss_pos", "gnss_speed", "gnss_course", "yaw_rate")
M_MAX = 5


class Layout(NamedTuple):
    """A stop's measurement rows (``epoch_rows``).

    Attributes:
        rows: (M_MAX, 2), ``rows[k]`` = (``Z_*`` kind, source row: fix or vehicle sample).
        blocks: (M_MAX, 4), the gating blocks (``core.gating.gate_blocks``).
        m, nb: how many rows and blocks the stop has.
    """

    rows: I64
    blocks: I64
    m: int
    nb: int


class ModelRows(NamedTuple):
    """Each model's measurement rows of a stop (``epoch_values``), model slot first (one
    slot, or the IMM's two).

    Attributes:
        z, r: measured values and their variances (k, M_MAX) (``r`` depends on the model).
        nu: innovations (k, M_MAX); H: Jacobian rows (k, M_MAX, NX).
        S: innovation covariances (k, M_MAX, M_MAX).
    """

    z: F64
    r: F64
    nu: F64
    H: F64
    S: F64


class GateWork(NamedTuple):
    """The gating's scratch and clocks, allocated once per run.

    Attributes:
        nis, accepted: per block, its NIS and whether it passed the gate.
        acc: the accepted rows (indices into the stop's rows).
        work: ``core.gating.gate_blocks``'s scratch (3, 6).
        reject_since: per stream, when its current run of rejections began, ns (-1: none).
    """

    nis: F64
    accepted: I64
    acc: I64
    work: F64
    reject_since: I64


@njit(cache=True)
def model_rows(k: int) -> ModelRows:
    """``ModelRows`` for ``k`` models."""
    return ModelRows(np.empty((k, M_MAX)), np.empty((k, M_MAX)), np.empty((k, M_MAX)),
                     np.empty((k, M_MAX, vm.NX)), np.empty((k, M_MAX, M_MAX)))  # fmt: skip


@njit(cache=True)
def gate_work(n_streams: int) -> GateWork:
    """``GateWork`` with every stream's clock stopped."""
    return GateWork(np.empty(M_MAX), np.empty(M_MAX, np.int64), np.empty(M_MAX, np.int64),
                    np.empty((3, 6)), -np.ones(n_streams, np.int64))  # fmt: skip


@njit(cache=True, inline="always")
def epoch_rows(stop: I64, veh: F64, fix: F64, rows: I64, blocks: I64) -> Layout:
    """Lay out the measurement rows of a stop into ``rows`` and ``blocks`` (``Layout``)."""
    m = 0
    nb_ = 0
    fi = stop[VS_FIX]
    if fi >= 0:
        if fix[fi, FX_POS_OK] > 0.0:
            blocks[nb_, 0], blocks[nb_, 1], blocks[nb_, 2], blocks[nb_, 3] = m, 2, S_POS, -1
            nb_ += 1
            rows[m, 0], rows[m, 1] = vm.Z_N, fi
            rows[m + 1, 0], rows[m + 1, 1] = vm.Z_E, fi
            m += 2
        if fix[fi, FX_SPEED_OK] > 0.0:
            blocks[nb_, 0], blocks[nb_, 1], blocks[nb_, 2], blocks[nb_, 3] = m, 1, S_SPEED, -1
            nb_ += 1
            rows[m, 0], rows[m, 1] = vm.Z_SPEED, fi
            m += 1
        if fix[fi, FX_COURSE_OK] > 0.0:
            blocks[nb_, 0], blocks[nb_, 1], blocks[nb_, 2], blocks[nb_, 3] = m, 1, S_COURSE, -1
            nb_ += 1
            rows[m, 0], rows[m, 1] = vm.Z_COURSE, fi
            m += 1
    vi = stop[VS_VEH]
    if vi >= 0 and veh[vi, VH_YAW_OK] > 0.0:
        blocks[nb_, 0], blocks[nb_, 1], blocks[nb_, 2], blocks[nb_, 3] = m, 1, S_YAW, -1
        nb_ += 1
        rows[m, 0], rows[m, 1] = vm.Z_YAW_RATE, vi
        m += 1
    return Layout(rows, blocks, m, nb_)


@njit(cache=True, inline="always")
def epoch_values(
    model: int, x: F64, u: F64, lay: Layout, sched: VehicleSchedule, vs: VehicleSettings,
    ms: ModelRows, j: int,
) -> None:  # fmt: skip
    """Measured values ``z``, variances ``r``, innovations ``nu`` (course wrapped) and
    Jacobian rows ``H`` of ``model`` at its predicted state ``x``, into slot ``j`` of ``ms``;
    ``u`` is the held input.

    ``r`` depends on the model: a yaw-rate row adds the steering noise carried by the
    prediction, ``(d r / d delta)^2 sigma_delta^2`` (``vehicle.model.yaw_rate_steer_sens``;
    without it the dynamic model's yaw-rate NIS is 2-5 at 10-35 m/s on car_speed_ramp).
    """
    z, r, nu, H = ms.z[j], ms.r[j], ms.nu[j], ms.H[j]
    veh, fix, vp = sched.veh, sched.fix, vs.vp
    delta = u[VH_D_KIN] if model == vm.KINEMATIC else u[VH_D_DYN]
    for k in range(lay.m):
        kind, src = lay.rows[k, 0], lay.rows[k, 1]
        if kind == vm.Z_N:
            z[k], sig = fix[src, FX_N], fix[src, FX_SIG_POS]
        elif kind == vm.Z_E:
            z[k], sig = fix[src, FX_E], fix[src, FX_SIG_POS]
        elif kind == vm.Z_SPEED:
            z[k], sig = fix[src, FX_SPEED], fix[src, FX_SIG_SPEED]
        elif kind == vm.Z_COURSE:
            z[k], sig = fix[src, FX_COURSE], fix[src, FX_SIG_COURSE]
        else:
            z[k], sig = veh[src, VH_YAW], vs.sig_yaw_rate_radps
        r[k] = sig * sig
        if kind == vm.Z_YAW_RATE:  # the steering sample's noise enters the prediction too
            sens = vm.yaw_rate_steer_sens(model, x, delta, vp) * vs.sig_steer_rad
            r[k] += sens * sens
        nu[k] = vm.residual(kind, z[k], vm.measure(model, x, delta, kind, vp))
        vm.measure_jac(model, x, delta, kind, vp, H[k])


@njit(cache=True)
def innovation_cov(P: F64, H: F64, r: F64, m: int, S: F64) -> None:
    """``S = H P H^T + R`` into ``S[:m, :m]``."""
    Hm = np.ascontiguousarray(H[:m, :])
    S[:m, :m] = Hm @ P @ Hm.T
    for k in range(m):
        S[k, k] += r[k]


@njit(cache=True, inline="always")
def predict(
    model: int, x: F64, P: F64, u: F64, dt: float, vs: VehicleSettings, noise: vm.ProcessNoise
) -> None:
    """Propagate ``x, P`` over ``dt`` seconds with input ``u`` held (sub-steps of at most
    ``vs.max_step_s``)."""
    if dt <= 0.0:
        return
    n_sub = max(1, math.ceil(dt / vs.max_step_s - 1e-9))
    h = dt / n_sub
    delta = u[VH_D_KIN] if model == vm.KINEMATIC else u[VH_D_DYN]
    vp = vs.vp
    F = np.empty((vm.NX, vm.NX))
    Q = np.empty((vm.NX, vm.NX))
    xn = np.empty(vm.NX)
    for _ in range(n_sub):
        vm.step_jac(model, x, u[VH_V], delta, h, vp, F)
        vm.process_noise(model, x, u[VH_V], delta, h, vp, noise, Q)
        vm.step(model, x, u[VH_V], delta, h, vp, xn)
        x[:] = xn
        P[:, :] = F @ P @ F.T + Q
    symmetrize(P, vm.NX)


@njit(cache=True)
def log_likelihood(nu: F64, S: F64, acc: I64, ma: int) -> float:
    """Gaussian log-likelihood of the accepted innovations (0 when none are accepted)."""
    if ma == 0:
        return 0.0
    Sa = np.empty((ma, ma))
    y = np.empty((ma, 1))
    for i in range(ma):
        y[i, 0] = nu[acc[i]]
        for j in range(ma):
            Sa[i, j] = S[acc[i], acc[j]]
    L = np.empty((ma, ma))
    if not cholesky(Sa, ma, L):
        return -math.inf
    s = 0.0
    d = 0.0
    w = np.empty(ma)
    for i in range(ma):
        t = y[i, 0]
        for k in range(i):
            t -= L[i, k] * w[k]
        w[i] = t / L[i, i]
        s += w[i] * w[i]
        d += 2.0 * math.log(L[i, i])
    return -0.5 * (s + d + ma * math.log(2.0 * math.pi))


@njit(cache=True)
def likelihood(ll: float, floor: float) -> float:
    """``exp(ll)``, floored so that no model's probability collapses to exactly zero."""
    return max(math.exp(min(ll, 700.0)), floor)


@njit(cache=True)
def imm_mixing(mu: F64, M: F64) -> tuple[F64, F64]:
    """(cbar, omega): predicted model probabilities ``cbar = mu M`` and mixing weights
    ``omega[i, j] = M[i, j] mu[i] / cbar[j]`` (filterpy's ``_compute_mixing_probabilities``)."""
    k = mu.shape[0]
    cbar = np.zeros(k)
    for j in range(k):
        for i in range(k):
            cbar[j] += mu[i] * M[i, j]
    omega = np.empty((k, k))
    for i in range(k):
        for j in range(k):
            omega[i, j] = M[i, j] * mu[i] / cbar[j]
    return cbar, omega


@njit(cache=True)
def imm_combine(xs: F64, Ps: F64, w: F64, x: F64, P: F64) -> None:
    """Weighted mean and covariance (with the spread of the means) of the models' estimates."""
    k = w.shape[0]
    x[:] = 0.0
    for i in range(k):
        x += w[i] * xs[i]
    P[:, :] = 0.0
    for i in range(k):
        d = xs[i] - x
        P += w[i] * (np.outer(d, d) + Ps[i])


@njit(cache=True)
def reset_stream(P: F64, stream: int, nu: F64, blocks: I64, nb_: int) -> float:
    """Decorrelate and inflate the states a timed-out stream observes (bad-inputs F2).

    Position: north and east, and the heading (a heading error is what makes a model drift
    away from its fixes); speed: the speed; course: heading and sideslip. Their variance
    becomes at least the square of the stream's largest innovation. Returns that innovation.
    """
    big = 0.0
    for b in range(nb_):
        if blocks[b, 2] == stream:
            for k in range(blocks[b, 0], blocks[b, 0] + blocks[b, 1]):
                big = max(big, abs(nu[k]))
    if stream == S_POS:
        states = np.array([vm.X_N, vm.X_E, vm.X_PSI])
        sig = np.array([big, big, 0.3])
    elif stream == S_SPEED:
        states = np.array([vm.X_V])
        sig = np.array([big])
    else:
        states = np.array([vm.X_PSI, vm.X_BETA])
        sig = np.array([big, big])
    for a in range(states.size):
        i = states[a]
        for j in range(vm.NX):
            if j != i:
                P[i, j] = 0.0
                P[j, i] = 0.0
        P[i, i] = max(P[i, i], sig[a] * sig[a])
    return big


@njit(cache=True, inline="always")
def gate_with_reset(
    t: int, lay: Layout, Ps: F64, ms: ModelRows, g: int, gw: GateWork, vs: VehicleSettings,
    log: RunLog,
) -> int:  # fmt: skip
    """Gate every block on model ``g``'s innovations (``S`` of every model computed from its
    ``Ps[j]``); a stream rejected for longer than ``vs.timeout_s`` has its states' covariance
    reset in every model (``reset_stream``, event ``gate_reset``) and is gated again. Then
    the stream clocks move on, model ``g``'s innovations are recorded and the accepted rows
    are listed in ``gw.acc``.

    Returns:
        the number of accepted rows.
    """
    m, nb_, blocks = lay.m, lay.nb, lay.blocks
    nmod = Ps.shape[0]
    for j in range(nmod):
        innovation_cov(Ps[j], ms.H[j], ms.r[j], m, ms.S[j])
    for attempt in range(2):
        gate_blocks(ms.nu[g], ms.S[g], blocks, nb_, vs.gate, gw.nis, gw.accepted, gw.work)
        if attempt == 1:
            break
        reset = streams_to_reset(t, blocks, nb_, gw.accepted, gw.reject_since, vs.timeout_s, S_YAW)
        if reset.sum() == 0:
            break
        for s in range(reset.size):
            if reset[s]:
                big = 0.0
                for j in range(nmod):
                    big = reset_stream(Ps[j], s, ms.nu[j], blocks, nb_)
                record_event(log.ev_i, log.ev_f, log.counts, t, EV_RESET, s, -1, big)
        for j in range(nmod):
            innovation_cov(Ps[j], ms.H[j], ms.r[j], m, ms.S[j])
    update_reject_since(t, blocks, nb_, gw.accepted, gw.reject_since)
    gated = GatedBlocks(ms.nu[g], ms.S[g], blocks, nb_, gw.nis, gw.accepted)
    record_innovations(t, gated, vs.gate, log.inn_i, log.inn_f, log.counts, log.ev_i, log.ev_f)
    return accepted_rows(blocks, nb_, gw.accepted, gw.acc)


@njit(cache=True)
def check(x: F64, P: F64, vs: VehicleSettings) -> int:
    """The NaN barrier and the divergence limit for a vehicle state."""
    for i in range(vm.NX):
        if not math.isfinite(x[i]):
            return STATUS_NONFINITE
        for j in range(vm.NX):
            if not math.isfinite(P[i, j]):
                return STATUS_NONFINITE
    if math.sqrt(P[vm.X_N, vm.X_N] + P[vm.X_E, vm.X_E]) > vs.max_pos_sigma_m:
        return STATUS_LIMIT
    return STATUS_OK


@njit(cache=True)
def switch_model(current: int, v_whl: float, vs: VehicleSettings) -> int:
    """Speed-based model choice with hysteresis (``v_up_mps`` > ``v_down_mps``)."""
    if current == vm.KINEMATIC and v_whl > vs.v_up_mps:
        return vm.DYNAMIC
    if current == vm.DYNAMIC and v_whl < vs.v_down_mps:
        return vm.KINEMATIC
    return current


@njit(cache=True)
def run_vehicle(
    x0: F64, P0: F64, sched: VehicleSchedule, vs: VehicleSettings, log: RunLog, out_aux: F64
) -> int:
    """Replay a vehicle-model filter from ``x0, P0`` at ``sched.t0`` over every stop.

    One model slot (``xs[0]``, ``Ps[0]``: the estimate itself) or the IMM's two (combined
    into ``x``, ``P``); every slot is predicted, updated with the same accepted rows and
    kept positive definite.

    Args:
        x0: initial state (5,); P0: its covariance (5, 5).
        sched: start, schedule and data; vs: the model and settings.
        log: outputs at flagged stops (and t0), innovations and events (``records.RunLog``).
        out_aux: out, per output row, the probability of the dynamic model (IMM) or the model
            in use (1 = dynamic).

    Returns:
        a ``common.STATUS_*`` code.
    """
    t0, u0, stops, veh, fix = sched
    ev_i, ev_f, counts = log.ev_i, log.ev_f, log.counts
    mode = vs.mode
    imm = mode == MODE_IMM
    noise = vm.ProcessNoise(np.array([vs.sig_wheel_speed_mps, vs.sig_steer_rad]), vs.q)
    nmod = 2 if imm else 1
    xs = np.empty((nmod, vm.NX))
    Ps = np.empty((nmod, vm.NX, vm.NX))
    for i in range(nmod):
        xs[i] = x0
        Ps[i] = P0
    pk, pd = vs.p_stay_kinematic, vs.p_stay_dynamic
    M = np.array([[pk, 1.0 - pk], [1.0 - pd, pd]])
    mu = np.array([1.0 - vs.mu0_dynamic, vs.mu0_dynamic])
    cbar, omega = imm_mixing(mu, M)
    model = vm.DYNAMIC if mode == MODE_DYNAMIC else vm.KINEMATIC
    if mode == MODE_SWITCHED:
        model = switch_model(vm.KINEMATIC, u0[VH_V], vs)
    u = u0.copy()
    if imm:
        x, P = x0.copy(), P0.copy()
    else:
        x, P = xs[0], Ps[0]
    L = np.empty((vm.NX, vm.NX))
    rows = np.empty((M_MAX, 2), np.int64)
    blocks = np.empty((M_MAX, 4), np.int64)
    ms = model_rows(nmod)
    gw = gate_work(4)
    lik = np.ones(2)
    aux = mu[1] if imm else float(model)
    _record(t0, x, P, aux, log, out_aux)
    t_cur = t0
    for k in range(stops.shape[0]):
        t = stops[k, VS_T]
        dt = (t - t_cur) * 1e-9
        t_cur = t
        if imm:
            xm = np.zeros((2, vm.NX))
            Pm = np.zeros((2, vm.NX, vm.NX))
            for j in range(2):
                imm_combine(xs, Ps, omega[:, j], xm[j], Pm[j])
            for j in range(2):
                xs[j] = xm[j]
                Ps[j] = Pm[j]
        for j in range(nmod):
            predict(j if imm else model, xs[j], Ps[j], u, dt, vs, noise)
        vi = stops[k, VS_VEH]
        if vi >= 0:
            u[:] = veh[vi]
        if mode == MODE_SWITCHED and vi >= 0:
            model = switch_model(model, u[VH_V], vs)
        lay = epoch_rows(stops[k], veh, fix, rows, blocks)
        lik[0], lik[1] = 1.0, 1.0
        if lay.m > 0:
            for j in range(nmod):
                epoch_values(j if imm else model, xs[j], u, lay, sched, vs, ms, j)
            g = 0 if not imm or cbar[0] >= cbar[1] else 1
            ma = gate_with_reset(t, lay, Ps, ms, g, gw, vs, log)
            for j in range(nmod):
                if ma > 0:
                    if imm:
                        ll = log_likelihood(ms.nu[j], ms.S[j], gw.acc, ma)
                        lik[j] = likelihood(ll, vs.likelihood_floor)
                    dx, ok = joseph_update(Ps[j], vm.NX, ms.H[j], ms.S[j], ms.r[j], ms.nu[j],
                                           gw.acc, ma)  # fmt: skip
                    if ok:
                        xs[j] += dx
        if imm:
            for j in range(2):
                mu[j] = cbar[j] * lik[j]
            mu /= mu.sum()
            cbar, omega = imm_mixing(mu, M)
            imm_combine(xs, Ps, mu, x, P)
            aux = mu[1]
        else:
            aux = float(model)
        ok_all = True
        for j in range(nmod):
            ok_all = ok_all and keep_pd(Ps[j], vm.NX, L, t, ev_i, ev_f, counts)
        status = check(x, P, vs) if ok_all else STATUS_INDEFINITE
        if status != STATUS_OK:
            return fail(t, status, ev_i, ev_f, counts)
        if stops[k, VS_OUT] > 0:
            _record(t, x, P, aux, log, out_aux)
        counts[CNT_STOP] = k + 1
    return STATUS_OK


@njit(cache=True)
def _record(t: int, x: F64, P: F64, aux: float, log: RunLog, out_aux: F64) -> None:
    """Append an output row (counted, not written, past the capacity)."""
    k = log.counts[CNT_OUT]
    if k < log.out_t.shape[0]:
        log.out_t[k] = t
        log.out_x[k] = x
        log.out_P[k] = P
        out_aux[k] = aux
    log.counts[CNT_OUT] = k + 1
