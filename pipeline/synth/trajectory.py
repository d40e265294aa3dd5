"""Land-vehicle trajectories: on the path exactly, and the body's own motion on its wheels.

A drive is a list of ``Leg`` (straights with optional hills, turns, stops) turned into three
C2 profiles of time (``pipeline.synth.profile``): signed speed along the body x axis ``v``
(negative: reversing), yaw rate ``r`` and road grade ``g`` (tan of the pitch). A drive starts
at rest or, for a rolling start, already at ``start_speed_mps``. From them, exactly:

- heading ``psi = psi0 + int r dt``; pitch ``theta = atan(g)``; roll ``phi = -k v r`` (the body
  leans out of a turn by ``k`` rad per m/s^2 of lateral acceleration);
- NED velocity ``v_n = [v cos psi, v sin psi, -g v]``, so the velocity lies along body x: the
  lateral and vertical body velocities are zero (non-holonomic constraint); reversing
  (``v < 0``), the course is the heading plus 180 deg;
- ``v_dot^n`` and the body rate w.r.t. NED ``w_nb^b`` (ZYX Euler kinematics) analytically;
- latitude, longitude and height by Simpson's rule on the 2x-rate grid (paper 001 eq. 1).

That is the idealised car, which obeys the non-holonomic constraint exactly. A real one does
not (``Body``): its tyres slip sideways in turns, so the body points into the turn by a sideslip
angle ``beta = k_beta v r`` (rad per m/s^2 of lateral acceleration; the lateral body velocity is
``-v sin beta``); its suspension pitches it by ``k_p v_dot`` (squat accelerating, dive braking);
and the road's roughness heaves it, a sum of sinusoids in the distance travelled, whose
amplitudes follow the road-profile spectrum's ``n^-2`` law, over wavelengths of 8-60 m (the
shorter ones the suspension absorbs: it passes to the body little above 1.5 Hz). All three
enter the attitude, velocity and rates analytically, so the IMU readings stay exact.

``imu_from_motion`` (``pipeline.nav.mechanization``) then gives the exact IMU readings.
Positive turn angles are to the right (clockwise seen from above, yaw increasing), whichever
way the car rolls. Between a forward and a reversing leg a drive needs a ``stop`` (a car comes
to rest before it changes direction; the profiles alone would pass through zero speed).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal, NamedTuple

import numpy as np

from navreplay.ingest.typed import FieldError
from navreplay.pipeline.nav.earth import E2, F64, A
from navreplay.pipeline.synth.profile import PEAK_SLOPE_FACTOR, ProfileBuilder

# scipy.interpolate takes most of a second to import, and params reads Leg from here
if TYPE_CHECKING:
    from scipy.interpolate import PPoly

MIN_RAMP_S = 3.0


@dataclass(frozen=True)
class Leg:
    """One piece of a drive.

    Attributes:
        kind: ``straight`` (hold ``speed_mps`` for ``duration_s``, optionally over a hill),
            ``turn`` (turn by ``angle_deg`` on radius ``radius_m`` at ``speed_mps``) or
            ``stop`` (brake to rest and wait ``duration_s``).
        speed_mps: speed along the body x axis; negative: reversing (straights and turns).
        angle_deg: heading change of a turn (positive: to the right, forwards or reversing).
        hill_m: on a straight, the height gained over its first half and lost over its second
            (negative: a dip).
    """

    kind: Literal["straight", "turn", "stop"]
    speed_mps: float = 0.0
    duration_s: float = 0.0
    angle_deg: float = 0.0
    radius_m: float = 1.0
    hill_m: float = 0.0

    def __post_init__(self) -> None:
        if self.kind != "stop" and self.speed_mps == 0.0:
            raise FieldError("speed_mps", f"a {self.kind} needs a speed (a stop is a 'stop' leg)")
        if self.duration_s < 0.0:
            raise FieldError("duration_s", "must be >= 0")
        if self.radius_m <= 0.0:
            raise FieldError("radius_m", "must be > 0")

    def mirrored(self) -> Leg:
        """The same leg with left and right exchanged."""
        return Leg(
            self.kind, self.speed_mps, self.duration_s, -self.angle_deg, self.radius_m, self.hill_m
        )


@dataclass(frozen=True)
class Limits:
    """Comfort limits that set the transition durations.

    Attributes:
        accel_mps2: peak longitudinal acceleration / deceleration.
        yaw_accel_radps2: peak yaw acceleration entering and leaving turns.
        grade_rate_ps: peak rate of change of the grade, 1/s.
    """

    accel_mps2: float
    yaw_accel_radps2: float
    grade_rate_ps: float


class Profiles(NamedTuple):
    """The C2 profiles of a drive (``scipy.interpolate.PPoly`` of time in seconds)."""

    speed: PPoly
    yaw_rate: PPoly
    grade: PPoly
    end_s: float


def build_profiles(
    legs: list[Leg],
    stationary_s: float,
    duration_s: float,
    limits: Limits,
    *,
    start_speed_mps: float = 0.0,
) -> Profiles:
    """Profiles of a drive: hold ``start_speed_mps`` (rest by default; a rolling start
    otherwise, straight ahead) for ``stationary_s``, then the legs, cycled until
    ``duration_s`` is covered."""
    if not legs:
        raise ValueError("a drive needs at least one leg")
    spd, yaw, grd = ProfileBuilder(value=start_speed_mps), ProfileBuilder(), ProfileBuilder()

    def hold(dt: float) -> None:
        for b in (spd, yaw, grd):
            b.hold(dt)

    def speed_to(v: float) -> None:
        if abs(v - spd.value) < 1e-12:
            return
        dt = max(MIN_RAMP_S, PEAK_SLOPE_FACTOR * abs(v - spd.value) / limits.accel_mps2)
        spd.ramp(v, dt)
        yaw.hold(dt)
        grd.hold(dt)

    hold(stationary_s)
    k = 0
    while spd.t < duration_s:
        leg = legs[k % len(legs)]
        k += 1
        if leg.kind == "stop":
            speed_to(0.0)
            hold(leg.duration_s)
        elif leg.kind == "straight":
            speed_to(leg.speed_mps)
            _straight(spd, yaw, grd, leg, limits)
        else:
            speed_to(leg.speed_mps)
            _turn(spd, yaw, grd, leg, limits)
    end = spd.t
    return Profiles(spd.build(end), yaw.build(end), grd.build(end), end)


def _straight(
    spd: ProfileBuilder, yaw: ProfileBuilder, grd: ProfileBuilder, leg: Leg, limits: Limits
) -> None:
    half = leg.duration_s / 2.0
    if leg.hill_m == 0.0 or half <= 0.0:
        for b in (spd, yaw, grd):
            b.hold(leg.duration_s)
        return
    # each half: grade ramps up over a quarter, holds half, ramps down over a quarter, so the
    # height change is v * g * 3/4 * half
    g = leg.hill_m / (leg.speed_mps * 0.75 * half)
    ramp = max(half / 4.0, PEAK_SLOPE_FACTOR * abs(g) / limits.grade_rate_ps)
    if ramp > half / 4.0:
        raise ValueError(f"hill of {leg.hill_m} m too steep for a {leg.duration_s} s straight")
    for sign in (1.0, -1.0):
        grd.ramp(sign * g, ramp)
        grd.hold(half / 2.0)
        grd.ramp(0.0, ramp)
    spd.hold(leg.duration_s)
    yaw.hold(leg.duration_s)


def _turn(
    spd: ProfileBuilder, yaw: ProfileBuilder, grd: ProfileBuilder, leg: Leg, limits: Limits
) -> None:
    r = math.copysign(abs(leg.speed_mps) / leg.radius_m, leg.angle_deg)
    angle = math.radians(abs(leg.angle_deg))
    ramp = max(MIN_RAMP_S, PEAK_SLOPE_FACTOR * abs(r) / limits.yaw_accel_radps2)
    # the two ramps together turn by |r| * ramp
    if abs(r) * ramp > angle:
        ramp = angle / abs(r)
    steady = (angle - abs(r) * ramp) / abs(r)
    yaw.ramp(r, ramp)
    yaw.hold(steady)
    yaw.ramp(0.0, ramp)
    total = 2.0 * ramp + steady
    spd.hold(total)
    grd.hold(total)


#: the sinusoids of a road profile (``Body.road``)
ROAD_COMPONENTS = 16


@dataclass(frozen=True)
class Body:
    """How the body moves on its wheels, beyond the path (module doc).

    Attributes:
        roll_per_lat_acc: body roll out of a turn, rad per m/s^2 of lateral acceleration.
        sideslip_per_lat_acc: sideslip angle (body x into the turn from the velocity), rad per
            m/s^2 of lateral acceleration (0.003-0.01 for passenger cars).
        pitch_per_long_acc: suspension pitch, nose up when accelerating, rad per m/s^2.
        road_rms_m: RMS of the road's height profile over 8-60 m wavelengths, as the body
            follows it (a few mm on a smooth road, 1-2 cm on a poor one); 0 for a flat road.
        road_seed: the road profile's random phases.
    """

    roll_per_lat_acc: float = 0.0
    sideslip_per_lat_acc: float = 0.0
    pitch_per_long_acc: float = 0.0
    road_rms_m: float = 0.0
    road_seed: int = 0

    def road(self) -> tuple[F64, F64, F64]:
        """The road's sinusoids: amplitudes (m), wavenumbers (rad/m) and phases (rad)."""
        lam = np.geomspace(8.0, 60.0, ROAD_COMPONENTS)
        k = 2.0 * np.pi / lam
        # a spectrum G(n) ~ n^-2 over log-spaced bands (width ~ n): each band's variance ~ 1/n
        amp = np.sqrt(lam)
        amp *= self.road_rms_m / np.sqrt(0.5 * np.sum(amp * amp))
        phase = np.random.default_rng(self.road_seed).uniform(0.0, 2.0 * np.pi, lam.size)
        return amp, k, phase


