"""Initialization and coarse alignment of the INS/GNSS filters (explicit and reported).

The filter starts at the first GNSS epoch of a segment whose horizontal speed reaches
``init.align_speed_mps`` and ``init.align_sigmas`` times its own 1-sigma there and at the
next ``init.align_epochs - 1`` epochs (a low-cost gyro cannot find north by gyrocompassing; a
land vehicle moves along its body x axis). The speed's sigma is the receiver's speed accuracy
where it reports a velocity, else the fixes' horizontal accuracy propagated through the
difference of the neighbouring fixes: at standstill, 1.5 m fixes a second apart difference to
~2 m/s of noise, which must not become a heading. The confirming epochs lie after the start
(this is a replay, the whole log is known), so a vehicle that keeps moving starts where it
would without them:

- heading: ``atan2(v_e, v_n)`` of the GNSS velocity (a reversing vehicle would be 180 deg
  off; the yaw 1-sigma of ``init`` must cover sideslip), its 1-sigma at least the angle the
  speed's noise subtends; a vehicle never fast enough for that, whose heading neither motion
  nor a compass gives, starts from the course of fixes differenced over a longer baseline
  (``_slow_course``: a robot at 1 m/s with 1 m fixes needs 9-20 s);
- roll and pitch: from the specific force averaged over +-0.25 s, corrected by the
  acceleration seen in the GNSS velocity: ``f^b = C_n^b (a^n - g^n)`` solved for pitch and
  roll at the known heading (static levelling when the vehicle is at rest);
- position and velocity: the GNSS antenna moved back by the lever arm; without fixes, a
  single-point solution (``ingest.gnss.spp``) from the pseudoranges and rates;
- gyro bias: the mean angular rate over the last static window before the start (at least
  ``init.static_window_s``) minus the earth rate; zero without a static window;
- clock (tight coupling): medians of the pseudorange and rate residuals at the start.

The covariance ``P0`` (error coordinates of ``models.ins``) takes the 1-sigma values of
``init`` (position at least the receiver's accuracy) and the IMU noise model's bias sigmas.
"""

from __future__ import annotations

import datetime as dt
import logging
import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from navreplay.ingest.config import ImuNoise
from navreplay.ingest.gnss import spp
from navreplay.ingest.timebase import gps_to_utc_ns
from navreplay.pipeline.estimation.ins import heading, magheading
from navreplay.pipeline.estimation.ins.config import InitParams
from navreplay.pipeline.estimation.ins.inputs import FixData, ImuData, MagData, ObsData
from navreplay.pipeline.estimation.ins.models import ins
from navreplay.pipeline.estimation.ins.models import measurement as me
from navreplay.pipeline.estimation.ins.models.gnss import AN_DIM, AN_RE, AN_VE, antenna
from navreplay.pipeline.nav.earth import F64, OMEGA_IE, ecef_to_geodetic, gravity, radii

log = logging.getLogger(__name__)

#: 1-sigma of a single-point velocity from Doppler, m/s (a few cm/s per rate, DOP ~2).
SPP_SPEED_SIGMA_MPS = 0.2
#: platforms (``ingest.platform``) whose GNSS course gives the heading once they move; the
#: others (multirotor, VTOL) take it from motion
COURSE_IS_HEADING = ("ground", "fixed_wing", "unknown")
#: the specific force at the start is averaged over +-0.25 s (a GNSS epoch needs that much IMU)
_HALF_NS = 250_000_000
#: the compass heading averages the field over +-1 s of the start
_COMPASS_HALF_NS = 1_000_000_000
#: 2000-01-01 in GPS nanoseconds: earlier times are a boot clock, not a date
_GPS_2000_NS = 630_720_013_000_000_000
#: GNSS speeds above this (and 3 sigma of their noise) are not at rest, m/s
_REST_SPEED_MPS = 0.3
#: a velocity differenced from fixes spans this many fixes on each side (the one whose speed
#: stands further out of its noise: two at 1 Hz in an acceleration from rest)
_DIFFERENCE_SPANS = (1, 2)
#: the longest baseline of fixes differenced for a slow vehicle's course (``_slow_course``), s
_SLOW_BASELINE_MAX_S = 20.0
#: floor on the yaw 1-sigma of a heading from motion (the attitude filter's own errors), rad
_MIN_MOTION_YAW_SIGMA = math.radians(1.0)
#: what a gyro bias measured at rest may still be off by in motion (g-sensitivity, vibration
#: rectification of MEMS gyros: ~0.05 deg/s), rad/s
_STATIC_BIAS_SHIFT_RADPS = 0.001


@dataclass(frozen=True)
class Alignment:
    """Where and how a segment's filter starts.

    Attributes:
        t_ns: start time.
        x0: initial full state (18,).
        P0: initial error covariance (n, n).
        method: ``gnss_velocity`` (+ ``static_gyro_bias`` when a static window was used).
        speed_mps: GNSS horizontal speed at the start.
        static_window_s: duration of the static window used for the gyro bias (0 if none).
    """

    t_ns: int
    x0: F64
    P0: F64
    method: str
    speed_mps: float
    static_window_s: float

    def summary(self) -> dict[str, object]:
        q = self.x0[ins.X_Q : ins.X_Q + 4]
        yaw, pitch, roll = Rotation.from_quat(q[[1, 2, 3, 0]]).as_euler("ZYX")
        return {
            "t_ns": self.t_ns,
            "method": self.method,
            "speed_mps": self.speed_mps,
            "static_window_s": self.static_window_s,
            "lat_deg": math.degrees(self.x0[ins.X_LAT]),
            "lon_deg": math.degrees(self.x0[ins.X_LON]),
            "alt_m": float(self.x0[ins.X_H]),
            "roll_rad": float(roll),
            "pitch_rad": float(pitch),
            "yaw_rad": float(yaw),
        }


