"""Synthetic GNSS receiver: clock, antenna motion, raw observables and position fixes.

The antenna sits at the lever arm ``l_b`` (body FRD) from the IMU: its position is
``r + C_b^n l_b`` and its velocity ``v^n + C_b^n (w_eb^b x l_b)`` (paper 001, eq. 7-8).

Observables of satellite i at epoch t, following ``gnss_obs`` conventions. The epoch is the
receiver's clock reading, as in a RINEX file (RINEX 3.04 section 5.7): the receiver clock runs
``b(t) / c`` ahead of GPS time, so the signals of epoch t arrived at GPS time ``t_r = t - b / c``
(83 us at the start of the default drive), and the pseudoranges carry the same ``b``:

- pseudorange ``rho = |R(w_e tau) r_i(t_r - tau) - r_ant(t_r)| + b(t) - sat_clock_m + noise``,
  the transmit time found by light-time iteration and the satellite expressed in the
  receive-time ECEF frame (``ingest.gnss.ephemeris.transmit_state``); ``r_ant(t_r)`` is the
  antenna at the epoch moved back along its velocity by ``b / c``; ``sat_clock_m`` is c times the
  broadcast clock offset with the relativistic term, less TGD;
- pseudorange rate: the exact time derivative of the noise-free geometric range (central
  difference over +-1 ms of the whole light-time solution) ``+ d(t) - sat_clock_drift_mps +
  noise``; the usual model ``e . (sat_v - v_ant)`` matches it to about 1 cm/s (the light-time
  rate terms);
- C/N0 from elevation, and noise sigmas scaled by 10^((cn0_ref - cn0) / 20).

Values are rounded as a RINEX 3 observation file stores them (pseudorange to 1 mm, Doppler
D1C = -rate / lambda_L1 to 1 mHz, C/N0 to 0.001 dB-Hz), so the file and the tables agree
exactly; the canonical rate is ``-D1C * LAMBDA_L1_M``.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from navreplay.ingest.gnss import spp
from navreplay.ingest.gnss.ephemeris import (
    C_MPS,
    LAMBDA_L1_M,
    Ephemeris,
    SatState,
    elevation_azimuth,
    select,
    transmit_state,
)
from navreplay.ingest.schema import FixType
from navreplay.pipeline.nav import earth
from navreplay.pipeline.nav.earth import F64, I64
from navreplay.pipeline.nav.rotations import quat_to_dcm
from navreplay.pipeline.synth.columns import axis_columns
from navreplay.pipeline.synth.seoul_params import ReceiverParams
from navreplay.pipeline.synth.trajectory import Motion

RATE_STEP_S = 1e-3


def receiver_clock(
    n: int, dt_s: float, params: ReceiverParams, rng: np.random.Generator, *, noisy: bool
) -> tuple[F64, F64]:
    """Receiver clock bias (m) and drift (m/s) at ``n`` samples ``dt_s`` apart.

    Two-state clock: the drift is a random walk (``q_d``), the bias integrates it plus white
    frequency noise (``q_b``); the discrete process noise is the exact integral
    ``Q = [[q_b dt + q_d dt^3/3, q_d dt^2/2], [q_d dt^2/2, q_d dt]]``.
    """
    qb = params.clock_bias_rw_m_rths**2 if noisy else 0.0
    qd = params.clock_drift_rw_mps_rths**2 if noisy else 0.0
    q = np.array(
        [[qb * dt_s + qd * dt_s**3 / 3.0, qd * dt_s**2 / 2.0], [qd * dt_s**2 / 2.0, qd * dt_s]]
    )
    w = rng.normal(0.0, 1.0, (n - 1, 2))
    if qd > 0.0 or qb > 0.0:
        w = w @ np.linalg.cholesky(q + 1e-300 * np.eye(2)).T
    else:
        w[:] = 0.0
    drift = params.clock_drift0_mps + np.concatenate(([0.0], np.cumsum(w[:, 1])))
    bias = params.clock_bias0_m + np.concatenate(([0.0], np.cumsum(drift[:-1] * dt_s + w[:, 0])))
    return bias, drift


class Antenna(NamedTuple):
    """Antenna states at the selected samples: geodetic (rad, m), ECEF (m, m/s), NED (m/s)."""

    lat_rad: F64
    lon_rad: F64
    h_m: F64
    ecef_m: F64
    vel_ecef_mps: F64
    vel_ned_mps: F64


def antenna(motion: Motion, rows: I64, lever_arm_m: F64) -> Antenna:
    """The antenna's position and velocity at samples ``rows`` of ``motion``."""
    m = rows.size
    ecef, vel_e, vel_n = np.empty((m, 3)), np.empty((m, 3)), np.empty((m, 3))
    lat, lon, h = np.empty(m), np.empty(m), np.empty(m)
    for j, i in enumerate(rows):
        la, lo, hh = motion.lat_rad[i], motion.lon_rad[i], motion.h_m[i]
        c_bn = quat_to_dcm(motion.q_wxyz[i])
        c_en = earth.dcm_ecef_to_ned(la, lo)
        w_en = earth.omega_en_n(la, hh, motion.vel_ned_mps[i, 0], motion.vel_ned_mps[i, 1])
        w_eb = motion.w_nb_b_radps[i] + c_bn.T @ w_en
        vel_n[j] = motion.vel_ned_mps[i] + c_bn @ np.cross(w_eb, lever_arm_m)
        ecef[j] = earth.geodetic_to_ecef(la, lo, hh) + c_en.T @ (c_bn @ lever_arm_m)
        vel_e[j] = c_en.T @ vel_n[j]
        lat[j], lon[j], h[j] = earth.ecef_to_geodetic(ecef[j, 0], ecef[j, 1], ecef[j, 2])
    return Antenna(lat, lon, h, ecef, vel_e, vel_n)


