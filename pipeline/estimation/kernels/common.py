"""Numerics and bookkeeping shared by both estimators and both backends (numba).

Everything here is a plain function over arrays, so the compiled replay loops
(``kernels.ekf``, ``kernels.ukf``) and the filterpy reference backend call the *same* gating,
timeout-reset, positive-definiteness, recording and NaN-barrier code: the backends differ only
in who performs the Kalman predict and update arithmetic.

The INS kernels' settings and run log are records (``kernels.records``); events and
innovations go into preallocated arrays, with the counters in ``counts`` (``CNT_*``): a row
past the capacity is counted, not written, and the driver re-runs with a larger log.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from navreplay.pipeline._jit import njit
from navreplay.pipeline.estimation.kernels.records import CNT_DIM as CNT_DIM
from navreplay.pipeline.estimation.kernels.records import CNT_EV as CNT_EV
from navreplay.pipeline.estimation.kernels.records import CNT_INN as CNT_INN
from navreplay.pipeline.estimation.kernels.records import CNT_OUT as CNT_OUT
from navreplay.pipeline.estimation.kernels.records import CNT_STOP as CNT_STOP
from navreplay.pipeline.estimation.kernels.records import CNT_T_FAIL as CNT_T_FAIL
from navreplay.pipeline.estimation.kernels.records import INN_F_COLS as INN_F_COLS
from navreplay.pipeline.estimation.kernels.records import INN_I_COLS as INN_I_COLS
from navreplay.pipeline.estimation.kernels.records import (
    EpochBuffers,
    GatedBlocks,
    RunLog,
    Settings,
)
from navreplay.pipeline.estimation.models.ins import E_CB, E_POS, E_VEL, N_LOOSE, X_VEL
from navreplay.pipeline.estimation.models.measurement import S_NHC, S_OBS, S_VEL
from navreplay.pipeline.nav.earth import F64, I64

EV_REJECT, EV_RESET, EV_REPAIR, EV_DIVERGED = 1, 2, 3, 4
EVENT_NAMES = {EV_REJECT: "gate_reject", EV_RESET: "gate_reset", EV_REPAIR: "cov_repair"}
EVENT_NAMES[EV_DIVERGED] = "divergence"

STATUS_OK, STATUS_NONFINITE, STATUS_LIMIT, STATUS_INDEFINITE = 0, 1, 2, 3
STATUS_TEXT = {
    STATUS_OK: "ok",
    STATUS_NONFINITE: "non-finite state or covariance",
    STATUS_LIMIT: "state or covariance beyond the divergence limits",
    STATUS_INDEFINITE: "covariance indefinite after repair",
}

N_STREAMS = 4

# Explicit signatures for the helpers called from many places: a call from jitted code
# otherwise compiles a new specialization for every array layout it sees. numba compiles them
# when this module is imported (or loads them from its cache).
_F2 = nb.float64[:, :]
_F2C = nb.float64[:, ::1]
_F1C = nb.float64[::1]
_I2C = nb.int64[:, ::1]
_I1C = nb.int64[::1]


@njit(nb.boolean(_F2, nb.int64, _F2), cache=True, error_model="numpy")
def cholesky(A: F64, n: int, L: F64) -> bool:
    """Lower Cholesky factor of ``A[:n, :n]`` into ``L``; False if not positive definite."""
    for j in range(n):
        s = A[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not s > 0.0 or not math.isfinite(s):
            return False
        d = math.sqrt(s)
        L[j, j] = d
        for i in range(j + 1, n):
            s = A[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s / d
        for i in range(j):
            L[i, j] = 0.0
    return True


@njit(nb.void(_F2, nb.int64, _F2, nb.int64), cache=True, error_model="numpy")
def cho_solve(L: F64, n: int, B: F64, k: int) -> None:
    """Solve ``(L L^T) X = B[:n, :k]`` in place (``L`` from ``cholesky``)."""
    for c in range(k):
        for i in range(n):
            s = B[i, c]
            for j in range(i):
                s -= L[i, j] * B[j, c]
            B[i, c] = s / L[i, i]
        for i in range(n - 1, -1, -1):
            s = B[i, c]
            for j in range(i + 1, n):
                s -= L[j, i] * B[j, c]
            B[i, c] = s / L[i, i]


@njit(cache=True, error_model="numpy")
def epoch_buffers(m_max: int, n: int) -> EpochBuffers:
    """The measurement scratch for epochs of up to ``m_max`` rows and ``n`` error states."""
    return EpochBuffers(
        np.empty((m_max, 2), np.int64),
        np.empty((m_max, 4), np.int64),
        np.empty(m_max),
        np.empty(m_max),
        np.empty(m_max),
        np.empty((m_max, n)),
        np.empty((m_max, m_max)),
        np.empty(m_max, np.int64),
        -np.ones(N_STREAMS, np.int64),
    )


@njit(cache=True, error_model="numpy")
def symmetrize(P: F64, n: int) -> None:
    """P <- (P + P^T) / 2 on ``P[:n, :n]``."""
    for i in range(n):
        for j in range(i + 1, n):
            a = 0.5 * (P[i, j] + P[j, i])
            P[i, j] = a
            P[j, i] = a


@njit(cache=True, error_model="numpy")
def ensure_pd(P: F64, n: int, L: F64) -> tuple[bool, bool, float]:
    """Keep ``P[:n, :n]`` symmetric positive definite; ``L`` receives its Cholesky factor.

    A ``P`` that fails the Cholesky test is repaired by adding a diagonal jitter, starting at
    1e-12 of its largest variance (at least 1e-30) and growing tenfold until the factorization
    succeeds (the minimal-change repair; no eigendecomposition is needed).

    Returns:
        (ok, repaired, total jitter added to each variance): ``ok`` is False when no repair is
        possible (non-finite entries); the caller logs a repair event.
    """
    symmetrize(P, n)
    if cholesky(P, n, L):
        return True, False, 0.0
    big = 0.0
    for i in range(n):
        for j in range(n):
            if not math.isfinite(P[i, j]):
                return False, False, math.nan
        big = max(big, abs(P[i, i]))
    step = max(1e-12 * big, 1e-30)
    total = 0.0
    for _ in range(60):
        for i in range(n):
            P[i, i] += step
        total += step
        if cholesky(P, n, L):
            return True, True, total
        step *= 10.0
    return False, True, total


@njit(cache=True, error_model="numpy")
def mat_mul_into(A: F64, B: F64, rows: int, inner: int, cols: int, out: F64) -> None:
    """``out[:rows, :cols] = A[:rows, :inner] B[:inner, :cols]``, each entry summed in the
    order of ``inner``."""
    for i in range(rows):
        for j in range(cols):
            a = 0.0
            for k in range(inner):
                a += A[i, k] * B[k, j]
            out[i, j] = a


@njit(cache=True, error_model="numpy")
def propagate_cov(P: F64, Phi: F64, Qd: F64, n: int, tmp: F64) -> None:
    """``P <- Phi P Phi^T + Qd`` in place (``tmp``: scratch (n, n))."""
    mat_mul_into(Phi, P, n, n, n, tmp)
    for r in range(n):
        for c in range(r, n):
            a = Qd[r, c]
            for k in range(n):
                a += tmp[r, k] * Phi[c, k]
            P[r, c] = a
            P[c, r] = a


@njit(cache=True, error_model="numpy")
def innovation_cov(H: F64, P: F64, r: F64, m: int, n: int, PHt: F64, S: F64) -> None:
    """``PHt = P H^T`` (n, m) and ``S = H P H^T + diag(r)`` (m, m) for the first ``m`` rows."""
    mat_mul_into(P, H.T, n, n, m, PHt)
    for k in range(m):
        for q in range(k, m):
            a = 0.0
            for j in range(n):
                a += H[k, j] * PHt[j, q]
            S[k, q] = a
            S[q, k] = a
        S[k, k] += r[k]


@njit(cache=True, error_model="numpy")
def keep_pd(P: F64, n: int, L: F64, t_ns: int, ev_i: I64, ev_f: F64, counts: I64) -> bool:
    """``ensure_pd`` with a ``cov_repair`` event (value: the jitter added) when a repair was
    needed; False if impossible."""
    ok, repaired, lam = ensure_pd(P, n, L)
    if repaired:
        record_event(ev_i, ev_f, counts, t_ns, EV_REPAIR, -1, -1, lam)
    return ok


@njit(cache=True, error_model="numpy")
def accepted_rows(blocks: I64, nb_: int, accepted: I64, out: I64) -> int:
    """Row indices of the accepted blocks into ``out``; returns their number."""
    ma = 0
    for b in range(nb_):
        if accepted[b]:
            for k in range(blocks[b, 0], blocks[b, 0] + blocks[b, 1]):
                out[ma] = k
                ma += 1
    return ma


@njit(cache=True, error_model="numpy")
def fail(t_ns: int, status: int, ev_i: I64, ev_f: F64, counts: I64) -> int:
    """Record a divergence (event and time) and return its status code."""
    record_event(ev_i, ev_f, counts, t_ns, EV_DIVERGED, -1, -1, float(status))
    counts[CNT_T_FAIL] = t_ns
    return status


@njit(cache=True, error_model="numpy")
def gate_blocks(
    nu: F64, S: F64, blocks: I64, nb_: int, gate: F64, nis: F64, accepted: I64, work: F64
) -> None:
    """Chi-square gate each block on its NIS ``nu_b^T S_bb^-1 nu_b`` (prior ``S``).

    Args:
        nu: innovations (m,).
        S: innovation covariance of all rows (m, m), prior: ``H P H^T + R`` or its unscented
            equivalent.
        blocks: block table (see ``models.measurement``).
        gate: chi-square threshold by dimension, ``gate[d]``.
        nis: out, NIS per block (nb,).
        accepted: out, 1 if the block passes (nb,).
        work: scratch, (3, 6).
    """
    for b in range(nb_):
        r0, d = blocks[b, 0], blocks[b, 1]
        Sb = work[:d, :d]
        Lb = work[:d, 3 : 3 + d]
        for i in range(d):
            for j in range(d):
                Sb[i, j] = S[r0 + i, r0 + j]
        if not cholesky(Sb, d, Lb):
            nis[b] = math.inf
            accepted[b] = 0
            continue
        y = np.empty((d, 1))
        for i in range(d):
            y[i, 0] = nu[r0 + i]
        cho_solve(Lb, d, y, 1)
        e = 0.0
        for i in range(d):
            e += nu[r0 + i] * y[i, 0]
        nis[b] = e
        accepted[b] = 1 if e <= gate[d] else 0


@njit(cache=True, error_model="numpy")
def gating_cov(S: F64, dr: F64, m: int) -> F64:
    """``S + diag(dr)`` over the first ``m`` rows: the covariance the innovations are gated
    against, and their NIS and logged sigmas computed from, where a row's update variance
    differs from its marginal one (``measurement.gate_shift``). ``S`` is left for the update."""
    Sg = S[:m, :m].copy()
    for k in range(m):
        Sg[k, k] += dr[k]
    return Sg


@njit(cache=True, error_model="numpy")
def stream_health(blocks: I64, nb_: int, accepted: I64) -> tuple[I64, I64]:
    """Per stream: (seen this epoch, accepted this epoch) flags, each (N_STREAMS,).

    A stream is accepted when at least half of its blocks pass their gates. One block per
    stream (loose coupling) is accepted or not; for pseudoranges (one block per satellite) a
    consistent position step (F2) is rejected on most satellites, while the few whose line of
    sight is nearly perpendicular to it still pass: those must not keep the stream from its
    timeout reset, or the filter creeps towards the new position for minutes.
    """
    n_seen = np.zeros(N_STREAMS, np.int64)
    n_ok = np.zeros(N_STREAMS, np.int64)
    for b in range(nb_):
        s = blocks[b, 2]
        n_seen[s] += 1
        if accepted[b]:
            n_ok[s] += 1
    seen = np.zeros(N_STREAMS, np.int64)
    ok = np.zeros(N_STREAMS, np.int64)
    for s in range(N_STREAMS):
        if n_seen[s] > 0:
            seen[s] = 1
            ok[s] = 1 if 2 * n_ok[s] >= n_seen[s] else 0
    return seen, ok


@njit(cache=True, error_model="numpy")
def streams_to_reset(
    t_ns: int, blocks: I64, nb_: int, accepted: I64, reject_since: I64, timeout_s: float, keep: int
) -> I64:
    """Streams that have been rejected (``stream_health``) for the timeout or longer (F2).

    ``reject_since[stream]`` holds the time (ns) of the first rejection of the current run of
    rejections, -1 if the stream was last accepted. Stream ``keep`` is never reset (the INS
    filters' NHC pseudo-measurement, the vehicle filters' yaw rate; -1: none).

    Returns:
        (N_STREAMS,) flags, 1 = reset that stream's states now.
    """
    seen, ok = stream_health(blocks, nb_, accepted)
    out = np.zeros(N_STREAMS, np.int64)
    for s in range(N_STREAMS):
        if s == keep or not seen[s] or ok[s] or reject_since[s] < 0:
            continue
        if (t_ns - reject_since[s]) * 1e-9 >= timeout_s:
            out[s] = 1
    return out


@njit(cache=True, error_model="numpy")
def update_reject_since(t_ns: int, blocks: I64, nb_: int, accepted: I64, reject_since: I64) -> None:
    """Advance the per-stream rejection clocks after an epoch's final gating decisions."""
    seen, ok = stream_health(blocks, nb_, accepted)
    for s in range(N_STREAMS):
        if not seen[s]:
            continue
        if ok[s]:
            reject_since[s] = -1
        elif reject_since[s] < 0:
            reject_since[s] = t_ns