@dataclass(frozen=True)
class _Track:
    t_ns: np.ndarray
    llh: np.ndarray  # antenna lat, lon (rad), h (m)
    vel: np.ndarray  # NED m/s (NaN where unknown)
    sig_speed: np.ndarray  # 1-sigma of the horizontal speed, m/s
    differenced: np.ndarray  # the velocity is differenced from neighbouring fixes
    sig_h: np.ndarray
    sig_v: np.ndarray
    clock: np.ndarray  # (K, 2) clock bias, drift from SPP (NaN from fixes)
    raw_sig_h: np.ndarray  # the fixes' own horizontal 1-sigma (sig_h: inflated for correlation)


def _spp(rows: F64) -> tuple[F64, float, F64, float] | None:
    """Single-point position and velocity of one epoch's ``obs`` rows (``ingest.gnss.spp``).

    Returns:
        (ECEF position m, clock bias m, ECEF velocity m/s, clock drift m/s), or None with
        fewer than four usable pseudoranges; the velocity is NaN with fewer than four rates.
    """
    pr = rows[rows[:, me.OB_PR_OK] > 0]
    if pr.shape[0] < 4:
        return None
    sat = np.ascontiguousarray(pr[:, me.OB_SAT : me.OB_SAT + 3])
    w = 1.0 / np.square(pr[:, me.OB_SIG_PR])
    x, _, _, ok = spp.solve_position(sat, pr[:, me.OB_PR].copy(), w, np.zeros(4), 20, 1e-4)
    if not ok:
        return None
    rr = rows[rows[:, me.OB_PRR_OK] > 0]
    v = np.full(4, math.nan)
    if rr.shape[0] >= 4:
        v, _ = spp.solve_velocity(
            np.ascontiguousarray(rr[:, me.OB_SAT : me.OB_SAT + 3]),
            np.ascontiguousarray(rr[:, me.OB_SAT + 3 : me.OB_SAT + 6]),
            rr[:, me.OB_PRR].copy(),
            1.0 / np.square(rr[:, me.OB_SIG_PRR]),
            x[:3].copy(),
        )
    return x[:3], float(x[3]), v[:3], float(v[3])


def _track_from_fixes(fixes: FixData) -> _Track | None:
    f = fixes.fix[fixes.usable & (fixes.fix[:, me.FX_POS_DIM] > 0)]
    t = fixes.t_ns[fixes.usable & (fixes.fix[:, me.FX_POS_DIM] > 0)]
    if t.size < 2:
        return None
    llh = f[:, [me.FX_LAT, me.FX_LON, me.FX_ALT]]
    vel = np.where(f[:, [me.FX_VEL_DIM]] > 0, f[:, me.FX_VN : me.FX_VN + 3], math.nan)
    vel[f[:, me.FX_VEL_DIM] == 2, 2] = 0.0  # no vertical velocity given: assume level
    # where the receiver gives no velocity, difference the neighbouring positions
    ned = _local_ned(llh)
    ts = t * 1e-9
    sig_speed = f[:, me.FX_SIG_VEL].copy()
    differenced = ~np.isfinite(vel[:, 0])
    # the fixes' own accuracy (FX_SIG_H carries the inflation for correlated errors)
    raw_sig_h = f[:, me.FX_SIG_H] / np.sqrt(f[:, me.FX_POS_INFL])
    for k in (int(j) for j in np.flatnonzero(~np.isfinite(vel[:, 0]))):
        # the neighbours one or two fixes away, whichever shows the speed over more of its
        # noise (a centred chord of a steady turn is the course at its middle)
        best = 0.0
        for m in _DIFFERENCE_SPANS:
            lo, hi = max(k - m, 0), min(k + m, int(t.size) - 1)
            if hi <= lo or ts[hi] - ts[lo] > 2.5 * m:
                continue
            v = (ned[hi] - ned[lo]) / (ts[hi] - ts[lo])
            # per axis; white fix errors (correlated ones difference to less)
            sig = math.hypot(raw_sig_h[lo], raw_sig_h[hi]) / (ts[hi] - ts[lo])
            ratio = math.hypot(v[0], v[1]) / sig
            if ratio >= best:
                best, vel[k], sig_speed[k] = ratio, v, sig
    clock = np.full((t.size, 2), math.nan)
    sig_v = f[:, me.FX_SIG_V]
    return _Track(t, llh, vel, sig_speed, differenced, f[:, me.FX_SIG_H], sig_v, clock, raw_sig_h)


def _track_from_obs(obs: ObsData) -> _Track | None:
    ts, llh, vel, clock = [], [], [], []
    for e in range(obs.epoch_t_ns.size):
        sol = _spp(obs.obs[obs.start[e] : obs.start[e + 1]])
        if sol is None:
            continue
        r, cb, v, cd = sol
        lat, lon, h = ecef_to_geodetic(r[0], r[1], r[2])
        ts.append(obs.epoch_t_ns[e])
        llh.append((lat, lon, h))
        vel.append(_ecef_to_ned(lat, lon) @ v)
        clock.append((cb, cd))
    if len(ts) < 2:
        return None
    k = len(ts)
    return _Track(
        np.array(ts),
        np.array(llh),
        np.array(vel),
        np.full(k, SPP_SPEED_SIGMA_MPS),
        np.zeros(k, dtype=bool),
        np.full(k, 5.0),
        np.full(k, 8.0),
        np.array(clock),
        np.full(k, 5.0),
    )