def _fixed3(x: F64) -> F64:
    """Round to 3 decimals exactly as ``%.3f`` prints (RINEX F14.3 fields)."""
    return np.array([float(f"{v:.3f}") for v in x], dtype=np.float64)


def observables(
    eph: Ephemeris,
    t_ns: I64,
    ant: Antenna,
    clock_bias_m: F64,
    clock_drift_mps: F64,
    params: ReceiverParams,
    rng: np.random.Generator,
    *,
    noisy: bool,
) -> dict[str, np.ndarray]:
    """Raw observables of every tracked satellite at each epoch, as ``gnss_obs`` columns.

    Rows are sorted by (t_ns, sv). Random draws cover the full epoch x PRN grid in a fixed
    order, so visibility never shifts the random stream.
    """
    prns = np.unique(eph.prn)
    n_ep, n_sv = t_ns.size, prns.size
    tt = np.repeat(t_ns, n_sv)
    pp = np.tile(prns, n_ep)
    rx = np.repeat(ant.ecef_m, n_sv, axis=0)
    rv = np.repeat(ant.vel_ecef_mps, n_sv, axis=0)
    idx = select(eph, pp, tt)
    draws = rng.normal(0.0, 1.0, (4, n_ep * n_sv))
    ok = idx >= 0
    late_s = np.repeat(-clock_bias_m / C_MPS, n_sv)  # t_r - t: the receiver clock is ahead
    rx = rx + late_s[:, None] * rv
    st = transmit_state(eph, np.where(ok, idx, 0), tt, rx, rx_offset_s=late_s)
    el, az = elevation_azimuth(rx, st.sat.pos_m)
    ok &= el >= math.radians(params.elevation_mask_deg)
    keep = np.flatnonzero(ok)
    i, t, rx, rv, draws = idx[keep], tt[keep], rx[keep], rv[keep], draws[:, keep]
    late_s = late_s[keep]
    sat, rng_m = SatState(*(f[keep] for f in st.sat)), st.range_m[keep]
    up = transmit_state(eph, i, t, rx + RATE_STEP_S * rv, rx_offset_s=late_s + RATE_STEP_S).range_m
    dn = transmit_state(eph, i, t, rx - RATE_STEP_S * rv, rx_offset_s=late_s - RATE_STEP_S).range_m
    range_rate = (up - dn) / (2.0 * RATE_STEP_S)
    epoch = np.repeat(np.arange(n_ep), n_sv)[keep]
    sat_clock_m = C_MPS * (sat.clock_s - sat.tgd_s)
    sat_drift_mps = C_MPS * sat.clock_drift_sps
    sin_el = np.sin(el[keep])
    cn0_true = params.cn0_zenith_dbhz + params.cn0_slope_db * np.log10(sin_el)
    scale = 10.0 ** ((params.cn0_ref_dbhz - cn0_true) / 20.0)
    pr_std, prr_std = params.pr_sigma_m * scale, params.prr_sigma_mps * scale
    on = 1.0 if noisy else 0.0
    pr = rng_m + clock_bias_m[epoch] - sat_clock_m + on * pr_std * draws[0]
    prr = range_rate + clock_drift_mps[epoch] - sat_drift_mps + on * prr_std * draws[1]
    doppler_hz = _fixed3(-prr / LAMBDA_L1_M)
    return {
        "t_ns": t,
        "sv": np.array([f"G{p:02d}" for p in eph.prn[i]]),
        "pseudorange_m": _fixed3(pr),
        "pseudorange_rate_mps": -doppler_hz * LAMBDA_L1_M,
        "cn0_dbhz": _fixed3(cn0_true + on * params.cn0_sigma_db * draws[2]),
        **axis_columns("sat_{}_m", sat.pos_m),
        **axis_columns("sat_v{}_mps", sat.vel_mps),
        "sat_clock_m": sat_clock_m,
        "sat_clock_drift_mps": sat_drift_mps,
        "elevation_deg": np.degrees(el[keep]),
        "azimuth_deg": np.degrees(az[keep]),
        "pseudorange_std_m": pr_std,
        "pseudorange_rate_std_mps": prr_std,
    }