@njit(cache=True, error_model="numpy")
def inflate_for_stream(
    P: F64, stream: int, nu: F64, blocks: I64, nb_: int, scale: F64, s: Settings
) -> float:
    """Reset the covariance of the states a timed-out stream observes; returns the largest
    innovation magnitude of that stream (logged with the reset event).

    Position (and clock bias for pseudoranges) or velocity rows and columns are decorrelated
    and their variance set to at least the configured reset sigma and the largest innovation
    of the stream, so the next update accepts the measurement. ``scale`` converts error
    coordinates to the filter's coordinates (ones for the EKF, ``coords_scale`` for the UKF).
    """
    big = 0.0
    for b in range(nb_):
        if blocks[b, 2] != stream:
            continue
        for r in range(blocks[b, 0], blocks[b, 0] + blocks[b, 1]):
            big = max(big, abs(nu[r]))
    n = s.n
    if stream == S_VEL:
        first, count, sig = E_VEL, 3, max(s.reset_vel_sigma_mps, big)
    else:
        first, count, sig = E_POS, 3, max(s.reset_pos_sigma_m, big)
    _reset_block(P, n, first, count, sig, scale)
    if stream == S_OBS and n > N_LOOSE:
        _reset_block(P, n, E_CB, 1, max(s.reset_clock_sigma_m, big), scale)
    return big


