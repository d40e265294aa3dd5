"""A run's files: ``estimate.parquet``, ``innovations.parquet``, ``events.parquet``.

``estimate.parquet`` is a canonical ``estimator`` table (validated as such): ``t_ns`` and the
navigation solution under the truth table's column names, so estimate and truth compare
directly, plus the estimated sensor biases (``acc_bias_{x,y,z}_mps2``,
``gyro_bias_{x,y,z}_radps``) and, for tightly coupled filters, the receiver clock
(``clock_bias_m``, ``clock_drift_mps``). Every estimated column has a 1-sigma column:

=========================  ===================================================================
``lat_sigma_m``            north position 1-sigma, m (latitude uncertainty in metres)
``lon_sigma_m``            east position 1-sigma, m
``alt_sigma_m``            height 1-sigma, m
``vel_{n,e,d}_sigma_mps``  velocity 1-sigma, m/s
``{roll,pitch,yaw}_sigma_rad``  Euler-angle 1-sigma, rad (the nav-frame attitude covariance
                           mapped through the Euler-rate Jacobian)
``<bias column>_sigma_<unit>``  e.g. ``acc_bias_x_sigma_mps2``, ``clock_bias_sigma_m``
=========================  ===================================================================

``innovations.parquet`` has one row per measurement block and update (a fix's position or
velocity, one satellite's pseudorange and rate, the NHC pair): ``t_ns``, ``stream``
(``gnss_pos`` m, ``gnss_vel`` m/s, ``gnss_obs`` m then m/s, ``nhc`` m/s), ``sv``, ``dim``,
``nis`` (with the prior innovation covariance), ``gate`` (the chi-square threshold),
``accepted``, ``innov_0..2`` and ``innov_sigma_0..2`` (NaN past ``dim``).

``events.parquet`` lists what the run skipped, rejected, reset or repaired: ``t_ns``,
``kind`` (``gate_reject``, ``gate_reset``, ``cov_repair``, ``divergence``, ``imu_gap``,
``imu_duplicate``, ``imu_backwards``, ``imu_invalid``, ``segment_break``, ``imu_tumble``,
``skip_invalid``,
``skip_no_fix``, ``no_alignment``), ``stream``, ``sv`` and ``value`` (NIS, gap length ...).
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa

from navreplay.ingest.schema import from_columns
from navreplay.pipeline.estimation.ins.models import ins
from navreplay.pipeline.estimation.ins.models import measurement as me
from navreplay.pipeline.estimation.ins.replay import RunResult
from navreplay.pipeline.nav.earth import F64

BIAS_COLUMNS = (
    ("acc_bias_x_mps2", ins.X_BA, ins.E_BA, "acc_bias_x_sigma_mps2"),
    ("acc_bias_y_mps2", ins.X_BA + 1, ins.E_BA + 1, "acc_bias_y_sigma_mps2"),
    ("acc_bias_z_mps2", ins.X_BA + 2, ins.E_BA + 2, "acc_bias_z_sigma_mps2"),
    ("gyro_bias_x_radps", ins.X_BG, ins.E_BG, "gyro_bias_x_sigma_radps"),
    ("gyro_bias_y_radps", ins.X_BG + 1, ins.E_BG + 1, "gyro_bias_y_sigma_radps"),
    ("gyro_bias_z_radps", ins.X_BG + 2, ins.E_BG + 2, "gyro_bias_z_sigma_radps"),
)
CLOCK_COLUMNS = (
    ("clock_bias_m", ins.X_CB, ins.E_CB, "clock_bias_sigma_m"),
    ("clock_drift_mps", ins.X_CD, ins.E_CD, "clock_drift_sigma_mps"),
)
#: a loosely coupled run's Gauss-Markov fix errors, in the clock's states
FIX_ERROR_COLUMNS = (
    ("fix_error_n_m", ins.X_CB, ins.E_CB, "fix_error_n_sigma_m"),
    ("fix_error_e_m", ins.X_CD, ins.E_CD, "fix_error_e_sigma_m"),
)


def extra_state_columns(result: RunResult) -> tuple[tuple[str, int, int, str], ...]:
    """The columns of states 15 and 16: the clock's (tight coupling), the fix errors' (loose
    coupling with ``FixNoise.states``), or none."""
    if result.n <= ins.N_LOOSE:
        return ()
    return FIX_ERROR_COLUMNS if result.fix_noise.get("states") else CLOCK_COLUMNS


def quat_to_euler_batch(q: F64) -> F64:
    """(K, 4) q_wxyz -> (K, 3) roll, pitch, yaw (ZYX, as ``nav.rotations.quat_to_euler``)."""
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    c20 = 2.0 * (x * z - w * y)
    c21 = 2.0 * (y * z + w * x)
    c22 = w * w - x * x - y * y + z * z
    c10 = 2.0 * (x * y + w * z)
    c00 = w * w + x * x - y * y - z * z
    return np.column_stack(
        [np.arctan2(c21, c22), -np.arcsin(np.clip(c20, -1.0, 1.0)), np.arctan2(c10, c00)]
    )


def euler_covariance(rpy: F64, P_att: F64) -> F64:
    """Covariance of (roll, pitch, yaw) from that of the nav-frame rotation vector phi.

    ``phi = M d(roll, pitch, yaw)`` with ``M = [[cy cp, -sy, 0], [sy cp, cy, 0], [-sp, 0, 1]]``
    (the nav-frame angular increment of ZYX Euler increments), so ``Cov = M^-1 P M^-T``.

    Args:
        rpy: (K, 3) Euler angles; P_att: (K, 3, 3) attitude covariances.
    """
    cp, sp = np.cos(rpy[:, 1]), np.sin(rpy[:, 1])
    cy, sy = np.cos(rpy[:, 2]), np.sin(rpy[:, 2])
    M = np.zeros((rpy.shape[0], 3, 3))
    M[:, 0, 0], M[:, 0, 1] = cy * cp, -sy
    M[:, 1, 0], M[:, 1, 1] = sy * cp, cy
    M[:, 2, 0], M[:, 2, 2] = -sp, 1.0
    Mi = np.linalg.inv(M)
    return Mi @ P_att @ np.transpose(Mi, (0, 2, 1))


def estimate_columns(result: RunResult) -> dict[str, np.ndarray]:
    """The columns of ``estimate.parquet`` (see the module docstring)."""
    x, P, n = result.x, result.P, result.n
    var = np.diagonal(P, axis1=1, axis2=2) if len(x) else np.zeros((0, n))
    rpy = quat_to_euler_batch(x[:, ins.X_Q : ins.X_Q + 4])
    cov_e = euler_covariance(rpy, P[:, ins.E_ATT : ins.E_ATT + 3, ins.E_ATT : ins.E_ATT + 3])
    cols: dict[str, np.ndarray] = {
        "t_ns": result.t_ns,
        "lat_deg": np.degrees(x[:, ins.X_LAT]),
        "lon_deg": np.degrees(np.angle(np.exp(1j * x[:, ins.X_LON]))),
        "alt_m": x[:, ins.X_H],
        "vel_n_mps": x[:, ins.X_VEL],
        "vel_e_mps": x[:, ins.X_VEL + 1],
        "vel_d_mps": x[:, ins.X_VEL + 2],
        "roll_rad": rpy[:, 0],
        "pitch_rad": rpy[:, 1],
        "yaw_rad": rpy[:, 2],
        "lat_sigma_m": np.sqrt(var[:, ins.E_POS]),
        "lon_sigma_m": np.sqrt(var[:, ins.E_POS + 1]),
        "alt_sigma_m": np.sqrt(var[:, ins.E_POS + 2]),
    }
    for j, axis in enumerate("ned"):
        cols[f"vel_{axis}_sigma_mps"] = np.sqrt(var[:, ins.E_VEL + j])
    for j, name in enumerate(("roll", "pitch", "yaw")):
        cols[f"{name}_sigma_rad"] = np.sqrt(cov_e[:, j, j])
    if "alpha" in result.extra:
        cols["fading_alpha"] = result.extra["alpha"]  # fwekf: the fuzzy fading factor
    if "r_scale" in result.extra:
        cols["iae_r_scale"] = result.extra["r_scale"]  # iae_ekf: horizontal fix variance x
    extra = BIAS_COLUMNS + extra_state_columns(result)
    for col, xi, ei, sig in extra:
        cols[col] = x[:, xi]
        cols[sig] = np.sqrt(var[:, ei])
    return cols


def estimate_table(result: RunResult) -> pa.Table:
    """``estimate.parquet`` as a validated canonical ``estimator`` table."""
    return from_columns("estimator", estimate_columns(result))


def innovations_table(result: RunResult) -> pa.Table:
    """``innovations.parquet``: one row per gated measurement block."""
    ii, ff = result.inn_i, result.inn_f
    return pa.table(
        {
            "t_ns": pa.array(ii[:, 0], pa.int64()),
            "stream": pa.array([me.STREAM_NAMES[s] for s in ii[:, 1]], pa.string()),
            "sv": pa.array([me.sv_name(int(c)) or None for c in ii[:, 2]], pa.string()),
            "dim": pa.array(ii[:, 3], pa.int8()),
            "nis": pa.array(ff[:, 0], pa.float64()),
            "gate": pa.array(ff[:, 1], pa.float64()),
            "accepted": pa.array(ii[:, 4].astype(bool), pa.bool_()),
            **{f"innov_{j}": pa.array(ff[:, 2 + j], pa.float64()) for j in range(3)},
            **{f"innov_sigma_{j}": pa.array(ff[:, 5 + j], pa.float64()) for j in range(3)},
        }
    )