def _level(f_b: F64, a_minus_g: F64, yaw: float) -> tuple[float, float]:
    """Roll and pitch with ``f_b = C_n^b (a^n - g^n)`` at heading ``yaw``."""
    cy, sy = math.cos(yaw), math.sin(yaw)
    u = np.array(
        [
            cy * a_minus_g[0] + sy * a_minus_g[1],
            -sy * a_minus_g[0] + cy * a_minus_g[1],
            a_minus_g[2],
        ]
    )
    # f_x = cos(p) u_x - sin(p) u_z  ->  p = delta - acos(f_x / rho), the branch near level
    rho = math.hypot(u[0], u[2])
    delta = math.atan2(-u[2], u[0])
    c = max(-1.0, min(1.0, f_b[0] / rho))
    cands = (delta - math.acos(c), delta + math.acos(c))
    pitch = min(cands, key=lambda p: abs(math.remainder(p, 2 * math.pi)))
    pitch = math.remainder(pitch, 2 * math.pi)
    w_y = u[1]
    w_z = math.sin(pitch) * u[0] + math.cos(pitch) * u[2]
    roll = math.remainder(math.atan2(w_z, w_y) - math.atan2(f_b[2], f_b[1]), 2 * math.pi)
    return roll, pitch


def _static_window(
    imu: ImuData,
    lo: int,
    hi: int,
    init: InitParams,
    g: float,
    *,
    last: bool = True,
    moving: np.ndarray | None = None,
) -> tuple[int, int]:
    """The last (or first) run of static samples in ``lo:hi``, as absolute sample indices
    ``(start, end)`` if it lasts ``init.static_window_s`` or more, else ``(0, 0)``. ``moving``
    (over ``lo:hi``) marks samples known not to be static (a car cruising straight passes the
    IMU's tests)."""
    f, w = imu.data[lo:hi, :3], imu.data[lo:hi, 3:]
    static = (np.abs(np.linalg.norm(f, axis=1) - g) < init.static_accel_tol_mps2) & (
        np.linalg.norm(w, axis=1) < init.static_gyro_tol_radps
    )
    if moving is not None:
        static &= ~moving
    if not static.any():
        return 0, 0
    if last:
        end = int(np.flatnonzero(static)[-1]) + 1
        start = end
        while start > 0 and static[start - 1]:
            start -= 1
    else:
        start = int(np.flatnonzero(static)[0])
        end = start
        while end < static.size and static[end]:
            end += 1
    if (imu.t_ns[lo + end - 1] - imu.t_ns[lo + start]) * 1e-9 < init.static_window_s:
        return 0, 0
    return lo + start, lo + end


def _tilt_absorbs_accel_bias(P0: F64, x0: F64, sigma_ba: float, g: float) -> None:
    """Add to ``P0`` what levelling the measured specific force leaves: the accelerometer
    bias ``b`` (body) is in it, so the tilt errors are ``att_n = (C_nb b)_e / g`` and
    ``att_e = -(C_nb b)_n / g`` (error = truth ``[-]`` estimate, rotation vector in the nav
    frame, as ``models.ins``), fully correlated with the bias errors. Without the correlation
    the velocity updates, which see only the sum, shrink both sigmas while neither error is
    observed: with a 0.5 m/s^2 bias the tilt sat 5 sigma off for a minute."""
    c = Rotation.from_quat(x0[ins.X_Q : ins.X_Q + 4][[1, 2, 3, 0]]).as_matrix()
    m = np.vstack([c[1], -c[0]]) / g  # (att_n, att_e) per unit body bias
    var = sigma_ba * sigma_ba
    a, b = ins.E_ATT, ins.E_BA
    P0[a : a + 2, a : a + 2] += var * (m @ m.T)
    P0[a : a + 2, b : b + 3] = var * m
    P0[b : b + 3, a : a + 2] = var * m.T


def _gyro_bias_sigma(noise: ImuNoise, static_s: float) -> float:
    """The gyro bias 1-sigma at the start: the prior, or where a rest of ``static_s`` measured
    the bias, what averaging the gyro noise over it leaves plus the shift a bias measured at
    rest may still see in motion (``_STATIC_BIAS_SHIFT_RADPS``), never over the prior. The
    prior covers any consumer gyro's turn-on bias; left on a measured bias, it lets noisy
    velocity innovations pull the bias, and the heading with it."""
    prior = max(noise.gyro_bias_sigma_radps, 1e-7)
    if not static_s:
        return prior
    averaged = noise.gyro_noise_radps_rthz**2 / static_s + _STATIC_BIAS_SHIFT_RADPS**2
    return min(prior, max(math.sqrt(averaged), OMEGA_IE))


def _static_gyro_bias(
    imu: ImuData, lo: int, hi: int, init: InitParams, c_bn: F64, lat: float, h: float
) -> tuple[F64, float]:
    """Gyro bias from the last static window in samples ``lo:hi`` (zero and 0 s if none)."""
    start, end = _static_window(imu, lo, hi, init, gravity(lat, h))
    if end == 0:
        return np.zeros(3), 0.0
    w_ie_n = np.array([OMEGA_IE * math.cos(lat), 0.0, -OMEGA_IE * math.sin(lat)])
    dur = (imu.t_ns[end - 1] - imu.t_ns[start]) * 1e-9
    return imu.data[start:end, 3:].mean(axis=0) - c_bn.T @ w_ie_n, float(dur)


