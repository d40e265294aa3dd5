"""Canonical tables to the arrays the replay loops read, with the data barrier in front.

Nothing invalid reaches a filter: IMU samples with a non-finite value, duplicated or
backwards timestamps are dropped and counted (bad-inputs F19, case 30/31); GNSS fields that
are NaN are skipped per block and counted (F11); fixes without a usable fix type are not fused
(case 27). Every skip becomes an event of the run. IMU gaps longer than ``step.imu_gap_s`` are
reported and bridged; longer than ``step.imu_gap_max_s`` they split the run into segments.

Arrays follow the layouts of ``models.measurement``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import pyarrow as pa

from navreplay.ingest.schema import FixType
from navreplay.pipeline.estimation.core.tables import (
    B8,
    Event,
    _is_null,
    fix_epochs,
    float_column,
)
from navreplay.pipeline.estimation.ins.config import GnssNoiseParams, StepParams
from navreplay.pipeline.estimation.ins.fixnoise import FixNoise, ObsNoise, learn, learn_obs
from navreplay.pipeline.estimation.ins.models import measurement as me
from navreplay.pipeline.nav.earth import F64, I64

_IMU_COLS = ("acc_x_mps2", "acc_y_mps2", "acc_z_mps2", "gyro_x_radps", "gyro_y_radps")
IMU_COLUMNS = (*_IMU_COLS, "gyro_z_radps")


@dataclass(frozen=True)
class ImuData:
    """Clean IMU samples: strictly increasing ``t_ns`` (N,), ``data`` (N, 6) = f_b, w_ib_b."""

    t_ns: I64
    data: F64
    segments: tuple[tuple[int, int], ...]  # [start, stop) index ranges split at long gaps
    events: tuple[Event, ...] = ()


@dataclass(frozen=True)
class FixData:
    """GNSS fixes (``fix`` layout of ``models.measurement``); ``usable`` marks rows with a
    position or velocity block."""

    t_ns: I64
    fix: F64
    usable: B8
    events: tuple[Event, ...] = ()
    noise: FixNoise | None = None


@dataclass(frozen=True)
class ObsData:
    """Satellite observations grouped by epoch (``obs`` layout of ``models.measurement``)."""

    epoch_t_ns: I64
    start: I64
    obs: F64
    events: tuple[Event, ...] = ()
    masked: int = 0
    noise: ObsNoise | None = None


@dataclass(frozen=True)
class MagData:
    """Magnetometer samples (the ``mag`` table): ``t_ns`` (K,), ``field`` (K, 3) gauss, body
    FRD; rows with a non-finite component dropped."""

    t_ns: I64
    field: F64


def prepare_mag(table: pa.Table) -> MagData | None:
    """The ``mag`` table's finite samples in time order, or None if it has none."""
    t = np.asarray(table.column("t_ns").to_numpy(), dtype=np.int64)
    b = np.column_stack([float_column(table, f"mag_{a}_gauss") for a in "xyz"])
    keep = np.isfinite(b).all(axis=1)
    if not keep.any():
        return None
    order = np.argsort(t[keep], kind="stable")
    return MagData(t[keep][order], np.ascontiguousarray(b[keep][order]))


def prepare_imu(table: pa.Table, step: StepParams) -> ImuData:
    """Drop invalid, duplicated and backwards samples; find gaps and segments."""
    t = np.asarray(table.column("t_ns").to_numpy(), dtype=np.int64)
    data = np.column_stack([float_column(table, c) for c in IMU_COLUMNS])
    return clean_imu(t, data, step)