def fixes(
    t_ns: I64,
    ant: Antenna,
    obs: dict[str, np.ndarray],
    params: ReceiverParams,
    rng: np.random.Generator,
    *,
    noisy: bool,
) -> dict[str, np.ndarray]:
    """Receiver position/velocity fixes at each epoch, as ``gnss`` columns.

    The reported accuracies come from the tracked geometry: per-axis sigmas
    ``UERE * sqrt(DOP^2 component)``; ``h_acc_m`` is their RMS over north and east (a per-axis
    1-sigma, as ROS drivers put on the covariance diagonal). The position error is a
    first-order Gauss-Markov process per axis (``fix_tau_s``) scaled by those sigmas; the
    velocity error is white. With fewer than four satellites there is no fix (NaN).
    """
    n_ep = t_ns.size
    starts = spp.epoch_starts(obs["t_ns"])
    ep_t = obs["t_ns"][starts[:-1]]
    sat_pos = np.stack([obs["sat_x_m"], obs["sat_y_m"], obs["sat_z_m"]], axis=-1)
    q = np.full((n_ep, 4), np.nan)
    nsat = np.zeros(n_ep, dtype=np.int64)
    where = np.searchsorted(t_ns, ep_t)
    for k, e in enumerate(where):
        a, b = starts[k], starts[k + 1]
        c_en = earth.dcm_ecef_to_ned(ant.lat_rad[e], ant.lon_rad[e])
        q[e] = spp.dop_enu(sat_pos[a:b], ant.ecef_m[e], c_en)
        nsat[e] = b - a
    sig_enu = params.fix_uere_m * np.sqrt(q[:, :3])
    a_gm = math.exp(-1.0 / (params.fix_tau_s * _rate(t_ns)))
    w = rng.normal(0.0, 1.0, (n_ep, 3))
    u = np.empty((n_ep, 3))
    u[0] = w[0]
    for k in range(1, n_ep):
        u[k] = a_gm * u[k - 1] + math.sqrt(1.0 - a_gm * a_gm) * w[k]
    on = 1.0 if noisy else 0.0
    err = on * sig_enu * u
    dn, de, du = err[:, 1], err[:, 0], err[:, 2]
    rm, rn = np.vectorize(earth.radii)(ant.lat_rad)
    lat = ant.lat_rad + dn / (rm + ant.h_m)
    lon = ant.lon_rad + de / ((rn + ant.h_m) * np.cos(ant.lat_rad))
    vel = ant.vel_ned_mps + on * params.fix_vel_sigma_mps * rng.normal(0.0, 1.0, (n_ep, 3))
    fix = nsat >= 4
    nan = np.where(fix, 1.0, np.nan)
    return {
        "t_ns": t_ns,
        "lat_deg": np.degrees(lat) * nan,
        "lon_deg": np.degrees(lon) * nan,
        "alt_m": (ant.h_m + du) * nan,
        "vel_n_mps": vel[:, 0] * nan,
        "vel_e_mps": vel[:, 1] * nan,
        "vel_d_mps": vel[:, 2] * nan,
        "h_acc_m": np.sqrt(0.5 * (sig_enu[:, 0] ** 2 + sig_enu[:, 1] ** 2)),
        "v_acc_m": sig_enu[:, 2],
        "speed_acc_mps": np.full(n_ep, params.fix_vel_sigma_mps),
        "fix_type": np.where(fix, FixType.FIX_3D, FixType.NO_FIX).astype(np.int8),
        "num_sats": nsat.astype(np.int16),
    }


def _rate(t_ns: I64) -> float:
    """Epochs per second of a uniform time grid (1 for a single epoch)."""
    return 1.0 if t_ns.size < 2 else 1e9 / float(t_ns[1] - t_ns[0])