def _initial_navigation(
    imu: ImuData,
    lo: int,
    hi: int,
    track: _Track,
    k: int,
    lever_b: F64,
    yaw: float | None = None,
    vel: F64 | None = None,
    *,
    steady: bool = False,
) -> tuple[F64, F64]:
    """Full state (biases and clock zero) at track epoch ``k``, and its C_b^n: heading from
    the GNSS velocity (or ``yaw``), roll and pitch from the specific force (less the track's
    acceleration, unless the vehicle is ``steady``: a slow one whose differenced fixes would
    make only noise of it), IMU position from the antenna's (lever arm removed), velocity the
    track's (or ``vel``)."""
    t_imu = imu.t_ns[lo:hi]
    t0 = int(track.t_ns[k])
    v = track.vel[k] if vel is None else vel
    if yaw is None:
        yaw = math.atan2(v[1], v[0])
    a_n = np.zeros(3)
    lo_k, hi_k = max(k - 1, 0), min(k + 1, track.t_ns.size - 1)
    dt = (track.t_ns[hi_k] - track.t_ns[lo_k]) * 1e-9
    finite = np.isfinite(track.vel[[lo_k, hi_k]]).all()
    if not steady and hi_k > lo_k and 0 < dt <= 2.5 and finite:
        a_n = (track.vel[hi_k] - track.vel[lo_k]) / dt
    lat, lon, h_ant = track.llh[k]
    win = (t_imu >= t0 - _HALF_NS) & (t_imu <= t0 + _HALF_NS)
    f_b = imu.data[lo:hi][win, :3].mean(axis=0)
    g_n = np.array([0.0, 0.0, gravity(lat, h_ant)])
    roll, pitch = _level(f_b, a_n - g_n, yaw)
    att = Rotation.from_euler("ZYX", [yaw, pitch, roll])
    c_bn = att.as_matrix()
    lever_n = c_bn @ lever_b
    rm, rn = radii(lat)
    x0 = np.zeros(ins.FULL_DIM)
    x0[ins.X_LAT] = lat - lever_n[0] / (rm + h_ant)
    x0[ins.X_LON] = lon - lever_n[1] / ((rn + h_ant) * math.cos(lat))
    x0[ins.X_H] = h_ant + lever_n[2]
    x0[ins.X_VEL : ins.X_VEL + 3] = v
    q = att.as_quat()[[3, 0, 1, 2]]
    x0[ins.X_Q : ins.X_Q + 4] = q if q[0] >= 0 else -q
    return x0, c_bn


def _confirmed(moving: np.ndarray, t_ns: np.ndarray, epochs: int) -> np.ndarray:
    """Epochs that are moving, as are the next ``epochs - 1`` ones, none of them more than
    2.5 s apart (a gap in the fixes breaks the run)."""
    ok = moving.copy()
    if moving.size < epochs:
        return np.zeros_like(ok)
    close = np.diff(t_ns) <= 2_500_000_000
    for j in range(1, epochs):
        nxt = np.zeros_like(ok)
        nxt[:-j] = (
            moving[j:]
            & np.all(np.lib.stride_tricks.sliding_window_view(close, j), axis=1)[: ok.size - j]
        )
        ok &= nxt
    return ok


def why_not_aligned(
    fixes: FixData | None,
    obs: ObsData | None,
    init: InitParams,
    *,
    course_is_heading: bool = True,
) -> str:
    """Why ``align`` found no start in a log: what its GNSS speed showed against the tests."""
    track = _track_from_fixes(fixes) if fixes is not None else None
    if track is None and obs is not None:
        track = _track_from_obs(obs)
    motion = (
        f"a heading from motion within {math.degrees(init.motion_yaw_sigma_max_rad):.3g} deg "
        "1-sigma (the horizontal velocity must change: a turn, a start, a stop)"
    )
    need = (
        f"a horizontal GNSS speed of at least {init.align_speed_mps:g} m/s and "
        f"{init.align_sigmas:g} times its own 1-sigma at {init.align_epochs} consecutive "
        f"epochs, or {motion}"
        if course_is_heading
        else f"{motion} (the course of this platform is not its heading)"
    )
    if track is None:
        return f"no GNSS epoch to start from (alignment needs {need})"
    speed = np.hypot(track.vel[:, 0], track.vel[:, 1])
    good = np.isfinite(speed)
    if not good.any():
        return f"no GNSS speed in the log (alignment needs {need})"
    k = int(np.nanargmax(speed / np.where(good, track.sig_speed, np.inf)))
    source = "differenced from the fixes" if track.differenced[k] else "from the receiver"
    return (
        f"alignment needs {need}; the log's best epoch had {speed[k]:.2f} m/s at "
        f"{speed[k] / track.sig_speed[k]:.1f} sigma (speed {source}, 1-sigma "
        f"{track.sig_speed[k]:.2f} m/s), fastest {np.nanmax(speed):.2f} m/s: a static or bench "
        "log, no fix, or a vehicle too slow and too steady for a heading (for a slow ground "
        "vehicle, lower filters.<name>.init.align_speed_mps)"
    )