def clean_imu(t: I64, data: F64, step: StepParams) -> ImuData:
    """The IMU data barrier on raw arrays (also used directly by tests of F12 and F19).

    Keeps the first of samples with equal timestamps (``imu_duplicate``), drops samples older
    than the last kept one (``imu_backwards``) and samples with a non-finite value
    (``imu_invalid``); reports intervals longer than ``imu_gap_s`` (``imu_gap``, value = the
    interval in s) and splits at intervals longer than ``imu_gap_max_s`` (``segment_break``)
    and at tumbles (``imu_tumble``, value = the peak rate in rad/s; the samples until they
    settle belong to no segment).
    """
    events: list[Event] = []
    finite = np.isfinite(data).all(axis=1)
    for k in np.flatnonzero(~finite):
        events.append(Event(int(t[k]), "imu_invalid", "imu"))
    keep = np.zeros(t.size, dtype=bool)
    last: int | None = None
    for k in np.flatnonzero(finite):
        tk = int(t[k])
        if last is not None and tk <= last:
            kind = "imu_duplicate" if tk == last else "imu_backwards"
            events.append(Event(tk, kind, "imu", value=(tk - last) * 1e-9))
            continue
        keep[k] = True
        last = tk
    t_ok, d_ok = t[keep], np.ascontiguousarray(data[keep])
    dt = np.diff(t_ok) * 1e-9
    # [start, stop) spans no segment may cross: long gaps, and tumbles with their settling
    cuts: list[tuple[int, int]] = []
    for k in np.flatnonzero(dt > step.imu_gap_s):
        events.append(Event(int(t_ok[k]), "imu_gap", "imu", value=float(dt[k])))
        if dt[k] > step.imu_gap_max_s:
            events.append(Event(int(t_ok[k + 1]), "segment_break", "imu", value=float(dt[k])))
            cuts.append((int(k) + 1, int(k) + 1))
    for lo, hi, rate in _tumbles(t_ok, d_ok, step):
        events.append(Event(int(t_ok[lo]), "imu_tumble", "imu", value=rate))
        cuts.append((lo, hi))
    segments: list[tuple[int, int]] = []
    start = 0
    for lo, hi in sorted(cuts):
        segments.append((start, lo))
        start = max(start, hi)
    segments.append((start, int(t_ok.size)))
    events.sort(key=lambda e: e.t_ns)
    return ImuData(t_ok, d_ok, tuple(s for s in segments if s[1] - s[0] >= 2), tuple(events))


def _tumbles(t: I64, data: F64, step: StepParams) -> list[tuple[int, int, float]]:
    """(first sample, first sample after settling, peak rate rad/s) of each tumble: samples
    turning faster than ``tumble_rate_radps`` and by more than ``tumble_rotation_rad`` to the
    next sample (see ``StepParams``), grouped where they are less than the settling time
    apart."""
    if t.size < 2:
        return []
    rate = np.linalg.norm(data[:, 3:], axis=1)
    dt = np.append(np.diff(t), 0) * 1e-9
    hit = np.flatnonzero((rate > step.tumble_rate_radps) & (rate * dt > step.tumble_rotation_rad))
    settle_ns = int(step.tumble_settle_s * 1e9)
    out: list[tuple[int, int, float]] = []
    for k in (int(j) for j in hit):
        if out and t[k] - t[out[-1][1] - 1] < settle_ns:
            lo, _, peak = out[-1]
            out[-1] = (lo, k + 1, max(peak, float(rate[k])))
        else:
            out.append((k, k + 1, float(rate[k])))
    ends = np.searchsorted(t, np.array([t[hi - 1] for _, hi, _ in out], np.int64) + settle_ns)
    return [(lo, int(end), peak) for (lo, _, peak), end in zip(out, ends, strict=True)]


def imu_white_noise(imu: ImuData) -> tuple[float, float]:
    """White-noise densities the log itself shows: (accelerometer m/s^2/sqrt(Hz), gyro
    rad/s/sqrt(Hz)), the largest over the three axes.

    Per axis, the sample-to-sample differences inside the segments give
    ``sigma = 1.4826 median|diff| / sqrt(2)`` (the MAD, robust to manoeuvres and glitches)
    and the density ``sigma sqrt(dt)``. On a quiet MEMS at 100 Hz this is the datasheet
    noise; on a log of decimated samples (ArduPilot's 25 Hz IMU messages of an 8 kHz sensor)
    it is the aliased vibration, which the filter has to treat as noise. True motion adds to
    it, so it is an upper estimate, used as a floor (``replay.resolve_imu_noise``).
    """
    diffs = [np.diff(imu.data[lo:hi], axis=0) for lo, hi in imu.segments if hi - lo >= 3]
    if not diffs:
        return 0.0, 0.0
    d = np.concatenate(diffs)
    sigma = 1.4826 * np.median(np.abs(d), axis=0) / math.sqrt(2.0)
    dt = float(np.median(np.diff(imu.t_ns))) * 1e-9
    density = sigma * math.sqrt(dt)
    return float(density[:3].max()), float(density[3:].max())


def _reported(acc: F64) -> F64:
    """A reported accuracy, NaN where it is absent or not positive."""
    return np.where(acc > 0.0, acc, math.nan)


