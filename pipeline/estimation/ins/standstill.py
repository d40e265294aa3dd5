"""When the vehicle stands still: the intervals in which the INS filters fuse the zero-velocity
and zero-angular-rate updates (``models.standstill``).

A sample is at rest when, over the window centred on it (``window_s``):

- the spread of the specific force and of the angular rate (their RMS about the window's
  mean, over the three axes) stays below ``noise_factor`` times the IMU's own sample noise
  (the white-noise density times the square root of the sample rate: the dataset's noise
  model, or the one the replay measured in the log when it is noisier). The spread, not the
  level, so that a gyro bias of 1 deg/s does not hide a standstill;
- the mean specific force is within ``init.static_accel_tol_mps2`` of gravity and the mean
  angular rate under ``max_rate_radps`` (no steady turn, no climb; above any plausible gyro
  bias);

and no GNSS fix within a second of it says the vehicle moves: a receiver velocity (3-D) over
``gnss_speed_mps`` and 3 sigma of itself, or, without one, a displacement of the fixes over
at least ``gnss_baseline_s`` faster than that. Every window covering the sample must be at
rest (the detection is eroded by half a window on both sides), so the first metre of a
drive-off is not taken for rest.

A vehicle cruising at constant speed on a smooth road can pass the IMU's tests (always, in a
simulator without vibration), and in a GNSS outage no fix vetoes it. So the log checks its
own IMU: where GNSS says the vehicle moves, the IMU must look quiet less than
``QUIET_WHILE_MOVING`` of the time; otherwise the IMU cannot tell rest from cruise in this
log, and rest needs a fix within a second that does not move (no updates in an outage).
An aircraft (``ground_only=False``) that hovers is not at rest, yet a simulator's quiet IMU
at hover passes every test: it is taken for at rest only where a fix says so, before the
GNSS first says it moves and after it last does (on the ground before take-off and after
landing; never in an outage).

The kernels also apply the updates only while the filter's own speed is plausible for rest
(``StandstillParams.max_speed_mps``), and gate them.
"""

from __future__ import annotations

import logging
import math

import numpy as np
from scipy.ndimage import minimum_filter1d, uniform_filter1d

from navreplay.ingest.config import ImuNoise
from navreplay.pipeline.estimation.ins.config import InitParams, StandstillParams
from navreplay.pipeline.estimation.ins.inputs import FixData, ImuData
from navreplay.pipeline.estimation.ins.models import measurement as me
from navreplay.pipeline.nav.earth import F64, I64, gravity, radii

log = logging.getLogger(__name__)

_VETO_NS = 1_000_000_000  # a moving fix vetoes rest this far around it, a still one allows it
#: the most of the GNSS-confirmed motion the IMU may take for rest and still be trusted alone
QUIET_WHILE_MOVING = 0.05


def detect(
    imu: ImuData,
    noise: ImuNoise,
    fixes: FixData | None,
    p: StandstillParams,
    init: InitParams,
    lat_rad: float = 0.0,
    h_m: float = 0.0,
    *,
    aircraft: bool = False,
) -> I64:
    """The standstill intervals of the IMU, (K, 2) int64 ``[start, end]`` in ns (inclusive),
    each inside one IMU segment; empty when ``p.enabled`` is off. ``aircraft``: at rest only
    at fixes that say so, before the first and after the last motion GNSS confirms."""
    if not p.enabled:
        return np.empty((0, 2), np.int64)
    g = gravity(lat_rad, h_m)
    quiet = np.zeros(imu.t_ns.size, dtype=bool)
    for lo, hi in imu.segments:
        t = imu.t_ns[lo:hi]
        if t.size >= 3:
            rate = (t.size - 1) / ((t[-1] - t[0]) * 1e-9)
            quiet[lo:hi] = _quiet(imu.data[lo:hi], rate, noise, p, init, g)
    moving_t, still_t = _gnss_moving(fixes, p)
    vetoed = _near(imu.t_ns, moving_t)
    rest = quiet & ~vetoed
    if vetoed.any() and quiet[vetoed].mean() > QUIET_WHILE_MOVING:
        log.info(
            "standstill: the IMU looks as quiet as at rest during %.0f %% of the motion GNSS "
            "confirms (no vibration): at rest only where a fix says so",
            100 * quiet[vetoed].mean(),
        )
        rest &= _near(imu.t_ns, still_t)
    if aircraft:
        rest &= _near(imu.t_ns, still_t)  # in an outage a hover passes for rest
        if moving_t.size:
            rest &= (imu.t_ns < moving_t[0] - _VETO_NS) | (imu.t_ns > moving_t[-1] + _VETO_NS)
    out: list[tuple[int, int]] = []
    for lo, hi in imu.segments:
        out.extend(_runs(imu.t_ns[lo:hi], rest[lo:hi]))
    return np.array(out, np.int64).reshape(-1, 2)