def align(
    imu: ImuData,
    segment: tuple[int, int],
    fixes: FixData | None,
    obs: ObsData | None,
    init: InitParams,
    noise: ImuNoise,
    lever_b: F64,
    n: int,
    *,
    course_is_heading: bool = True,
    mag: MagData | None = None,
) -> Alignment | None:
    """Coarse alignment of one IMU segment (see the module docstring); None if no heading can
    be found with GNSS available.

    ``course_is_heading`` (a ground vehicle, an aeroplane, an unknown platform): the heading
    comes from the GNSS course once the vehicle moves, else (and for a multirotor always) from
    motion (``heading``) and the magnetometer (``mag``, ``magheading``), combined where both
    are there."""
    lo, hi = segment
    t_imu = imu.t_ns[lo:hi]
    track = _track_from_fixes(fixes) if fixes is not None else None
    if track is None and obs is not None:
        track = _track_from_obs(obs)
    if track is None:
        return None
    # epochs with the IMU on both sides, and samples around them (not in a gap of the IMU)
    inside = (track.t_ns - _HALF_NS >= t_imu[0]) & (track.t_ns + _HALF_NS <= t_imu[-1])
    around = np.searchsorted(t_imu, track.t_ns + _HALF_NS, "right") - np.searchsorted(
        t_imu, track.t_ns - _HALF_NS, "left"
    )
    inside &= around >= 2
    # every start consults the heading from motion: a multirotor's, a late course's, and
    # the check of a course start (reversing, an IMU not along the vehicle)
    mh = _motion_heading(imu, segment, track, inside, init, noise)
    start = _course_or_motion(track, inside, init, mh, course_is_heading)
    if start is not None and start.any():
        k = int(np.flatnonzero(start)[0])
        v = track.vel[k]
        speed = math.hypot(v[0], v[1])
        yaw_sigma = max(init.yaw_sigma_rad, math.atan2(float(track.sig_speed[k]), speed))
        yaw, yaw_sigma, method = _course_heading(track, inside, k, init, mh, yaw_sigma)
        x0, c_bn = _initial_navigation(imu, lo, hi, track, k, lever_b, yaw)
        return _finish(imu, segment, track, k, x0, c_bn, yaw_sigma, method, obs, init,
                       noise, lever_b, n)  # fmt: skip
    rows = np.flatnonzero(inside)
    if rows.size == 0:
        return None
    # the compass at the first epoch (at rest before a take-off), the motion heading's first
    # trusted epoch otherwise; both where both are there
    sig_m = mh.sigma if mh is not None else np.full(rows.size, math.inf)
    trusted = np.flatnonzero(sig_m <= init.motion_yaw_sigma_max_rad)
    compass = _compass(imu, segment, track, int(rows[0]), mag, init, lever_b)
    if compass is not None:
        j = 0
    elif trusted.size:
        j = int(trusted[0])
    else:
        return _slow_start(imu, segment, track, inside, init, mh, noise, lever_b, obs, n) \
            if course_is_heading else None  # fmt: skip
    k = int(rows[j])
    vel = track.vel[k].copy()
    if mh is not None and (track.differenced[k] or not np.isfinite(vel).all()):
        vel[:2] = mh.vel_ne[j]
        vel[2] = vel[2] if np.isfinite(vel[2]) else 0.0
    estimates: list[tuple[str, float, float]] = []
    if mh is not None and sig_m[j] <= 2.0 * init.motion_yaw_sigma_max_rad:
        estimates.append(
            ("motion_heading", mh.yaw_at(j), max(float(sig_m[j]), _MIN_MOTION_YAW_SIGMA))
        )
    if compass is not None:
        estimates.append(("magnetometer", compass.yaw_rad, compass.sigma_rad))
    method, yaw, yaw_sigma = _combine(estimates)
    x0, c_bn = _initial_navigation(imu, lo, hi, track, k, lever_b, yaw, vel)
    return _finish(imu, segment, track, k, x0, c_bn, yaw_sigma, method, obs, init,
                   noise, lever_b, n)  # fmt: skip


def _slow_start(
    imu: ImuData,
    segment: tuple[int, int],
    track: _Track,
    inside: np.ndarray,
    init: InitParams,
    mh: heading.MotionHeading | None,
    noise: ImuNoise,
    lever_b: F64,
    obs: ObsData | None,
    n: int,
) -> Alignment | None:
    """A start from the course of a vehicle too slow for ``align_speed_mps`` (the last
    resort of ``align``): the fixes differenced over a baseline long enough for the course to
    be within ``motion_yaw_sigma_max_rad`` (``_slow_course``), checked against the heading
    from motion as a course start is."""
    found = _slow_course(imu, segment, track, inside, init)
    if found is None:
        return None
    k, vel, sigma = found
    lo, hi = segment
    yaw, sigma, method = _course_heading(track, inside, k, init, mh, sigma, vel)
    method = "slow_course" if method == "gnss_velocity" else method
    x0, c_bn = _initial_navigation(imu, lo, hi, track, k, lever_b, yaw, vel, steady=True)
    return _finish(imu, segment, track, k, x0, c_bn, sigma, method, obs, init, noise, lever_b, n)


def _slow_course(
    imu: ImuData, segment: tuple[int, int], track: _Track, inside: np.ndarray, init: InitParams
) -> tuple[int, F64, float] | None:
    """(track epoch, NED velocity, course 1-sigma) of the first epoch from which a slow
    vehicle's course gives its heading, or None.

    At each epoch the fixes are differenced over the shortest centred baseline (up to
    ``_SLOW_BASELINE_MAX_S``, no gap over 2.5 s) over which the displacement is
    ``align_sigmas`` times its noise and its direction within ``motion_yaw_sigma_max_rad``
    1-sigma (white fix errors: correlated ones difference to less); the chord of a steady
    turn is the course at its middle, so the gyro's turn over the baseline must stay within
    twice that sigma. The next ``align_epochs - 1`` epochs must give a course too.
    """
    ts = track.t_ns * 1e-9
    ned = _local_ned(track.llh)
    breaks = np.concatenate([[0], np.cumsum(np.diff(ts) > 2.5)])
    tan_max = math.tan(init.motion_yaw_sigma_max_rad)
    ok = np.zeros(ts.size, dtype=bool)
    vel = np.full((ts.size, 3), math.nan)
    sig = np.full(ts.size, math.nan)
    for k in (int(j) for j in np.flatnonzero(inside)):
        for m in range(1, ts.size):
            a, b = k - m, k + m
            if (
                a < 0
                or b >= ts.size
                or ts[b] - ts[a] > _SLOW_BASELINE_MAX_S
                or breaks[b] != breaks[a]
            ):
                break
            v = (ned[b] - ned[a]) / (ts[b] - ts[a])
            speed = math.hypot(v[0], v[1])
            s = math.hypot(track.raw_sig_h[a], track.raw_sig_h[b]) / (ts[b] - ts[a])
            if speed < max(_REST_SPEED_MPS, init.align_sigmas * s) or s > speed * tan_max:
                continue
            sigma = math.atan2(s, speed)
            if abs(_turn(imu, segment, int(track.t_ns[a]), int(track.t_ns[b]))) <= 2.0 * sigma:
                ok[k], vel[k], sig[k] = True, v, max(init.yaw_sigma_rad, sigma)
            break
    start = np.flatnonzero(_confirmed(ok, track.t_ns, init.align_epochs) & inside)
    if start.size == 0:
        return None
    k = int(start[0])
    v = vel[k].copy()
    v[2] = 0.0  # a slow ground vehicle: level
    return k, v, float(sig[k])