#: with Gauss-Markov fix-error states, the white part of a fix's horizontal variance (the
#: receiver's noise beside the slowly wandering multipath and atmosphere), as a share of it
GM_WHITE_SHARE = 0.09
#: ... used where the learned correlation time is at least this many fix intervals
GM_MIN_INTERVALS = 3.0


def _with_error_states(noise: FixNoise, t_ns: I64, fix: F64, gnss: GnssNoiseParams) -> FixNoise:
    """``noise`` with the Gauss-Markov states decided (``GnssNoiseParams.fix_error_states``):
    a correlation learned from the log over ``GM_MIN_INTERVALS`` fix intervals or more; their
    1-sigma is the fixes' median horizontal 1-sigma (reported, learned or default)."""
    if noise.states or t_ns.size < 2:
        return noise
    dt = float(np.median(np.diff(t_ns))) * 1e-9
    pos = fix[:, me.FX_POS_DIM] >= 2
    if not (gnss.fix_error_states and noise.source == "learned" and pos.any()
            and noise.tau_s >= GM_MIN_INTERVALS * dt):  # fmt: skip
        return noise
    sigma = float(np.median(fix[pos, me.FX_SIG_H]))
    return replace(noise, states=True, states_sigma_m=sigma)


def _apply_noise(
    t_ns: I64, fix: F64, noise: FixNoise, reported: tuple[F64, F64], gnss: GnssNoiseParams
) -> FixNoise:
    """The fix-error model into the ``fix`` rows (in place): the learned size where the
    receiver ``reported`` (horizontal, vertical accuracy) none, then the correlation as
    Gauss-Markov states or as an inflation; returns the model with its states decided."""
    h_acc, v_acc = reported
    if math.isfinite(noise.sigma_h_m):  # the receiver's own accuracies win where given
        learned_h = max(noise.sigma_h_m, gnss.pos_sigma_floor_m)
        fix[:, me.FX_SIG_H] = np.where(np.isfinite(h_acc), fix[:, me.FX_SIG_H], learned_h)
    if math.isfinite(noise.sigma_v_m):
        learned_v = max(noise.sigma_v_m, gnss.pos_sigma_floor_m)
        fix[:, me.FX_SIG_V] = np.where(np.isfinite(v_acc), fix[:, me.FX_SIG_V], learned_v)
    noise = _with_error_states(noise, t_ns, fix, gnss)
    # time-correlated errors: fewer independent fixes than fixes (the variances inflated, as
    # alignment and the standstill detector read them), the horizontal ones Gauss-Markov states
    # where the filter carries them (its update takes the white share alone)
    fix[:, me.FX_SIG_H] *= math.sqrt(noise.inflation)
    fix[:, me.FX_SIG_V] *= math.sqrt(noise.inflation)
    fix[:, me.FX_GM] = GM_WHITE_SHARE if noise.states else 0.0
    fix[:, me.FX_POS_INFL] = noise.inflation  # gated against the marginal variance
    return noise