class Motion(NamedTuple):
    """A trajectory sampled on a uniform grid (N samples).

    Attributes:
        t_s: time since the start, s, (N,).
        lat_rad, lon_rad, h_m: geodetic position of the body (IMU) origin, (N,).
        vel_ned_mps: velocity, (N, 3).
        vdot_ned_mps2: time derivative of the NED velocity components, (N, 3).
        rpy_rad: roll, pitch, yaw, (N, 3).
        w_nb_b_radps: body rate w.r.t. NED in body FRD, (N, 3).
        q_wxyz: attitude quaternion body FRD -> NED, (N, 4).
    """

    t_s: F64
    lat_rad: F64
    lon_rad: F64
    h_m: F64
    vel_ned_mps: F64
    vdot_ned_mps2: F64
    rpy_rad: F64
    w_nb_b_radps: F64
    q_wxyz: F64


def sample(
    profiles: Profiles,
    *,
    rate_hz: int,
    duration_s: float,
    lat0_rad: float,
    lon0_rad: float,
    h0_m: float,
    yaw0_rad: float,
    body: Body,
) -> Motion:
    """Sample the drive at ``rate_hz`` over ``[0, duration_s]`` (N = duration*rate + 1)."""
    n = round(duration_s * rate_hz) + 1
    t2 = np.arange(2 * n - 1, dtype=np.float64) / (2 * rate_hz)  # the grid and its midpoints
    sp, yr, gr = profiles.speed, profiles.yaw_rate, profiles.grade
    v, vdot, vddot = sp(t2), sp.derivative()(t2), sp.derivative(2)(t2)
    r, rdot = yr(t2), yr.derivative()(t2)
    g, gdot = gr(t2), gr.derivative()(t2)
    psi = yaw0_rad + yr.antiderivative()(t2)
    cpsi, spsi = np.cos(psi), np.sin(psi)
    zdot, zddot = _heave(body, sp.antiderivative()(t2), v, vdot)  # the road lifts the body
    vel = np.stack([v * cpsi, v * spsi, -g * v - zdot], axis=-1)
    lat, lon, h = integrate_geodetic(lat0_rad, lon0_rad, h0_m, vel, 1.0 / rate_hz)
    s = slice(0, None, 2)
    vdot_n = np.stack(
        [
            vdot * cpsi - v * spsi * r,
            vdot * spsi + v * cpsi * r,
            -(gdot * v + g * vdot) - zddot,
        ],
        axis=-1,
    )[s]
    theta = np.arctan(g) + body.pitch_per_long_acc * vdot
    thetadot = gdot / (1.0 + g * g) + body.pitch_per_long_acc * vddot
    phi = -body.roll_per_lat_acc * v * r
    phidot = -body.roll_per_lat_acc * (vdot * r + v * rdot)
    yaw = psi + body.sideslip_per_lat_acc * v * r  # the body points into the turn
    yawdot = r + body.sideslip_per_lat_acc * (vdot * r + v * rdot)
    sph, cph, sth, cth = np.sin(phi), np.cos(phi), np.sin(theta), np.cos(theta)
    w_nb = np.stack(
        [
            phidot - yawdot * sth,
            thetadot * cph + yawdot * cth * sph,
            -thetadot * sph + yawdot * cth * cph,
        ],
        axis=-1,
    )[s]
    rpy = np.stack([phi, theta, np.arctan2(np.sin(yaw), np.cos(yaw))], axis=-1)[s]
    return Motion(t2[s], lat, lon, h, vel[s], vdot_n, rpy, w_nb, quats_from_rpy(rpy))