def _turn(imu: ImuData, segment: tuple[int, int], t0: int, t1: int) -> float:
    """The IMU's turn about the vertical (the mean specific force's axis) from ``t0`` to
    ``t1``, rad (the gyro bias not removed: a few degrees over the baseline at most)."""
    lo, hi = segment
    i0 = lo + int(np.searchsorted(imu.t_ns[lo:hi], t0))
    i1 = lo + int(np.searchsorted(imu.t_ns[lo:hi], t1))
    if i1 - i0 < 2:
        return math.inf
    d = imu.data[i0:i1]
    up = -d[:, :3].mean(axis=0)
    norm = float(np.linalg.norm(up))
    if norm == 0.0:
        return math.inf
    rate = d[:, 3:] @ (up / norm)
    return float(np.sum(rate[:-1] * np.diff(imu.t_ns[i0:i1]) * 1e-9))


def _local_ned(llh: F64) -> F64:
    """Positions (lat, lon rad, h m) as north, east, down metres from the first."""
    rm, rn = np.vectorize(radii)(llh[:, 0])
    return np.column_stack(
        [
            (llh[:, 0] - llh[0, 0]) * (rm + llh[:, 2]),
            (llh[:, 1] - llh[0, 1]) * (rn + llh[:, 2]) * np.cos(llh[:, 0]),
            -(llh[:, 2] - llh[0, 2]),
        ]
    )


def _course_or_motion(
    track: _Track,
    inside: np.ndarray,
    init: InitParams,
    mh: heading.MotionHeading | None,
    course_is_heading: bool,
) -> np.ndarray | None:
    """The epochs a course start may take (None: the platform's course is not its heading,
    or the course comes late and the heading from motion ``mh`` is trusted before it)."""
    start = _course_start(track, init) & inside if course_is_heading else None
    if start is None or not start.any() or not _course_late(track, start, inside, init):
        return start
    return None if _trusted_before(mh, track, inside, start, init) else start


def _course_late(track: _Track, start: np.ndarray, inside: np.ndarray, init: InitParams) -> bool:
    """The first course start comes more than ``course_wait_s`` after the first motion GNSS
    confirms (over the rest threshold and 3 sigma of its own noise at ``align_epochs``
    consecutive epochs)."""
    moving = _confirmed(_fast(track), track.t_ns, init.align_epochs) & inside
    if not moving.any():
        return False
    t_course = track.t_ns[np.flatnonzero(start)[0]]
    t_motion = track.t_ns[np.flatnonzero(moving)[0]]
    return bool((t_course - t_motion) * 1e-9 > init.course_wait_s)


def _trusted_before(
    mh: heading.MotionHeading | None,
    track: _Track,
    inside: np.ndarray,
    start: np.ndarray,
    init: InitParams,
) -> bool:
    """The heading from motion is trusted at an epoch before the first course start."""
    if mh is None:
        return False
    rows = np.flatnonzero(inside)
    ok = rows[mh.sigma <= init.motion_yaw_sigma_max_rad]
    return bool(ok.size and track.t_ns[ok[0]] < track.t_ns[np.flatnonzero(start)[0]])


def _course_heading(
    track: _Track,
    inside: np.ndarray,
    k: int,
    init: InitParams,
    mh: heading.MotionHeading | None,
    course_sigma: float,
    vel: F64 | None = None,
) -> tuple[float, float, str]:
    """(heading, 1-sigma, method) at a course start (track epoch ``k``), checked against the
    heading from motion where that is trusted there: the course if they agree within 3 sigma;
    the course + 180 deg if the vehicle reverses (backing out of a bay faster than
    ``align_speed_mps``); the heading from motion otherwise (an IMU not mounted along the
    vehicle: its x axis is not the course). ``vel``: the velocity the course is taken from
    (default: the track's at ``k``)."""
    v = track.vel[k] if vel is None else vel
    course = math.atan2(v[1], v[0])
    j = int(np.searchsorted(np.flatnonzero(inside), k))
    if mh is None or mh.sigma[j] > init.motion_yaw_sigma_max_rad:
        return course, course_sigma, "gnss_velocity"
    sig_mh = max(float(mh.sigma[j]), _MIN_MOTION_YAW_SIGMA)
    bound = 3.0 * math.hypot(sig_mh, course_sigma)
    off = math.remainder(mh.yaw_at(j) - course, 2.0 * math.pi)
    if abs(off) <= bound:
        return course, course_sigma, "gnss_velocity"
    if abs(math.remainder(off - math.pi, 2.0 * math.pi)) <= bound:
        log.warning(
            "the vehicle reverses at its course start (the heading from motion is %.0f deg "
            "from the course): heading = course + 180 deg",
            math.degrees(off),
        )
        return math.remainder(course + math.pi, 2.0 * math.pi), course_sigma, "gnss_velocity"
    log.warning(
        "the heading from motion is %.0f deg from the course at the course start (1-sigma "
        "%.1f deg): the IMU's x axis is not along the vehicle (set imu.mounting_rpy_deg in "
        "dataset.yaml); using the heading from motion", math.degrees(off), math.degrees(sig_mh)
    )  # fmt: skip
    return mh.yaw_at(j), sig_mh, "motion_heading"


