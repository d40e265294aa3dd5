"""Heading from motion: the rotation that maps the IMU's horizontal velocity changes onto the
GNSS track's, for a vehicle whose course is not its heading (a multirotor flying sideways) or
one too slow for a heading from its course.

A tilt-only attitude filter (``_ahrs``: the gyros integrated, roll and pitch pulled towards the
specific force with time constant ``init.tilt_tau_s``, heading free) carries the specific force
into a level frame whose heading is arbitrary but fixed: the true attitude is that frame turned
about the vertical by an unknown angle ``psi0`` (slowly wandering with the gyro's bias). Over
each interval between GNSS epochs the horizontal specific force integrates to a velocity change
``D`` and a position change ``E`` in that frame, so that, with ``u = (cos psi0, sin psi0)``
and ``M(d) = [[d_x, -d_y], [d_y, d_x]]``,

    v_k+1 = v_k + M(D_k) u + T c,       p_k+1 = p_k + T v_k + M(E_k) u + T^2/2 c,

where ``c`` is a slowly varying horizontal acceleration error (the attitude filter's tilt
error, accelerometer bias). Every term is linear in the state ``(p, v, u, c)`` (north, east
each): a linear Kalman filter over the GNSS epochs, smoothed backwards (Rauch-Tung-Striebel),
gives ``psi0`` and its 1-sigma at every epoch, and the heading at any time is
``psi0 + yaw_frame(t)``. No hypothesis bank is needed: with the rotation written as the
unconstrained 2-vector ``u`` the problem has one solution and no linearization error; ``|u|``
near 1 checks the fit (an IMU that does not match the GNSS track gives anything else).

The heading is observable only where the horizontal velocity changes (a vehicle that never
accelerates has none); the sigma says how well, and grows away from the manoeuvres by the gyro
drift the filter admits (``noise.gyro_bias_sigma_radps`` over ``init.drift_horizon_s``). This
is a replay: the smoothed heading at take-off uses the manoeuvres after it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from navreplay.ingest.config import ImuNoise
from navreplay.pipeline._jit import njit
from navreplay.pipeline.estimation.ins.config import InitParams
from navreplay.pipeline.nav.earth import F64, gravity, radii

#: chi-square gate of a GNSS update of the heading filter (4 dof at 1e-4)
_GATE = 23.5
#: random walk of the horizontal acceleration error c, (m/s^2)^2/s
_Q_C = 0.01**2
#: state layout
_P, _V, _U, _C = 0, 2, 4, 6
#: |u| must lie within this factor of 1 for a heading to be trusted
_SCALE_TOL = 0.25


@dataclass(frozen=True)
class MotionHeading:
    """The heading-from-motion solution at the GNSS epochs of one segment.

    Attributes:
        t_ns: the epochs (K,).
        psi0: heading of the level frame, rad (K,): true heading = ``psi0 + yaw_frame``.
        sigma: 1-sigma of ``psi0``, rad (K,) (inf where the fit is not trusted).
        vel_ne: smoothed horizontal velocity of the antenna, m/s (K, 2).
        scale: ``|u|`` (K,), ~1 where the IMU and the track agree.
        frame_t_ns, frame_yaw: the attitude filter's own heading at the IMU samples.
    """

    t_ns: np.ndarray
    psi0: F64
    sigma: F64
    vel_ne: F64
    scale: F64
    frame_t_ns: np.ndarray
    frame_yaw: F64

    def yaw_at(self, k: int) -> float:
        """True heading at epoch ``k`` (rad, wrapped to (-pi, pi])."""
        j = min(int(np.searchsorted(self.frame_t_ns, self.t_ns[k])), self.frame_t_ns.size - 1)
        return math.remainder(float(self.psi0[k] + self.frame_yaw[j]), 2.0 * math.pi)


@njit(cache=True)
def _ahrs(dt: F64, f: F64, w: F64, bias: F64, gain: float, g: float, q0: F64) -> tuple[F64, F64]:
    """Tilt filter: (horizontal specific force in the level frame (N, 2), its heading (N,)).

    Gyro rates (minus ``bias``) integrated as body increments; roll and pitch pulled towards
    the measured specific force (``e = f_hat x C^T (0, 0, -1)``, weight falling to zero when
    ``|f|`` is 2 m/s^2 away from gravity). ``q0``: w, x, y, z of the start.
    """
    n = f.shape[0]
    fa = np.empty((n, 2))
    yaw = np.empty(n)
    qw, qx, qy, qz = q0[0], q0[1], q0[2], q0[3]
    for i in range(n):
        c00 = 1 - 2 * (qy * qy + qz * qz)
        c01 = 2 * (qx * qy - qw * qz)
        c02 = 2 * (qx * qz + qw * qy)
        c10 = 2 * (qx * qy + qw * qz)
        c11 = 1 - 2 * (qx * qx + qz * qz)
        c12 = 2 * (qy * qz - qw * qx)
        c20 = 2 * (qx * qz - qw * qy)
        c21 = 2 * (qy * qz + qw * qx)
        c22 = 1 - 2 * (qx * qx + qy * qy)
        fx, fy, fz = f[i, 0], f[i, 1], f[i, 2]
        fa[i, 0] = c00 * fx + c01 * fy + c02 * fz
        fa[i, 1] = c10 * fx + c11 * fy + c12 * fz
        yaw[i] = math.atan2(c10, c00)
        wx, wy, wz = w[i, 0] - bias[0], w[i, 1] - bias[1], w[i, 2] - bias[2]
        fn = math.sqrt(fx * fx + fy * fy + fz * fz)
        if fn > 0.0:
            k = gain * max(0.0, 1.0 - abs(fn - g) / 2.0) / fn
            vx, vy, vz = -c20, -c21, -c22  # C^T (0, 0, -1): the expected direction of f
            wx += k * (fy * vz - fz * vy)
            wy += k * (fz * vx - fx * vz)
            wz += k * (fx * vy - fy * vx)
        h = 0.5 * dt[i]
        ax, ay, az = wx * h, wy * h, wz * h
        a = math.sqrt(ax * ax + ay * ay + az * az)
        s = math.sin(a) / a if a > 1e-12 else 1.0
        dw, dx, dy, dz = math.cos(a), ax * s, ay * s, az * s
        qw, qx, qy, qz = (
            qw * dw - qx * dx - qy * dy - qz * dz,
            qw * dx + qx * dw + qy * dz - qz * dy,
            qw * dy - qx * dz + qy * dw + qz * dx,
            qw * dz + qx * dy - qy * dx + qz * dw,
        )
        nq = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
        qw, qx, qy, qz = qw / nq, qx / nq, qy / nq, qz / nq
    return fa, yaw


def _level_quat(f: F64) -> F64:
    """w, x, y, z of roll and pitch from a mean specific force (heading 0)."""
    roll = math.atan2(-f[1], -f[2])
    pitch = math.atan2(f[0], math.hypot(f[1], f[2]))
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    return np.array([cr * cp, sr * cp, cr * sp, -sr * sp])


def _transition(T: float, d: F64, e: F64, q_a: float, q_u: float) -> tuple[F64, F64]:
    """F and Q of one interval of ``T`` s whose specific force integrates to the velocity
    change ``d`` and the position change ``e`` (level frame)."""
    eye2 = np.eye(2)
    F = np.eye(8)
    F[_P : _P + 2, _V : _V + 2] = T * eye2
    F[_P : _P + 2, _U : _U + 2] = _rot(e)
    F[_P : _P + 2, _C : _C + 2] = 0.5 * T * T * eye2
    F[_V : _V + 2, _U : _U + 2] = _rot(d)
    F[_V : _V + 2, _C : _C + 2] = T * eye2
    Q = np.zeros((8, 8))
    Q[_P : _P + 2, _P : _P + 2] = q_a * T**3 / 3 * eye2
    Q[_P : _P + 2, _V : _V + 2] = Q[_V : _V + 2, _P : _P + 2] = q_a * T**2 / 2 * eye2
    Q[_V : _V + 2, _V : _V + 2] = q_a * T * eye2
    Q[_U : _U + 2, _U : _U + 2] = q_u * T * eye2
    Q[_C : _C + 2, _C : _C + 2] = _Q_C * T * eye2
    return F, Q


def _measurement(pos: F64, vel: F64 | None, sig_h: float, sig_vel: float) -> tuple[F64, F64, F64]:
    """z, H, R of one GNSS epoch: the horizontal position, and the velocity where given."""
    m = 2 if vel is None else 4
    H = np.zeros((m, 8))
    H[[0, 1], [_P, _P + 1]] = 1.0
    r = [sig_h**2] * 2
    if vel is None:
        return pos, H, np.diag(r)
    H[[2, 3], [_V, _V + 1]] = 1.0
    return np.concatenate([pos, vel]), H, np.diag(r + [sig_vel**2] * 2)


def _rot(d: F64) -> F64:
    """M(d) of the module docstring."""
    return np.array([[d[0], -d[1]], [d[1], d[0]]])


def estimate(
    t_imu: np.ndarray,
    imu: F64,
    gyro_bias: F64,
    t_gnss: np.ndarray,
    llh: F64,
    vel: F64,
    sig_h: F64,
    sig_vel: F64,
    init: InitParams,
    noise: ImuNoise,
) -> MotionHeading | None:
    """Heading from motion over one segment (see the module docstring).

    The frame is levelled on gravity alone, slowly (``init.tilt_tau_s``): an acceleration
    leans it along the acceleration, which shrinks ``|u|`` but does not turn ``u``. (Levelling
    it on the GNSS acceleration instead, rotated by a first estimate of ``psi0``, would feed
    that estimate back as data: the second pass only echoes the first.)

    Args:
        t_imu, imu: the segment's IMU samples (N,), (N, 6) f_b, w_ib_b.
        gyro_bias: gyro bias to remove (a static window's, or zero), rad/s.
        t_gnss, llh, vel: GNSS epochs within the segment (K,), antenna lat, lon (rad), h (m)
            (K, 3), NED velocity (K, 3; NaN where the receiver gives none: then positions
            only).
        sig_h, sig_vel: 1-sigma of each horizontal position and velocity axis (K,).
        init: ``tilt_tau_s``, ``drift_horizon_s``.
        noise: the gyro bias sigma sets the drift of ``psi0``; the accelerometer's the
            velocity noise.

    Returns:
        The solution, or None with fewer than two GNSS epochs.
    """
    if t_gnss.size < 2 or t_imu.size < 2:
        return None
    t_s = (t_imu - t_imu[0]) * 1e-9
    dt = np.diff(t_s, prepend=t_s[0])
    tg = (t_gnss - t_imu[0]) * 1e-9
    g = gravity(float(llh[0, 0]), float(llh[0, 2]))
    n0 = max(2, int(np.searchsorted(t_s, 0.5)))
    q0 = _level_quat(imu[:n0, :3].mean(axis=0))
    rm, rn = radii(float(llh[0, 0]))
    pos = np.column_stack(
        [(llh[:, 0] - llh[0, 0]) * (rm + llh[:, 2]), (llh[:, 1] - llh[0, 1]) * (rn + llh[:, 2])
         * math.cos(llh[0, 0])]
    )  # fmt: skip
    fa, frame_yaw = _ahrs(dt, imu[:, :3], imu[:, 3:], gyro_bias, 1.0 / init.tilt_tau_s, g, q0)
    xs, Ps = _smooth(t_s, dt, fa, tg, pos, vel, sig_h, sig_vel, init, noise)
    u = xs[:, _U : _U + 2]
    psi0 = np.arctan2(u[:, 1], u[:, 0])
    scale = np.hypot(u[:, 0], u[:, 1])
    perp = np.column_stack([-np.sin(psi0), np.cos(psi0)])
    var = np.einsum("ki,kij,kj->k", perp, Ps[:, _U : _U + 2, _U : _U + 2], perp)
    sigma = np.sqrt(np.maximum(var, 0.0)) / np.maximum(scale, 1e-9)
    sigma[np.abs(scale - 1.0) > _SCALE_TOL] = math.inf
    return MotionHeading(t_gnss, psi0, sigma, xs[:, _V : _V + 2], scale, t_imu, frame_yaw)


def _smooth(
    t_s: F64,
    dt: F64,
    fa: F64,
    tg: F64,
    pos: F64,
    vel: F64,
    sig_h: F64,
    sig_vel: F64,
    init: InitParams,
    noise: ImuNoise,
) -> tuple[F64, F64]:
    """The linear filter of the module docstring over the GNSS epochs, then smoothed (RTS):
    states (K, 8) and covariances (K, 8, 8)."""
    # cumulative integrals, read at the GNSS epochs: D = S1(b) - S1(a), E = t_b D - (S2 - S2)
    s1 = np.vstack([np.zeros(2), np.cumsum(fa * dt[:, None], axis=0)])
    s2 = np.vstack([np.zeros(2), np.cumsum(fa * (dt * t_s)[:, None], axis=0)])
    idx = np.searchsorted(t_s, tg, side="right")
    have_vel = np.isfinite(vel[:, 0]) & np.isfinite(vel[:, 1])
    q_a = max(noise.accel_noise_mps2_rthz, 0.05) ** 2 + 0.1**2  # m^2/s^3: noise + tilt wander
    q_u = max(noise.gyro_bias_sigma_radps, 1e-4) ** 2 * init.drift_horizon_s  # rad^2/s
    k_n = tg.size
    x = np.zeros(8)
    P = np.diag([1.0, 1.0, 25.0, 25.0, 1.0, 1.0, 0.3**2, 0.3**2])
    x[_P : _P + 2] = pos[0]
    P[_P, _P] = P[_P + 1, _P + 1] = sig_h[0] ** 2
    if have_vel[0]:
        x[_V : _V + 2] = vel[0, :2]
        P[_V, _V] = P[_V + 1, _V + 1] = sig_vel[0] ** 2
    xf, Pf = np.empty((k_n, 8)), np.empty((k_n, 8, 8))
    xp, Pp, Fs = np.empty((k_n, 8)), np.empty((k_n, 8, 8)), np.empty((k_n, 8, 8))
    rejected = 0
    for k in range(k_n):
        if k > 0:
            a, b = idx[k - 1], idx[k]
            d = s1[b] - s1[a]
            F, Q = _transition(tg[k] - tg[k - 1], d, tg[k] * d - (s2[b] - s2[a]), q_a, q_u)
            x = F @ x
            P = F @ P @ F.T + Q
            Fs[k] = F
        xp[k], Pp[k] = x, P
        z, H, R = _measurement(pos[k], vel[k, :2] if have_vel[k] else None, sig_h[k], sig_vel[k])
        nu = z - H @ x
        S = H @ P @ H.T + R
        if k > 0 and nu @ np.linalg.solve(S, nu) > _GATE:
            rejected += 1
            if rejected < 3:
                xf[k], Pf[k] = x, P
                continue
            # a run of rejections: the track left the model; restart position and velocity
            P[_P : _V + 2, _P : _V + 2] += np.diag([100.0, 100.0, 25.0, 25.0])
            S = H @ P @ H.T + R
        rejected = 0
        K = np.linalg.solve(S, H @ P).T
        x = x + K @ nu
        P = P - K @ H @ P
        P = 0.5 * (P + P.T)
        xf[k], Pf[k] = x, P
    xs, Ps = xf.copy(), Pf.copy()
    for k in range(k_n - 2, -1, -1):
        G = np.linalg.solve(Pp[k + 1].T, Fs[k + 1] @ Pf[k].T).T  # Pf F^T Pp^-1
        xs[k] = xf[k] + G @ (xs[k + 1] - xp[k + 1])
        Ps[k] = Pf[k] + G @ (Ps[k + 1] - Pp[k + 1]) @ G.T
    return xs, Ps
