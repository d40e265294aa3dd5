"""One update epoch as stacked measurement rows: layout, values, predictions and Jacobians.

An epoch (one stop of the replay loop) may carry a GNSS fix (loose coupling), the satellites
of one ``gnss_obs`` epoch (tight coupling), the NHC pair and, at rest, the zero-velocity and
zero-angular-rate triples (``models.standstill``); all its rows are fused in one
joint update (paper 001: "if both NHC and GPS observables are used at the same time ...").
Rows are grouped into *blocks*, the units of gating: a fix's position (3 rows, 2 for a 2-D
fix), its velocity (3, or 2 when the receiver gives speed and course only), one satellite's
pseudorange and rate (1-2), the NHC pair (2), the ZUPT velocity (3) and the ZARU angular rate
(3), the last two one ``standstill`` stream.

Array layouts shared with ``pipeline.estimation.ins.inputs`` (which fills them) and the kernels:

- ``fix`` (M, ``FIX_COLS``): latitude, longitude (rad), altitude (m), NED velocity (m/s),
  horizontal, vertical and speed 1-sigma, position dimension (0 = unusable, 2 = horizontal,
  3), velocity dimension (0 = unusable, 2 = north and east only, 3) and the factor by which
  the position variances were inflated for time-correlated errors (1 = white; see
  ``gate_shift``).
- ``obs`` (K, ``OBS_COLS``): satellite ECEF position and velocity, corrected pseudorange (m)
  and pseudorange rate (m/s), their 1-sigma, the satellite code (``sv_code``) and flags.
- ``obs_start`` (E + 1,): rows of obs epoch ``e`` are ``obs_start[e]:obs_start[e + 1]``.
- ``stop`` rows (``STOP_COLS``, int64): time (ns), fix index, obs epoch index (-1 = none),
  NHC flag, output flag, standstill flag (the span since the previous stop was at rest).
- ``still`` (5,): the standstill rows' values of an epoch: ZUPT and ZARU 1-sigma (m/s,
  rad/s) and the mean angular rate over the span (rad/s, body).
- ``rows`` (m, 2): kind (``K_*``) and the fix or obs row it reads.
- ``blocks`` (b, 4): first row, dimension, stream (``S_*``) and satellite code (-1 = none).

The replay passes the table a filter does not read as an empty array (no stop names one of
its epochs), so loosely and tightly coupled filters share one compiled kernel. ``None`` is
accepted too: numba then prunes the ``is not None`` branches while compiling (a separate,
smaller kernel); the arithmetic is the same either way.
"""

from __future__ import annotations

import numpy as np

from navreplay.pipeline._jit import njit
from navreplay.pipeline.estimation.ins.models.gnss import (
    AN_DIM,
    AN_LLH,
    AN_VN,
    antenna,
    ned_offset,
    position_jac,
    pseudorange_h,
    pseudorange_jac,
    pseudorange_rate_h,
    pseudorange_rate_jac,
    velocity_jac,
)
from navreplay.pipeline.estimation.ins.models.ins import X_CB, X_VEL
from navreplay.pipeline.estimation.ins.models.nhc import body_velocity, nhc_jac
from navreplay.pipeline.estimation.ins.models.standstill import zaru_h, zaru_jac, zupt_jac
from navreplay.pipeline.nav.earth import F64, I64

FX_LAT, FX_LON, FX_ALT, FX_VN, FX_VE, FX_VD = 0, 1, 2, 3, 4, 5
FX_SIG_H, FX_SIG_V, FX_SIG_VEL, FX_POS_DIM, FX_VEL_DIM, FX_POS_INFL = 6, 7, 8, 9, 10, 11
#: > 0: the fix's north and east errors are the filter's Gauss-Markov states; its horizontal
#: rows then carry this share of the fix's own variance (``FX_SIG_H`` without the
#: ``FX_POS_INFL`` inflation), the white noise beside them, gated and updated as is (the
#: vertical keeps the inflation). 0: no states, the inflated variance
FX_GM = 12
FIX_COLS = 13