def _heave(body: Body, dist: F64, v: F64, vdot: F64) -> tuple[F64, F64]:
    """The rate and acceleration of the road's lift of the body (up), at distance ``dist``
    along the path travelled at speed ``v`` (signed)."""
    if body.road_rms_m == 0.0:
        return np.zeros_like(v), np.zeros_like(v)
    amp, k, phase = body.road()
    arg = np.outer(dist, k) + phase
    slope = np.cos(arg) @ (amp * k)  # dz/ds
    curve = -(np.sin(arg) @ (amp * k * k))  # d2z/ds2
    return slope * v, curve * v * v + slope * vdot


def quats_from_rpy(rpy: F64) -> F64:
    """q_wxyz of C_b^n = Rz(yaw) Ry(pitch) Rx(roll) for every row, scalar part >= 0."""
    cr, sr = np.cos(rpy[:, 0] / 2), np.sin(rpy[:, 0] / 2)
    cp, sp = np.cos(rpy[:, 1] / 2), np.sin(rpy[:, 1] / 2)
    cy, sy = np.cos(rpy[:, 2] / 2), np.sin(rpy[:, 2] / 2)
    q = np.stack(
        [
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        ],
        axis=-1,
    )
    return np.asarray(q * np.where(q[:, :1] < 0.0, -1.0, 1.0), dtype=np.float64)