def _near(t: I64, events: I64) -> np.ndarray:
    """Samples within ``_VETO_NS`` of any of the sorted ``events``."""
    near = np.zeros(t.size, dtype=bool)
    if events.size == 0:
        return near
    j = np.searchsorted(events, t)
    near |= (j < events.size) & (events[np.minimum(j, events.size - 1)] - t <= _VETO_NS)
    near |= (j > 0) & (t - events[np.maximum(j - 1, 0)] <= _VETO_NS)
    return near


def _quiet(
    data: F64, rate_hz: float, noise: ImuNoise, p: StandstillParams, init: InitParams, g: float
) -> np.ndarray:
    """Samples whose every covering window passes the IMU's tests."""
    w = max(3, round(p.window_s * rate_hz) | 1)  # odd: centred
    mean = uniform_filter1d(data, w, axis=0, mode="nearest")
    sq = uniform_filter1d(data * data, w, axis=0, mode="nearest")
    var = np.maximum(sq - mean * mean, 0.0)
    sig_f = noise.accel_noise_mps2_rthz * math.sqrt(rate_hz)
    sig_w = noise.gyro_noise_radps_rthz * math.sqrt(rate_hz)
    k2 = p.noise_factor**2
    ok = (var[:, :3].sum(axis=1) <= k2 * 3.0 * sig_f**2) & (
        var[:, 3:].sum(axis=1) <= k2 * 3.0 * sig_w**2
    )
    ok &= np.abs(np.linalg.norm(mean[:, :3], axis=1) - g) <= init.static_accel_tol_mps2
    ok &= np.linalg.norm(mean[:, 3:], axis=1) <= p.max_rate_radps
    return np.asarray(minimum_filter1d(ok.astype(np.uint8), w, mode="nearest") > 0)


def _gnss_moving(fixes: FixData | None, p: StandstillParams) -> tuple[I64, I64]:
    """Times of the fixes that say the vehicle moves, and of the others (sorted)."""
    if fixes is None or fixes.t_ns.size == 0:
        return np.empty(0, np.int64), np.empty(0, np.int64)
    f, t = fixes.fix, fixes.t_ns
    use = fixes.usable
    moving = np.zeros(t.size, dtype=bool)
    has_vel = use & (f[:, me.FX_VEL_DIM] > 0)
    vd = np.where(f[:, me.FX_VEL_DIM] == 3, f[:, me.FX_VD], 0.0)  # a climb moves too
    speed = np.sqrt(f[:, me.FX_VN] ** 2 + f[:, me.FX_VE] ** 2 + vd**2)
    moving |= has_vel & (speed > np.maximum(p.gnss_speed_mps, 3.0 * f[:, me.FX_SIG_VEL]))
    pos = np.flatnonzero(use & (f[:, me.FX_POS_DIM] > 0))
    if pos.size >= 2:
        tp = t[pos] * 1e-9
        lat, lon = f[pos, me.FX_LAT], f[pos, me.FX_LON]
        rm, rn = np.vectorize(radii)(lat)
        north, east = lat * rm, lon * rn * np.cos(lat)
        sig = f[pos, me.FX_SIG_H] / np.sqrt(f[pos, me.FX_POS_INFL])
        # each fix against the first one at least gnss_baseline_s later
        j = np.searchsorted(tp, tp + p.gnss_baseline_s)
        ok = j < pos.size
        a, b = np.flatnonzero(ok), j[ok]
        dt = tp[b] - tp[a]
        close = dt <= 2.0 * p.gnss_baseline_s  # no long gap between them
        a, b, dt = a[close], b[close], dt[close]
        v = np.hypot(north[b] - north[a], east[b] - east[a]) / dt
        sig_v = np.hypot(sig[a], sig[b]) / dt
        fast = (v > p.gnss_speed_mps) & (v > 3.0 * sig_v)
        moving[pos[a[fast]]] = True
        moving[pos[b[fast]]] = True
    return np.sort(t[moving]), np.sort(t[use & ~moving])


def _runs(t: I64, rest: np.ndarray) -> list[tuple[int, int]]:
    """``[first, last]`` times of the runs of ``rest``."""
    if not rest.any():
        return []
    edges = np.diff(np.concatenate([[0], rest.astype(np.int8), [0]]))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1
    return [(int(t[a]), int(t[b])) for a, b in zip(starts, ends, strict=True) if b > a]


def flag_stops(stops_t: I64, t_start: int, intervals: I64) -> np.ndarray:
    """Per stop, whether the span since the previous stop (``t_start`` before the first) lies
    within one standstill interval."""
    if intervals.size == 0 or stops_t.size == 0:
        return np.zeros(stops_t.size, dtype=bool)
    prev = np.concatenate([[t_start], stops_t[:-1]])
    k = np.searchsorted(intervals[:, 0], prev, side="right") - 1
    kc = np.maximum(k, 0)
    inside: np.ndarray = (k >= 0) & (prev >= intervals[kc, 0]) & (stops_t <= intervals[kc, 1])
    return inside