def prepare_fixes(table: pa.Table, gnss: GnssNoiseParams, noise: FixNoise | None = None) -> FixData:
    """Receiver fixes -> ``fix`` rows with floored accuracies; NaN blocks skipped (F11).

    Position sigmas are inflated for time-correlated errors, their correlation time learned
    from the log where it has a receiver velocity (``fixnoise.learn``), else
    ``pos_error_corr_time_s``; where the receiver reports no accuracy, the learned size
    replaces ``pos_sigma_default_m``. ``noise``: a model learned before (from the whole log,
    where ``table`` is a scenario's or a window's part of it) instead of learning one here.
    A fix is applied at its own epoch: with a ``latency_s`` column (arrival minus the
    receiver's epoch, as the comma2k19 reader writes it, or the dataset's latency against the
    IMU: ``with_fix_latency``), at ``t_ns - latency_s`` (``fix_epochs``).
    Position needs a fix type of at least 2-D (a 2-D fix is fused horizontally); velocity
    needs north and east, and includes down where the receiver provides it (null = not
    provided, a 2-D velocity block; NaN = invalid, the block is skipped).
    """
    n = table.num_rows
    t = np.asarray(table.column("t_ns").to_numpy(), dtype=np.int64)
    epochs = fix_epochs(table)
    if gnss.use_fix_latency and np.any(epochs != t):
        # the fix describes its own epoch, not its arrival (bad-inputs F10)
        t = epochs
        order = np.argsort(t, kind="stable")
        if np.any(order != np.arange(n)):
            table, t = table.take(pa.array(order)), t[order]
    fix = np.zeros((n, me.FIX_COLS))
    lat, lon, alt = (
        float_column(table, "lat_deg"),
        float_column(table, "lon_deg"),
        float_column(table, "alt_m"),
    )
    fix[:, me.FX_LAT], fix[:, me.FX_LON], fix[:, me.FX_ALT] = np.radians(lat), np.radians(lon), alt
    fix_type = np.asarray(table.column("fix_type").to_numpy(), dtype=np.int64)
    # an accuracy of zero is one the receiver did not report (PX4 SITL writes 0)
    h_acc = _reported(float_column(table, "h_acc_m"))
    v_acc = _reported(float_column(table, "v_acc_m"))
    fix[:, me.FX_SIG_H] = np.maximum(
        np.where(np.isfinite(h_acc), h_acc, gnss.pos_sigma_default_m), gnss.pos_sigma_floor_m
    )
    # without a reported vertical accuracy, assume the usual GNSS 1.5 x horizontal
    fix[:, me.FX_SIG_V] = np.maximum(
        np.where(np.isfinite(v_acc), v_acc, 1.5 * gnss.pos_sigma_default_m),
        gnss.pos_sigma_floor_m,
    )
    s_acc = _reported(float_column(table, "speed_acc_mps"))
    fix[:, me.FX_SIG_VEL] = np.maximum(
        np.where(np.isfinite(s_acc), s_acc, gnss.vel_sigma_default_mps), gnss.vel_sigma_floor_mps
    )
    events: list[Event] = []
    pos_finite = np.isfinite(lat) & np.isfinite(lon) & np.isfinite(alt)
    has_fix = fix_type >= FixType.FIX_2D
    fix[:, me.FX_POS_DIM] = np.where(has_fix & pos_finite, np.where(fix_type == 2, 2, 3), 0)
    for k in np.flatnonzero(~has_fix):
        events.append(Event(int(t[k]), "skip_no_fix", "gnss_pos", value=float(fix_type[k])))
    for k in np.flatnonzero(has_fix & ~pos_finite):
        events.append(Event(int(t[k]), "skip_invalid", "gnss_pos"))
    vel = np.column_stack([float_column(table, c) for c in ("vel_n_mps", "vel_e_mps", "vel_d_mps")])
    fix[:, me.FX_VN : me.FX_VN + 3] = vel
    given_h = ~(_is_null(table, "vel_n_mps") | _is_null(table, "vel_e_mps"))
    given_d = ~_is_null(table, "vel_d_mps")
    finite_h = np.isfinite(vel[:, 0]) & np.isfinite(vel[:, 1])
    finite_d = np.isfinite(vel[:, 2])
    use = has_fix & gnss.use_velocity
    # north and east are required; down is used where the receiver gives it (3-D block)
    vdim = np.where(given_h & finite_h, np.where(given_d & finite_d, 3, 2), 0)
    fix[:, me.FX_VEL_DIM] = np.where(use & (~given_d | finite_d), vdim, 0)
    for k in np.flatnonzero(use & ((given_h & ~finite_h) | (given_d & ~finite_d))):
        events.append(Event(int(t[k]), "skip_invalid", "gnss_vel"))
    noise = learn(t, fix, h_acc, gnss) if noise is None else noise
    noise = _apply_noise(t, fix, noise, (h_acc, v_acc), gnss)
    usable = (fix[:, me.FX_POS_DIM] > 0) | (fix[:, me.FX_VEL_DIM] > 0)
    fix[~np.isfinite(fix)] = 0.0  # unusable fields never reach a kernel as NaN
    return FixData(t, fix, usable, tuple(events), noise)


def corrected_observables(table: pa.Table) -> tuple[F64, F64]:
    """``gnss_obs`` -> (pseudorange + sat_clock - iono - tropo, m; rate + sat_clock_drift,
    m/s): the satellite clock and atmosphere corrections applied, absent ones as zero (the
    table's conventions); NaN where the observable itself is NaN."""
    pr = (
        float_column(table, "pseudorange_m")
        + float_column(table, "sat_clock_m", 0.0)
        - float_column(table, "iono_delay_m", 0.0)
        - float_column(table, "tropo_delay_m", 0.0)
    )
    rate = float_column(table, "pseudorange_rate_mps")
    return pr, rate + float_column(table, "sat_clock_drift_mps", 0.0)