OB_SAT = 0  # 0..5: ECEF x, y, z (m), vx, vy, vz (m/s)
OB_PR, OB_PRR, OB_SIG_PR, OB_SIG_PRR, OB_SV, OB_PR_OK, OB_PRR_OK = 6, 7, 8, 9, 10, 11, 12
OBS_COLS = 13

ST_T, ST_FIX, ST_OBS, ST_NHC, ST_OUT, ST_STILL = 0, 1, 2, 3, 4, 5
STOP_COLS = 6

# K_POS + axis, K_VEL + axis, K_NHC + 0/1, K_ZUPT + axis, K_ZARU + axis
K_POS, K_VEL, K_PR, K_PRR, K_NHC, K_ZUPT, K_ZARU = 0, 3, 6, 7, 8, 10, 13

# the pseudo-measurement streams come last: from S_NHC on, a stream is never reset
S_POS, S_VEL, S_OBS, S_NHC, S_STILL = 0, 1, 2, 3, 4
STREAM_NAMES = ("gnss_pos", "gnss_vel", "gnss_obs", "nhc", "standstill")
STREAM_UNITS = ("m", "mps", "m|mps", "mps", "mps|radps")

STILL_SIG_VEL, STILL_SIG_RATE, STILL_RATE = 0, 1, 2  # still[2:5]: mean angular rate
STILL_COLS = 5


def sv_code(sv: str) -> int:
    """Integer code of a satellite id ("G05" -> 7*1000+5 style: ord(system) * 1000 + number)."""
    return ord(sv[0]) * 1000 + int(sv[1:])


def sv_name(code: int) -> str:
    """Inverse of ``sv_code`` ("" for -1)."""
    if code < 0:
        return ""
    return f"{chr(code // 1000)}{code % 1000:02d}"


@njit(cache=True, inline="always", error_model="numpy")
def _add_block(
    rows: I64, blocks: I64, m: int, nb_: int, dim: int, stream: int, kind0: int, src: int
) -> tuple[int, int]:
    """Append a block of ``dim`` rows of kinds ``kind0, kind0 + 1, ...`` reading row ``src``
    of its table (-1: none) after the ``m`` rows and ``nb_`` blocks used; returns them after
    it."""
    blocks[nb_, 0], blocks[nb_, 1], blocks[nb_, 2], blocks[nb_, 3] = m, dim, stream, -1
    for a in range(dim):
        rows[m + a, 0], rows[m + a, 1] = kind0 + a, src
    return m + dim, nb_ + 1


@njit(cache=True, error_model="numpy")
def epoch_layout(
    stop: I64,
    fix: F64 | None,
    obs: F64 | None,
    obs_start: I64,
    nhc_on: bool,
    still_on: bool,
    rows: I64,
    blocks: I64,
) -> tuple[int, int]:
    """Lay out the rows and blocks of the epoch at ``stop``; returns (rows, blocks) used."""
    m = 0
    nb_ = 0
    fi = stop[ST_FIX]
    if fix is not None and fi >= 0:
        pdim = int(fix[fi, FX_POS_DIM])
        if pdim > 0:
            m, nb_ = _add_block(rows, blocks, m, nb_, pdim, S_POS, K_POS, fi)
        vdim = int(fix[fi, FX_VEL_DIM])
        if vdim > 0:
            m, nb_ = _add_block(rows, blocks, m, nb_, vdim, S_VEL, K_VEL, fi)
    oi = stop[ST_OBS]
    if obs is not None and oi >= 0:
        for k in range(obs_start[oi], obs_start[oi + 1]):
            start = m
            if obs[k, OB_PR_OK] > 0.0:
                rows[m, 0], rows[m, 1] = K_PR, k
                m += 1
            if obs[k, OB_PRR_OK] > 0.0:
                rows[m, 0], rows[m, 1] = K_PRR, k
                m += 1
            if m > start:
                blocks[nb_, 0], blocks[nb_, 1] = start, m - start
                blocks[nb_, 2], blocks[nb_, 3] = S_OBS, int(obs[k, OB_SV])
                nb_ += 1
    if nhc_on and stop[ST_NHC] > 0:
        m, nb_ = _add_block(rows, blocks, m, nb_, 2, S_NHC, K_NHC, -1)
    if still_on and stop[ST_STILL] > 0:
        m, nb_ = _add_block(rows, blocks, m, nb_, 3, S_STILL, K_ZUPT, -1)
        m, nb_ = _add_block(rows, blocks, m, nb_, 3, S_STILL, K_ZARU, -1)
    return m, nb_


