"""Gating, stream clocks, status codes and run-log recording shared by every family's compiled
filters and their filterpy backends (numba).

A measurement epoch is a table of blocks (rows, dimension, stream, satellite); each block is
gated on its NIS, a stream rejected for the timeout is reset (``streams_to_reset``), and the
innovations, events and estimates go into the run log (``core.runlog``).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from navreplay.pipeline._jit import njit
from navreplay.pipeline.estimation.core.linalg import (
    _F1C,
    _I1C,
    _I2C,
    cho_solve,
    cholesky,
    ensure_pd,
)
from navreplay.pipeline.estimation.core.runlog import (
    CNT_EV,
    CNT_INN,
    CNT_OUT,
    CNT_T_FAIL,
    GatedBlocks,
    RunLog,
)
from navreplay.pipeline.nav.earth import F64, I64

EV_REJECT, EV_RESET, EV_REPAIR, EV_DIVERGED = 1, 2, 3, 4


EVENT_NAMES = {
    EV_REJECT: "gate_reject",
    EV_RESET: "gate_reset",
    EV_REPAIR: "cov_repair",
    EV_DIVERGED: "divergence",
}


STATUS_OK, STATUS_NONFINITE, STATUS_LIMIT, STATUS_INDEFINITE = 0, 1, 2, 3


STATUS_TEXT = {
    STATUS_OK: "ok",
    STATUS_NONFINITE: "non-finite state or covariance",
    STATUS_LIMIT: "state or covariance beyond the divergence limits",
    STATUS_INDEFINITE: "covariance indefinite after repair",
}


N_STREAMS = 5


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
    rejections, -1 if the stream was last accepted. Streams ``keep`` and after are never reset
    (the INS filters' NHC and standstill pseudo-measurements, the vehicle filters' yaw rate:
    resetting the states they hold would let a wrong constraint in; -1: none).

    Returns:
        (N_STREAMS,) flags, 1 = reset that stream's states now.
    """
    seen, ok = stream_health(blocks, nb_, accepted)
    out = np.zeros(N_STREAMS, np.int64)
    for s in range(N_STREAMS):
        if 0 <= keep <= s or not seen[s] or ok[s] or reject_since[s] < 0:
            continue
        if (t_ns - reject_since[s]) * 1e-9 >= timeout_s:
            out[s] = 1
    return out


@njit(cache=True, error_model="numpy")
def new_stream_clock(t0_ns: int) -> I64:
    """Per stream (4, N_STREAMS): last seen (ns; the run's start ``t0_ns`` at first), its
    consecutive rejected epochs, whether that run of rejections began soon after a gap
    (``returning_to_reset``), and when the stream last came back from a gap (ns, -1: never).

    A run restarted from a checkpoint (the outage Monte Carlo) thus sees the same gaps as the
    full replay: every outage window starts after the checkpoint and outlasts ``gap_s``.
    """
    clock = np.zeros((4, N_STREAMS), np.int64)
    clock[0, :] = t0_ns
    clock[3, :] = -1
    return clock


@njit(cache=True, error_model="numpy")
def _back_from_gap(t_ns: int, clock: I64, s: int, gap_s: float, window_s: float) -> bool:
    """Stream ``s`` seen at ``t_ns`` is back from a gap of ``gap_s`` (counted from the run's
    start before its first measurement), or came back less than ``window_s`` ago."""
    if (t_ns - clock[0, s]) * 1e-9 >= gap_s:
        return True
    return bool(clock[3, s] >= 0 and (t_ns - clock[3, s]) * 1e-9 <= window_s)


@njit(cache=True, error_model="numpy")
def returning_to_reset(
    t_ns: int, blocks: I64, nb_: int, accepted: I64, clock: I64, gap_s: float, epochs: int,
    window_s: float, keep: int,
) -> I64:  # fmt: skip
    """Streams back from a gap of ``gap_s`` or longer (``new_stream_clock``) whose run
    of rejections began within ``window_s`` of their return and has lasted ``epochs`` epochs,
    this one included: after an outage the filter has drifted, not the returning
    measurements, so waiting out the timeout only lets its error grow (bad-inputs F4). Single
    outliers (F1, F7) away from an outage keep the timeout. Streams ``keep`` and after are
    never reset.

    Returns:
        (N_STREAMS,) flags, 1 = reset that stream's states now.
    """
    seen, ok = stream_health(blocks, nb_, accepted)
    out = np.zeros(N_STREAMS, np.int64)
    for s in range(N_STREAMS):
        if 0 <= keep <= s or not seen[s] or ok[s]:
            continue
        if clock[1, s] == 0:  # a new run: does it begin soon after a gap?
            returning = _back_from_gap(t_ns, clock, s, gap_s, window_s)
        else:
            returning = clock[2, s] == 1
        if returning and clock[1, s] + 1 >= epochs:
            out[s] = 1
    return out


@njit(cache=True, error_model="numpy")
def update_stream_clock(
    t_ns: int, blocks: I64, nb_: int, accepted: I64, clock: I64, gap_s: float, window_s: float
) -> None:
    """Advance ``clock`` (``new_stream_clock``) after an epoch's final gating decisions."""
    seen, ok = stream_health(blocks, nb_, accepted)
    for s in range(N_STREAMS):
        if not seen[s]:
            continue
        if (t_ns - clock[0, s]) * 1e-9 >= gap_s:
            clock[3, s] = t_ns
        if ok[s]:
            clock[1, s] = 0
            clock[2, s] = 0
        else:
            if clock[1, s] == 0:
                clock[2, s] = 1 if _back_from_gap(t_ns, clock, s, gap_s, window_s) else 0
            clock[1, s] += 1
        clock[0, s] = t_ns


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