def _compass(
    imu: ImuData,
    segment: tuple[int, int],
    track: _Track,
    k: int,
    mag: MagData | None,
    init: InitParams,
    lever_b: F64,
) -> magheading.MagHeading | None:
    """The magnetometer's heading over +-1 s of track epoch ``k``, levelled with the start's
    roll and pitch; None without a magnetometer, a date on the clock (the World Magnetic Model
    needs one), or a field that passes the calibration check within the alignment's bound."""
    if mag is None:
        return None
    t0 = int(track.t_ns[k])
    if t0 < _GPS_2000_NS:  # a boot clock, not GPS time: no date for the WMM
        log.info("magnetometer not used for the heading: the log's clock is not GPS time")
        return None
    win = (mag.t_ns >= t0 - _COMPASS_HALF_NS) & (mag.t_ns <= t0 + _COMPASS_HALF_NS)
    if win.sum() < magheading.MIN_SAMPLES:
        return None
    lo, hi = segment
    x0, _ = _initial_navigation(imu, lo, hi, track, k, lever_b, 0.0, np.zeros(3))
    q = x0[[ins.X_Q + 1, ins.X_Q + 2, ins.X_Q + 3, ins.X_Q]]
    _, pitch, roll = Rotation.from_quat(q).as_euler("ZYX")
    utc_ns = int(gps_to_utc_ns(np.array([t0], dtype=np.int64))[0])
    when = dt.datetime.fromtimestamp(utc_ns * 1e-9, tz=dt.UTC)
    lat, lon, h = track.llh[k]
    got = magheading.mag_heading(
        mag.t_ns[win], np.zeros(3), mag.field[win], math.degrees(lat), math.degrees(lon),
        float(h), when, roll_pitch_rad=(float(roll), float(pitch)),
    )  # fmt: skip
    if got is None or not got.usable or got.sigma_rad > init.motion_yaw_sigma_max_rad:
        log.info("magnetometer not used for the heading: %s", got.check if got else "no field")
        return None
    return got


def _combine(estimates: list[tuple[str, float, float]]) -> tuple[str, float, float]:
    """One heading from (method, yaw, sigma) estimates: inverse-variance weighted where they
    agree within 3 sigma of their difference, else the tightest (and the disagreement
    logged)."""
    if len(estimates) == 1:
        return estimates[0]
    (m1, y1, s1), (m2, y2, s2) = estimates
    diff = math.remainder(y2 - y1, 2.0 * math.pi)
    if abs(diff) > 3.0 * math.hypot(s1, s2):
        log.warning(
            "the %s heading and the %s heading disagree by %.1f deg (1-sigma %.1f and %.1f): "
            "using the %s", m1, m2, math.degrees(diff), math.degrees(s1), math.degrees(s2),
            m1 if s1 <= s2 else m2,
        )  # fmt: skip
        return estimates[0] if s1 <= s2 else estimates[1]
    w = s1**2 / (s1**2 + s2**2)
    yaw = math.remainder(y1 + w * diff, 2.0 * math.pi)
    return f"{m1}+{m2}", yaw, 1.0 / math.sqrt(1.0 / s1**2 + 1.0 / s2**2)


def _course_start(track: _Track, init: InitParams) -> np.ndarray:
    """Epochs from which the course gives the heading: fast enough, over the speed's own noise,
    confirmed by the next epochs."""
    speed = np.hypot(track.vel[:, 0], track.vel[:, 1])
    moving = (
        np.isfinite(speed)
        & (speed >= init.align_speed_mps)
        & (speed >= init.align_sigmas * track.sig_speed)
    )
    return _confirmed(moving, track.t_ns, init.align_epochs)


def _motion_heading(
    imu: ImuData,
    segment: tuple[int, int],
    track: _Track,
    inside: np.ndarray,
    init: InitParams,
    noise: ImuNoise,
) -> heading.MotionHeading | None:
    """``heading.estimate`` over the segment's GNSS epochs, the gyros corrected by the mean rate
    of the first static window where GNSS says the vehicle is at rest (earth rate included:
    the level frame turns with the earth)."""
    lo, hi = segment
    if inside.sum() < 2:
        return None
    lat, h = float(track.llh[inside][0, 0]), float(track.llh[inside][0, 2])
    moving = _gnss_moving(imu, lo, hi, track)
    s0, s1 = _static_window(imu, lo, hi, init, gravity(lat, h), last=False, moving=moving)
    bias = imu.data[s0:s1, 3:].mean(axis=0) if s1 > s0 else np.zeros(3)
    vel = np.where(track.differenced[:, None], math.nan, track.vel)
    return heading.estimate(
        imu.t_ns[lo:hi],
        imu.data[lo:hi],
        bias,
        track.t_ns[inside],
        track.llh[inside],
        vel[inside],
        track.raw_sig_h[inside],
        track.sig_speed[inside],
        init,
        noise,
    )