@njit(cache=True, error_model="numpy")
def fix_position_variance(fix: F64, src: int, axis: int) -> float:
    """Noise variance of fix ``src``'s NED position ``axis``: the inflated variance, or for
    the north and east of a fix whose errors are states (``FX_GM``) the white share of its
    own."""
    if axis == 2:
        return float(fix[src, FX_SIG_V] ** 2)
    if fix[src, FX_GM] > 0.0:
        return float(fix[src, FX_SIG_H] ** 2 / fix[src, FX_POS_INFL] * fix[src, FX_GM])
    return float(fix[src, FX_SIG_H] ** 2)


@njit(cache=True, error_model="numpy")
def epoch_z(
    rows: I64,
    m: int,
    fix: F64 | None,
    obs: F64 | None,
    ref: F64,
    nhc_sigma: F64,
    still: F64,
    z: F64,
    r: F64,
) -> None:
    """Measured values ``z`` and noise variances ``r`` of the rows (positions as NED offsets
    from ``ref`` = (lat, lon, h) in metres; NHC and ZUPT pseudo-measurements are zero, ZARU
    the mean angular rate in ``still``)."""
    for k in range(m):
        kind, src = rows[k, 0], rows[k, 1]
        if kind < K_PR:
            if fix is not None:
                if kind < K_VEL:
                    off = ned_offset(fix[src, FX_LAT], fix[src, FX_LON], fix[src, FX_ALT], ref)
                    z[k] = off[0] if kind == K_POS else off[1] if kind == K_POS + 1 else off[2]
                    r[k] = fix_position_variance(fix, src, kind - K_POS)
                else:
                    z[k] = fix[src, FX_VN + kind - K_VEL]
                    r[k] = fix[src, FX_SIG_VEL] ** 2
        elif kind < K_NHC:
            if obs is not None:
                pr = kind == K_PR
                z[k] = obs[src, OB_PR] if pr else obs[src, OB_PRR]
                sig = obs[src, OB_SIG_PR] if pr else obs[src, OB_SIG_PRR]
                r[k] = sig * sig
        elif kind < K_ZUPT:
            z[k] = 0.0
            r[k] = nhc_sigma[kind - K_NHC] ** 2
        elif kind < K_ZARU:
            z[k] = 0.0
            r[k] = still[STILL_SIG_VEL] ** 2
        else:
            z[k] = still[STILL_RATE + kind - K_ZARU]
            r[k] = still[STILL_SIG_RATE] ** 2


@njit(cache=True, error_model="numpy")
def scale_fix_rows(rows: I64, m: int, r_scale: F64, r: F64) -> None:
    """Multiply the fix rows' variances ``r`` by ``r_scale[kind]`` (``records.Epoch``: ones
    but in the adaptive ``iae_ekf``), before the gate and the update see them."""
    for k in range(m):
        kind = rows[k, 0]
        if kind < K_PR:
            r[k] *= r_scale[kind]