@njit(
    nb.void(_F2C, nb.int64, nb.int64, nb.int64, nb.float64, _F1C), cache=True, error_model="numpy"
)
def _reset_block(P: F64, n: int, first: int, count: int, sigma: float, scale: F64) -> None:
    for i in range(first, first + count):
        for j in range(n):
            if j != i:
                P[i, j] = 0.0
                P[j, i] = 0.0
        P[i, i] = max(P[i, i], (sigma * scale[i]) ** 2)


@njit(
    nb.void(_I2C, _F1C, _I1C, nb.int64, nb.int64, nb.int64, nb.int64, nb.float64),
    cache=True,
    error_model="numpy",
)
def record_event(
    ev_i: I64, ev_f: F64, counts: I64, t_ns: int, kind: int, stream: int, sv: int, value: float
) -> None:
    """Append an event (past the preallocated capacity it is counted, not written)."""
    k = counts[CNT_EV]
    if k < ev_i.shape[0]:
        ev_i[k, 0], ev_i[k, 1], ev_i[k, 2], ev_i[k, 3] = t_ns, kind, stream, sv
        ev_f[k] = value
    counts[CNT_EV] = k + 1


@njit(cache=True, error_model="numpy")
def record_innovations(
    t_ns: int,
    g: GatedBlocks,
    gate: F64,
    inn_i: I64,
    inn_f: F64,
    counts: I64,
    ev_i: I64,
    ev_f: F64,
) -> None:
    """Append one innovation row per block of ``g`` (with its threshold ``gate[d]``), and a
    ``gate_reject`` event per rejected block (rows past the capacity are counted, not
    written)."""
    nu, S, blocks, nis, accepted = g.nu, g.S, g.blocks, g.nis, g.accepted
    for b in range(g.nb):
        k = counts[CNT_INN]
        counts[CNT_INN] = k + 1
        if not accepted[b]:
            record_event(ev_i, ev_f, counts, t_ns, EV_REJECT, blocks[b, 2], blocks[b, 3], nis[b])
        if k >= inn_i.shape[0]:
            continue
        r0, d = blocks[b, 0], blocks[b, 1]
        inn_i[k, 0], inn_i[k, 1], inn_i[k, 2] = t_ns, blocks[b, 2], blocks[b, 3]
        inn_i[k, 3], inn_i[k, 4] = d, accepted[b]
        inn_f[k, 0], inn_f[k, 1] = nis[b], gate[d]
        for j in range(3):
            inn_f[k, 2 + j] = nu[r0 + j] if j < d else math.nan
            inn_f[k, 5 + j] = math.sqrt(S[r0 + j, r0 + j]) if j < d else math.nan


