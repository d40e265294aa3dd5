"""What the INS kernels share beyond the core (``estimation.core``): epoch buffers, the
covariance reset of a timed-out stream (which states each INS stream observes), the state
checks, and the close of an epoch's gating, for both estimators and both backends (numba).

The compiled replay loops (``kernels.ekf``, ``kernels.ukf``, ``kernels.fwekf``) and the
filterpy reference backend call the *same* code here and in ``core.gating``: the backends
differ only in who performs the Kalman predict and update arithmetic.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from navreplay.pipeline._jit import njit
from navreplay.pipeline.estimation.core.gating import (
    EV_RESET,
    N_STREAMS,
    STATUS_LIMIT,
    STATUS_NONFINITE,
    STATUS_OK,
    accepted_rows,
    new_stream_clock,
    record_event,
    record_innovations,
    returning_to_reset,
    streams_to_reset,
    update_reject_since,
    update_stream_clock,
)
from navreplay.pipeline.estimation.core.linalg import (
    _F1C,
    _F2C,
)
from navreplay.pipeline.estimation.core.runlog import (
    GatedBlocks,
    RunLog,
)
from navreplay.pipeline.estimation.ins.kernels.records import EpochBuffers, Settings
from navreplay.pipeline.estimation.ins.models.ins import E_CB, E_POS, E_VEL, N_LOOSE, X_VEL
from navreplay.pipeline.estimation.ins.models.measurement import (
    S_NHC,
    S_OBS,
    S_VEL,
    ST_STILL,
    STILL_RATE,
    STILL_SIG_RATE,
    STILL_SIG_VEL,
)
from navreplay.pipeline.nav.earth import F64, I64


@njit(cache=True, error_model="numpy")
def epoch_buffers(m_max: int, n: int, t0_ns: int) -> EpochBuffers:
    """The measurement scratch for epochs of up to ``m_max`` rows and ``n`` error states, of
    a run starting at ``t0_ns``."""
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
        new_stream_clock(t0_ns),
    )


@njit(cache=True, error_model="numpy")
def rest_plausible(stop: I64, v: F64, P: F64, s: Settings) -> bool:
    """The standstill updates apply at ``stop``: it is flagged at rest (``ST_STILL``) and the
    filter's speed ``|v|`` (velocity error-state variances in ``P``) is within
    ``max_speed + 3 sigma`` of zero (``still_sigma[2]``)."""
    if not s.still_on or stop[ST_STILL] <= 0:
        return False
    speed2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2]
    var = P[E_VEL, E_VEL] + P[E_VEL + 1, E_VEL + 1] + P[E_VEL + 2, E_VEL + 2]
    lim = s.still_sigma[2] + 3.0 * math.sqrt(max(var, 0.0))
    return bool(speed2 <= lim * lim)


@njit(cache=True, error_model="numpy")
def fill_still(
    still: F64, imu: F64, i0: int, i1: int, w_now: F64, span_s: float, s: Settings
) -> None:
    """The standstill rows' values of the epoch ending a span (``measurement.STILL_COLS``):
    the ZUPT sigma, the mean angular rate of the IMU samples ``i0:i1`` of the span (``w_now``
    if it holds none) and its sigma, the gyro white noise averaged over the span
    (``sqrt(psd / span_s)``) with the configured floor (vibration, quantization)."""
    for a in range(3):
        still[STILL_RATE + a] = 0.0
    if i1 > i0:
        for i in range(i0, i1):
            for a in range(3):
                still[STILL_RATE + a] += imu[i, 3 + a]
        for a in range(3):
            still[STILL_RATE + a] /= i1 - i0
    else:
        for a in range(3):
            still[STILL_RATE + a] = w_now[a]
    still[STILL_SIG_VEL] = s.still_sigma[0]
    floor = s.still_sigma[1]
    still[STILL_SIG_RATE] = math.sqrt(s.noise[1] / max(span_s, 1e-3) + floor * floor)


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


@njit(cache=True, error_model="numpy", inline="always")
def reset_timed_out(
    t_ns: int, P: F64, g: GatedBlocks, buf: EpochBuffers, scale: F64, cfg: Settings, log: RunLog
) -> bool:
    """Reset the covariance of every stream rejected for the timeout or longer
    (``streams_to_reset``), or back from an outage and rejected at ``cfg.return_epochs``
    epochs in a row (``returning_to_reset``), with ``inflate_for_stream`` and ``scale``, each
    with a ``gate_reset`` event; True if any was."""
    reset = streams_to_reset(
        t_ns, g.blocks, g.nb, g.accepted, buf.reject_since, cfg.timeout_s, S_NHC
    )
    back = returning_to_reset(
        t_ns, g.blocks, g.nb, g.accepted, buf.stream_clock, cfg.return_gap_s, cfg.return_epochs,
        cfg.timeout_s, S_NHC,
    )  # fmt: skip
    for st in range(N_STREAMS):
        if back[st]:
            buf.stream_clock[2, st] = 0  # once: a run rejected after its reset keeps the timeout
        if reset[st] or back[st]:
            big = inflate_for_stream(P, st, g.nu, g.blocks, g.nb, scale, cfg)
            record_event(log.ev_i, log.ev_f, log.counts, t_ns, EV_RESET, st, -1, big)
    return bool(reset.sum() + back.sum() > 0)


@njit(cache=True, error_model="numpy", inline="always")
def close_gating(t_ns: int, g: GatedBlocks, cfg: Settings, buf: EpochBuffers, log: RunLog) -> int:
    """An INS epoch's final gating decisions: record the innovations and rejections, advance
    the rejection clocks (``buf.reject_since``, ``buf.stream_clock``) and write the accepted
    rows into ``buf.acc_rows``; returns their number."""
    record_innovations(t_ns, g, cfg.gate, log.inn_i, log.inn_f, log.counts, log.ev_i, log.ev_f)
    update_reject_since(t_ns, g.blocks, g.nb, g.accepted, buf.reject_since)
    update_stream_clock(
        t_ns, g.blocks, g.nb, g.accepted, buf.stream_clock, cfg.return_gap_s, cfg.timeout_s
    )
    return accepted_rows(g.blocks, g.nb, g.accepted, buf.acc_rows)