def prepare_obs(table: pa.Table, gnss: GnssNoiseParams, noise: ObsNoise | None = None) -> ObsData:
    """Satellite observations -> corrected pseudoranges and rates grouped by epoch.

    ``pseudorange + sat_clock - iono - tropo`` and ``rate + sat_clock_drift`` (absent
    corrections count as zero, per the ``gnss_obs`` conventions); satellites below the
    elevation mask are left out; NaN values skip that observable (F11). Where the table has
    no sigmas (a receiver or RINEX file that reports none) and ``gnss.learn_fix_noise``, they
    are learned from the log's own single-point residuals (``fixnoise.learn_obs``) instead
    of ``pseudorange_sigma_default_m``; ``noise``: values learned before (from the whole log,
    where ``table`` is a scenario's or a window's part of it) instead.
    """
    t = np.asarray(table.column("t_ns").to_numpy(), dtype=np.int64)
    k = table.num_rows
    obs = np.zeros((k, me.OBS_COLS))
    for j, c in enumerate(("sat_x_m", "sat_y_m", "sat_z_m", "sat_vx_mps", "sat_vy_mps")):
        obs[:, me.OB_SAT + j] = float_column(table, c)
    obs[:, me.OB_SAT + 5] = float_column(table, "sat_vz_mps")
    pr, prr = corrected_observables(table)
    obs[:, me.OB_PR], obs[:, me.OB_PRR] = pr, prr
    sig_pr = float_column(table, "pseudorange_std_m")
    sig_prr = float_column(table, "pseudorange_rate_std_mps")
    obs[:, me.OB_SIG_PR] = np.maximum(
        np.where(np.isfinite(sig_pr), sig_pr, gnss.pseudorange_sigma_default_m),
        gnss.pseudorange_sigma_floor_m,
    )
    obs[:, me.OB_SIG_PRR] = np.maximum(
        np.where(np.isfinite(sig_prr), sig_prr, gnss.pseudorange_rate_sigma_default_mps),
        gnss.pseudorange_rate_sigma_floor_mps,
    )
    svs = [str(s) for s in table.column("sv").to_pylist()]
    obs[:, me.OB_SV] = [me.sv_code(s) for s in svs]
    pos_ok = np.isfinite(obs[:, me.OB_SAT : me.OB_SAT + 3]).all(axis=1)
    vel_ok = np.isfinite(obs[:, me.OB_SAT + 3 : me.OB_SAT + 6]).all(axis=1)
    pr_ok = pos_ok & np.isfinite(pr)
    prr_ok = pos_ok & vel_ok & np.isfinite(prr)
    rate_provided = ~_is_null(table, "pseudorange_rate_mps")
    elev = float_column(table, "elevation_deg")
    masked = np.isfinite(elev) & (elev < gnss.elevation_mask_deg)
    events = [Event(int(t[j]), "skip_invalid", "gnss_obs", svs[j]) for j in np.flatnonzero(~pr_ok)]
    events += [
        Event(int(t[j]), "skip_invalid", "gnss_obs", svs[j], 1.0)
        for j in np.flatnonzero(pr_ok & rate_provided & ~prr_ok)
    ]
    obs[:, me.OB_PR_OK] = (pr_ok & ~masked).astype(float)
    obs[:, me.OB_PRR_OK] = (prr_ok & ~masked).astype(float)
    obs[~np.isfinite(obs)] = 0.0
    keep = (obs[:, me.OB_PR_OK] > 0) | (obs[:, me.OB_PRR_OK] > 0)
    t, obs = t[keep], obs[keep]
    sig_pr, sig_prr = sig_pr[keep], sig_prr[keep]
    epoch_t, first = np.unique(t, return_index=True)
    start = np.append(first, t.size).astype(np.int64)
    given = noise
    noise = ObsNoise(math.nan, math.nan, "reported")
    if not np.isfinite(sig_pr).all() and gnss.learn_fix_noise:  # none given: the log's own
        noise = learn_obs(start, obs) if given is None else given
        if math.isfinite(noise.pseudorange_sigma_m):
            learned = max(noise.pseudorange_sigma_m, gnss.pseudorange_sigma_floor_m)
            obs[:, me.OB_SIG_PR] = np.where(np.isfinite(sig_pr), obs[:, me.OB_SIG_PR], learned)
        if math.isfinite(noise.rate_sigma_mps):
            learned = max(noise.rate_sigma_mps, gnss.pseudorange_rate_sigma_floor_mps)
            obs[:, me.OB_SIG_PRR] = np.where(np.isfinite(sig_prr), obs[:, me.OB_SIG_PRR], learned)
    elif not np.isfinite(sig_pr).all():
        noise = ObsNoise(math.nan, math.nan, "default")
    events.sort(key=lambda e: e.t_ns)
    return ObsData(
        epoch_t, start, np.ascontiguousarray(obs), tuple(events), int(masked.sum()), noise
    )


