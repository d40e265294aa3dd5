"""A cascaded run's files: ``estimate.parquet``, ``innovations.parquet``, ``events.parquet``.

``estimate.parquet`` is a canonical ``estimator`` table (validated as such): ``t_ns``, the
position as ``lat_deg``/``lon_deg``/``alt_m`` (the local map's height; the filters are
planar), ``vel_n_mps``/``vel_e_mps`` from the control filter's speed along the estimated
heading, ``yaw_rad`` the estimated heading (wrapped), ``lat_sigma_m`` / ``lon_sigma_m`` /
``yaw_sigma_rad``; ``vel_d``, roll and pitch are null (not estimated). Every state of both
filters is an extra float column under the truth table's name where it has one
(``STATE_COLUMNS``), each with a 1-sigma column ``<name>_sigma_<unit>``.

``innovations.parquet``: one row per gated block: ``t_ns``, ``stream`` (``gnss_pos`` m,
``gnss_heading`` rad, ``yaw_rate`` rad/s, ``speed`` m/s, ``steer`` rad), ``dim``, ``nis``,
``gate``, ``accepted``, ``innov_0..2``, ``innov_sigma_0..2`` (NaN past ``dim``), as the INS
filters' file (``pipeline.estimation.ins.outputs``).

``events.parquet``: ``t_ns``, ``kind`` (``gate_reject``, ``gate_reset``, ``cov_repair``,
``divergence``, ``input_gap``, ``no_steer_command``, ``no_gnss_heading``), ``stream``,
``sv`` (empty), ``value``.
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa

from navreplay.ingest.schema import from_columns
from navreplay.pipeline.estimation.cascaded.cascade import STREAM_NAMES
from navreplay.pipeline.estimation.cascaded.engine import CascadedResult
from navreplay.pipeline.estimation.cascaded.model import CTL_VX, NAV_E, NAV_N, NAV_PSI, NX, wrap_pi
from navreplay.pipeline.nav.earth import F64
from navreplay.pipeline.nav.local import LocalFrame

#: (index into [X1, X2], column, sigma column)
STATE_COLUMNS: tuple[tuple[int, str, str], ...] = (
    (0, "east_m", "east_sigma_m"),
    (1, "north_m", "north_sigma_m"),
    (2, "radar_bias_mps", "radar_bias_sigma_mps"),
    (3, "heading_rad", "heading_sigma_rad"),
    (4, "gyro_bias_z_radps", "gyro_bias_z_sigma_radps"),
    (5, "heading_bias_rad", "heading_bias_sigma_rad"),
    (NX + 0, "yaw_rate_radps", "yaw_rate_sigma_radps"),
    (NX + 1, "yaw_accel_radps2", "yaw_accel_sigma_radps2"),
    (NX + 2, "speed_mps", "speed_sigma_mps"),
    (NX + 3, "steer_rad", "steer_sigma_rad"),
    (NX + 4, "steer_rate_radps", "steer_rate_sigma_radps"),
    (NX + 5, "steer_bias_rad", "steer_bias_sigma_rad"),
)


def sigmas(result: CascadedResult) -> F64:
    """1-sigma of every state, ``[X1, X2]`` order, (K, 12)."""
    var = [np.diagonal(result.P[:, f], axis1=1, axis2=2) for f in range(2)]
    out: F64 = np.sqrt(np.concatenate(var, axis=1))
    return out


def estimate_columns(result: CascadedResult, frame: LocalFrame) -> dict[str, np.ndarray]:
    """The columns of ``estimate.parquet`` (see the module docstring)."""
    x, sig = result.x, sigmas(result)
    lat, lon, alt = frame.to_geodetic(x[:, NAV_N], x[:, NAV_E])
    psi = x[:, NAV_PSI]
    speed = x[:, NX + CTL_VX]
    cols: dict[str, np.ndarray] = {
        "t_ns": result.t_ns,
        "lat_deg": lat,
        "lon_deg": lon,
        "alt_m": alt,
        "vel_n_mps": speed * np.cos(psi),
        "vel_e_mps": speed * np.sin(psi),
        "yaw_rad": np.array([wrap_pi(float(a)) for a in psi]),
        "lat_sigma_m": sig[:, NAV_N],
        "lon_sigma_m": sig[:, NAV_E],
        "yaw_sigma_rad": sig[:, NAV_PSI],
    }
    for i, name, sname in STATE_COLUMNS:
        cols[name] = x[:, i]
        cols[sname] = sig[:, i]
    return cols


def estimate_table(result: CascadedResult, frame: LocalFrame) -> pa.Table:
    """``estimate.parquet`` as a validated canonical ``estimator`` table."""
    return from_columns("estimator", estimate_columns(result, frame))


def innovations_table(result: CascadedResult) -> pa.Table:
    """``innovations.parquet``: one row per gated measurement block."""
    ii, ff = result.inn_i, result.inn_f
    return pa.table(
        {
            "t_ns": pa.array(ii[:, 0], pa.int64()),
            "stream": pa.array([STREAM_NAMES[s] for s in ii[:, 1]], pa.string()),
            "dim": pa.array(ii[:, 3], pa.int8()),
            "nis": pa.array(ff[:, 0], pa.float64()),
            "gate": pa.array(ff[:, 1], pa.float64()),
            "accepted": pa.array(ii[:, 4].astype(bool), pa.bool_()),
            **{f"innov_{j}": pa.array(ff[:, 2 + j], pa.float64()) for j in range(3)},
            **{f"innov_sigma_{j}": pa.array(ff[:, 5 + j], pa.float64()) for j in range(3)},
        }
    )