@njit(cache=True, error_model="numpy")
def gate_shift(rows: I64, m: int, fix: F64 | None, r: F64, dr: F64) -> None:
    """Per row, the gating variance minus the update variance ``r`` (``dr[:m]``, <= 0).

    A fix position whose variance was inflated by ``1 + 2 tau / dt`` for time-correlated
    errors (``inputs.prepare_fixes``) is *updated* with the inflated variance, so that a run
    of correlated fixes is not counted as independent information; but one fix's error is
    still distributed with the receiver's marginal variance, so the innovation is *gated*
    (and its NIS reported) against ``H P H^T`` plus that marginal variance. Gating against
    the inflated variance would let a 20 m multipath outlier through a 1.5 m fix's gate
    (bad-inputs F7). Every other row gates with its update variance (``dr = 0``).
    """
    for k in range(m):
        kind, src = rows[k, 0], rows[k, 1]
        dr[k] = 0.0
        if fix is None:
            continue
        if kind < K_VEL and not (fix[src, FX_GM] > 0.0 and kind < K_POS + 2):
            infl = fix[src, FX_POS_INFL]
            if infl > 1.0:
                dr[k] = r[k] * (1.0 / infl - 1.0)


@njit(cache=True, error_model="numpy", inline="always")
def epoch_h(
    X: F64, rows: I64, m: int, obs: F64 | None, ref: F64, w_ib_b: F64, lever_b: F64, out: F64
) -> None:
    """Predicted values of the rows for the full state ``X`` (``out[:m]``); a fix's north and
    east include its Gauss-Markov error (``X[X_CB]``, ``X[X_CD]``) where a loosely coupled
    filter carries it, zero otherwise."""
    ant = np.empty(AN_DIM)
    antenna(X, lever_b, w_ib_b, np.empty((3, 3)), ant)
    pos = ned_offset(ant[AN_LLH], ant[AN_LLH + 1], ant[AN_LLH + 2], ref)
    for k in range(m):
        kind, src = rows[k, 0], rows[k, 1]
        if kind < K_VEL:
            axis = kind - K_POS
            out[k] = pos[axis] + (X[X_CB + axis] if axis < 2 else 0.0)
        elif kind < K_PR:
            out[k] = ant[AN_VN + kind - K_VEL]
        elif kind < K_NHC:
            if obs is not None:
                sat = obs[src, OB_SAT : OB_SAT + 6]
                if kind == K_PR:
                    out[k] = pseudorange_h(ant, X, sat)
                else:
                    out[k] = pseudorange_rate_h(ant, X, sat)
        elif kind < K_ZUPT:
            out[k] = body_velocity(X, ant, 1 + kind - K_NHC)
        elif kind < K_ZARU:
            out[k] = X[X_VEL + kind - K_ZUPT]
        else:
            out[k] = zaru_h(X, ant, kind - K_ZARU)


@njit(cache=True, error_model="numpy", inline="always")
def epoch_jac(
    X: F64, rows: I64, m: int, obs: F64 | None, w_ib_b: F64, lever_b: F64, n: int, H: F64
) -> None:
    """Jacobian rows w.r.t. the error state (``H[:m, :n]``)."""
    ant = np.empty(AN_DIM)
    antenna(X, lever_b, w_ib_b, np.empty((3, 3)), ant)
    for k in range(m):
        kind, src = rows[k, 0], rows[k, 1]
        if kind < K_VEL:
            position_jac(ant, kind - K_POS, n, H[k])
        elif kind < K_PR:
            velocity_jac(ant, lever_b, kind - K_VEL, n, H[k])
        elif kind < K_NHC:
            if obs is not None:
                sat = obs[src, OB_SAT : OB_SAT + 6]
                if kind == K_PR:
                    pseudorange_jac(ant, sat, n, H[k])
                else:
                    pseudorange_rate_jac(ant, lever_b, sat, n, H[k])
        elif kind < K_ZUPT:
            nhc_jac(X, ant, 1 + kind - K_NHC, n, H[k])
        elif kind < K_ZARU:
            zupt_jac(kind - K_ZUPT, n, H[k])
        else:
            zaru_jac(X, ant, kind - K_ZARU, n, H[k])