def _simpson(f2: F64, dt: float) -> F64:
    """Cumulative integral at the grid points of samples given on the grid and its midpoints."""
    steps = dt / 6.0 * (f2[:-1:2] + 4.0 * f2[1::2] + f2[2::2])
    return np.concatenate(([0.0], np.cumsum(steps)))


def integrate_geodetic(
    lat0: float, lon0: float, h0: float, vel2: F64, dt: float
) -> tuple[F64, F64, F64]:
    """Paper 001 eq. 1 integrated with Simpson's rule on the grid and its midpoints.

    The radii of curvature depend on the latitude being integrated; three fixed-point passes
    (each shrinking the error by ~1e-5, the relative change of the radii over the drive)
    converge far below a micrometre.

    Args:
        lat0, lon0, h0: the start (rad, m).
        vel2: NED velocity on the grid and its midpoints, (2N - 1, 3).
        dt: the grid step, s.

    Returns:
        latitude, longitude and height on the grid, (N,) each.
    """
    h = h0 - _simpson(vel2[:, 2], dt)
    h2 = np.empty(vel2.shape[0])  # heights on the grid and (interpolated, for the radii) between
    h2[::2] = h
    h2[1::2] = 0.5 * (h[:-1] + h[1:])
    lat = np.full(h.shape, lat0)
    lat2 = np.full(vel2.shape[0], lat0)
    for _ in range(3):
        s = np.sin(lat2)
        w = np.sqrt(1.0 - E2 * s * s)
        rn = A / w
        rm = rn * (1.0 - E2) / (w * w)
        lat = lat0 + _simpson(vel2[:, 0] / (rm + h2), dt)
        lat2[::2] = lat
        lat2[1::2] = 0.5 * (lat[:-1] + lat[1:])
    lon = lon0 + _simpson(vel2[:, 1] / ((rn + h2) * np.cos(lat2)), dt)
    return lat, lon, h