@njit(cache=True, error_model="numpy")
def check_state(X: F64, P: F64, scale: F64, s: Settings) -> int:
    """The NaN barrier and divergence limits; returns a ``STATUS_*`` code."""
    for j in range(X.shape[0]):
        if not math.isfinite(X[j]):
            return STATUS_NONFINITE
    for i in range(s.n):
        if not math.isfinite(P[i, i]) or not P[i, i] > 0.0:
            return STATUS_NONFINITE
    v = X[X_VEL : X_VEL + 3]
    if math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]) > s.max_speed_mps:
        return STATUS_LIMIT
    var_h = P[0, 0] / scale[0] ** 2 + P[1, 1] / scale[1] ** 2
    if math.sqrt(var_h) > s.max_pos_sigma_m:
        return STATUS_LIMIT
    return STATUS_OK


@njit(cache=True, error_model="numpy")
def record_output(t_ns: int, X: F64, P_err: F64, log: RunLog) -> None:
    """Append an output row: full state and its error-coordinate covariance."""
    k = log.counts[CNT_OUT]
    if k < log.out_t.shape[0]:
        log.out_t[k] = t_ns
        for j in range(X.shape[0]):
            log.out_x[k, j] = X[j]
        n = log.out_P.shape[1]
        for r in range(n):
            for c in range(n):
                log.out_P[k, r, c] = P_err[r, c]
    log.counts[CNT_OUT] = k + 1