def _fast(track: _Track) -> np.ndarray:
    """GNSS epochs whose horizontal speed is over the rest threshold and 3 sigma of its own
    noise."""
    speed = np.hypot(track.vel[:, 0], track.vel[:, 1])
    fast: np.ndarray = np.isfinite(speed) & (
        speed > np.maximum(_REST_SPEED_MPS, 3.0 * track.sig_speed)
    )
    return fast


def _gnss_moving(imu: ImuData, lo: int, hi: int, track: _Track) -> np.ndarray:
    """IMU samples ``lo:hi`` next to a ``_fast`` GNSS epoch (a car cruising straight passes
    the IMU's static tests)."""
    return np.asarray(np.interp(imu.t_ns[lo:hi], track.t_ns, _fast(track).astype(float)) > 0.0)


def _finish(
    imu: ImuData,
    segment: tuple[int, int],
    track: _Track,
    k: int,
    x0: F64,
    c_bn: F64,
    yaw_sigma: float,
    method: str,
    obs: ObsData | None,
    init: InitParams,
    noise: ImuNoise,
    lever_b: F64,
    n: int,
) -> Alignment:
    """Gyro bias, clock and covariance of a start at track epoch ``k``."""
    lo, _ = segment
    t0 = int(track.t_ns[k])
    lat, h_ant = track.llh[k, 0], track.llh[k, 2]
    i_start = lo + int(np.searchsorted(imu.t_ns[lo : segment[1]], t0))
    bg, static_s = _static_gyro_bias(imu, lo, i_start, init, c_bn, lat, h_ant)
    if not static_s:  # a start at rest (a heading from motion): the rest that follows it
        i_rest = min(segment[1], i_start + int(np.searchsorted(imu.t_ns[i_start:], t0 + 60e9)))
        moving = _gnss_moving(imu, i_start, i_rest, track)
        start, end = _static_window(
            imu, i_start, i_rest, init, gravity(lat, h_ant), last=False, moving=moving
        )
        if end and imu.t_ns[start] - t0 < _HALF_NS:
            bg, static_s = _static_gyro_bias(imu, start, end, init, c_bn, lat, h_ant)
    x0[ins.X_BG : ins.X_BG + 3] = bg
    if n > ins.N_LOOSE:
        x0[ins.X_CB], x0[ins.X_CD] = _clock(x0, obs, t0, lever_b, track.clock[k])
    sig_h = max(init.pos_sigma_m, float(track.sig_h[k]))
    sig_v = max(init.pos_sigma_m, float(track.sig_v[k]))
    d = [sig_h, sig_h, sig_v] + [init.vel_sigma_mps] * 3
    d += [init.roll_pitch_sigma_rad] * 2 + [yaw_sigma]
    d += [max(noise.accel_bias_sigma_mps2, 1e-6)] * 3
    d += [_gyro_bias_sigma(noise, static_s)] * 3
    d += [init.clock_bias_sigma_m, init.clock_drift_sigma_mps]
    P0 = np.diag(np.square(d[:n]))
    _tilt_absorbs_accel_bias(P0, x0, noise.accel_bias_sigma_mps2, gravity(lat, h_ant))
    method += "+static_gyro_bias" if static_s else ""
    speed = math.hypot(x0[ins.X_VEL], x0[ins.X_VEL + 1])
    log.info("aligned at t=%d ns: %s, speed %.1f m/s, yaw sigma %.1f deg", t0, method, speed,
             math.degrees(yaw_sigma))  # fmt: skip
    return Alignment(t0, x0, P0, method, speed, static_s)


def _clock(
    x0: F64, obs: ObsData | None, t0: int, lever_b: F64, spp_clock: F64
) -> tuple[float, float]:
    """Clock bias and drift at the start: medians of the residuals of the nearest epoch."""
    if obs is None or obs.epoch_t_ns.size == 0:
        return 0.0, 0.0
    e = min(int(np.searchsorted(obs.epoch_t_ns, t0)), obs.epoch_t_ns.size - 1)
    rows = obs.obs[obs.start[e] : obs.start[e + 1]]
    ant = np.empty(AN_DIM)
    antenna(x0, lever_b, np.zeros(3), np.empty((3, 3)), ant)
    r_ant, v_ant = ant[AN_RE : AN_RE + 3], ant[AN_VE : AN_VE + 3]
    pr = rows[rows[:, me.OB_PR_OK] > 0]
    if pr.shape[0] == 0:
        return (
            (float(spp_clock[0]), float(spp_clock[1]))
            if np.isfinite(spp_clock).all()
            else (
                0.0,
                0.0,
            )
        )
    d = pr[:, me.OB_SAT : me.OB_SAT + 3] - r_ant
    cb = float(np.median(pr[:, me.OB_PR] - np.linalg.norm(d, axis=1)))
    rr = rows[rows[:, me.OB_PRR_OK] > 0]
    cd = 0.0
    if rr.shape[0]:
        d = rr[:, me.OB_SAT : me.OB_SAT + 3] - r_ant
        e_u = d / np.linalg.norm(d, axis=1)[:, None]
        pred = np.sum(e_u * (rr[:, me.OB_SAT + 3 : me.OB_SAT + 6] - v_ant), axis=1)
        cd = float(np.median(rr[:, me.OB_PRR] - pred))
    return cb, cd


def _ecef_to_ned(lat: float, lon: float) -> F64:
    """C_e^n at (lat, lon) (numpy; the kernels have their own)."""
    sl, cl, so, co = math.sin(lat), math.cos(lat), math.sin(lon), math.cos(lon)
    return np.array([[-sl * co, -sl * so, cl], [-so, co, 0.0], [-cl * co, -cl * so, -sl]])