def build_schedule(
    t0: int,
    t_end: int,
    step_s: float,
    fix_t: I64 | None,
    obs_t: I64 | None,
    nhc_rate_hz: float | None,
) -> I64:
    """The stops of a replay in ``(t0, t_end]``: the output grid and every update epoch.

    ``fix_t`` / ``obs_t`` are the times of the usable fixes / observation epochs (the stop
    stores their index), or None when the filter does not use them. With ``nhc_rate_hz``, NHC
    pseudo-measurements are stacked onto the GNSS epoch nearest each NHC slot (within half a
    period) and get their own stop otherwise.

    Returns:
        (S, ``STOP_COLS``) int64, sorted by time.
    """
    step_ns = round(step_s * 1e9)
    grid = t0 + step_ns * np.arange(1, (t_end - t0) // step_ns + 1, dtype=np.int64)
    times = [grid]
    for ts in (fix_t, obs_t):
        if ts is not None:
            times.append(ts[(ts > t0) & (ts <= t_end)])
    gnss_t = np.unique(np.concatenate(times[1:])) if len(times) > 1 else np.empty(0, np.int64)
    nhc_extra = np.empty(0, np.int64)
    nhc_on_gnss = np.zeros(gnss_t.size, dtype=bool)
    if nhc_rate_hz is not None:
        period = round(1e9 / nhc_rate_hz)
        slots = t0 + period * np.arange(1, (t_end - t0) // period + 1, dtype=np.int64)
        if gnss_t.size:
            j = np.clip(np.searchsorted(gnss_t, slots), 1, gnss_t.size) - 1
            j_next = np.minimum(j + 1, gnss_t.size - 1)
            pick = np.where(np.abs(gnss_t[j_next] - slots) < np.abs(gnss_t[j] - slots), j_next, j)
            near = np.abs(gnss_t[pick] - slots) <= period // 2
            nhc_on_gnss[pick[near]] = True
            nhc_extra = slots[~near]
        else:
            nhc_extra = slots
    all_t = np.unique(np.concatenate([grid, gnss_t, nhc_extra]))
    stops = np.full((all_t.size, me.STOP_COLS), -1, dtype=np.int64)
    stops[:, me.ST_T] = all_t
    stops[:, me.ST_NHC] = 0
    stops[:, me.ST_STILL] = 0  # replay.py flags the standstill (``standstill.flag_stops``)
    stops[:, me.ST_OUT] = np.isin(all_t, grid).astype(np.int64)
    for col, ts in ((me.ST_FIX, fix_t), (me.ST_OBS, obs_t)):
        if ts is None:
            continue
        idx = np.searchsorted(ts, all_t)
        hit = (idx < ts.size) & (ts[np.minimum(idx, ts.size - 1)] == all_t)
        stops[hit, col] = idx[hit]
    if nhc_rate_hz is not None:
        stops[np.isin(all_t, nhc_extra), me.ST_NHC] = 1
        stops[np.isin(all_t, gnss_t[nhc_on_gnss]), me.ST_NHC] = 1
    return stops


def max_rows(stops: I64, obs_start: I64, coupling_tight: bool) -> int:
    """Most measurement rows one stop can carry (sizes the kernels' work arrays)."""
    sats = int(np.max(np.diff(obs_start))) if coupling_tight and obs_start.size > 1 else 0
    return 6 + 2 * sats + 2 + 6  # fix, satellites, NHC, standstill


def interpolate_input(t_ns: I64, data: F64, t: int) -> tuple[int, F64]:
    """Index of the first sample later than ``t`` and the input interpolated at ``t``."""
    i = int(np.searchsorted(t_ns, t, side="right"))
    if i == 0:
        return 0, data[0].copy()
    if i >= t_ns.size:
        return i, data[-1].copy()
    a = (t - t_ns[i - 1]) / (t_ns[i] - t_ns[i - 1])
    return i, data[i - 1] + a * (data[i] - data[i - 1])