@njit(cache=True, error_model="numpy")
def reset_timed_out(
    t_ns: int, P: F64, g: GatedBlocks, reject_since: I64, scale: F64, cfg: Settings, log: RunLog
) -> bool:
    """Reset the covariance of every stream rejected for the timeout or longer
    (``streams_to_reset``, ``inflate_for_stream`` with ``scale``), each with a ``gate_reset``
    event; True if any was."""
    reset = streams_to_reset(t_ns, g.blocks, g.nb, g.accepted, reject_since, cfg.timeout_s, S_NHC)
    for st in range(N_STREAMS):
        if reset[st]:
            big = inflate_for_stream(P, st, g.nu, g.blocks, g.nb, scale, cfg)
            record_event(log.ev_i, log.ev_f, log.counts, t_ns, EV_RESET, st, -1, big)
    return bool(reset.sum() > 0)


@njit(cache=True, error_model="numpy")
def close_gating(t_ns: int, g: GatedBlocks, gate: F64, buf: EpochBuffers, log: RunLog) -> int:
    """An INS epoch's final gating decisions: record the innovations and rejections, advance
    the rejection clocks (``buf.reject_since``) and write the accepted rows into
    ``buf.acc_rows``; returns their number."""
    record_innovations(t_ns, g, gate, log.inn_i, log.inn_f, log.counts, log.ev_i, log.ev_f)
    update_reject_since(t_ns, g.blocks, g.nb, g.accepted, buf.reject_since)
    return accepted_rows(g.blocks, g.nb, g.accepted, buf.acc_rows)
