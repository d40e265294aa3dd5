"""The vehicle-model family (paper 003: kinematic, dynamic, switched, IMM) under the run
contract (``estimation.core.contract``).

``estimate.parquet`` is a canonical ``estimator`` table: ``lat_deg``, ``lon_deg`` (the local
north/east mapped back through the run's origin), ``alt_m`` (the origin's height: the models
are planar), ``vel_n_mps`` and ``vel_e_mps`` (speed along the course psi + beta), ``yaw_rad``
(heading, wrapped), NaN ``vel_d_mps``, ``roll_rad`` and ``pitch_rad``; extra float columns
``speed_mps``, ``slip_angle_rad`` (sideslip beta), ``course_rad`` and ``dynamic_weight`` (the
IMM's probability of the dynamic model, or 1 while the switched filter uses it), with 1-sigma
columns ``lat_sigma_m``, ``lon_sigma_m``, ``vel_{n,e}_sigma_mps``, ``yaw_sigma_rad``,
``speed_sigma_mps``, ``slip_angle_sigma_rad`` and ``course_sigma_rad``.
"""

from __future__ import annotations

import logging

import numpy as np
import pyarrow as pa

from navreplay.ingest.schema import TableName, from_columns
from navreplay.pipeline.estimation.core.contract import (
    Backend,
    RunInputs,
    RunOutput,
)
from navreplay.pipeline.estimation.core.windows import ErrorTrack, table_track
from navreplay.pipeline.estimation.vehicle import kernel as kv
from navreplay.pipeline.estimation.vehicle import model as vm
from navreplay.pipeline.estimation.vehicle.config import VEHICLE_FILTERS, VehicleFilterParams
from navreplay.pipeline.estimation.vehicle.metrics import compute_metrics
from navreplay.pipeline.estimation.vehicle.replay import VehicleRunResult, run_vehicle_filter

log = logging.getLogger(__name__)

INPUTS = (TableName.VEHICLE, TableName.GNSS, TableName.TRUTH)


def estimate_columns(result: VehicleRunResult) -> dict[str, np.ndarray]:
    """The columns of ``estimate.parquet`` (see the module docstring)."""
    x, P = result.x, result.P
    var = np.diagonal(P, axis1=1, axis2=2)
    lat, lon, alt = result.origin.to_geodetic(x[:, vm.X_N], x[:, vm.X_E], 0.0)
    course = x[:, vm.X_PSI] + x[:, vm.X_BETA]
    c, s = np.cos(course), np.sin(course)
    var_course = var[:, vm.X_PSI] + var[:, vm.X_BETA] + 2.0 * P[:, vm.X_PSI, vm.X_BETA]
    v = x[:, vm.X_V]
    nan = np.full(x.shape[0], np.nan)
    return {
        "t_ns": result.t_ns,
        "lat_deg": lat,
        "lon_deg": lon,
        "alt_m": alt,
        "vel_n_mps": v * c,
        "vel_e_mps": v * s,
        "vel_d_mps": nan,
        "roll_rad": nan,
        "pitch_rad": nan,
        "yaw_rad": np.angle(np.exp(1j * x[:, vm.X_PSI])),
        "speed_mps": v,
        "slip_angle_rad": x[:, vm.X_BETA],
        "course_rad": np.angle(np.exp(1j * course)),
        "dynamic_weight": result.aux,
        "lat_sigma_m": np.sqrt(var[:, vm.X_N]),
        "lon_sigma_m": np.sqrt(var[:, vm.X_E]),
        "vel_n_sigma_mps": np.sqrt(c * c * var[:, vm.X_V] + (v * s) ** 2 * var_course),
        "vel_e_sigma_mps": np.sqrt(s * s * var[:, vm.X_V] + (v * c) ** 2 * var_course),
        "yaw_sigma_rad": np.sqrt(var[:, vm.X_PSI]),
        "speed_sigma_mps": np.sqrt(var[:, vm.X_V]),
        "slip_angle_sigma_rad": np.sqrt(var[:, vm.X_BETA]),
        "course_sigma_rad": np.sqrt(np.maximum(var_course, 0.0)),
    }


def innovations_table(result: VehicleRunResult) -> pa.Table:
    """``innovations.parquet`` rows (streams ``vehicle.kernel.STREAM_NAMES``)."""
    ii, ff = result.inn_i, result.inn_f
    return pa.table(
        {
            "t_ns": pa.array(ii[:, 0], pa.int64()),
            "stream": pa.array([kv.STREAM_NAMES[s] for s in ii[:, 1]], pa.string()),
            "sv": pa.array([None] * ii.shape[0], pa.string()),
            "dim": pa.array(ii[:, 3], pa.int8()),
            "nis": pa.array(ff[:, 0], pa.float64()),
            "gate": pa.array(ff[:, 1], pa.float64()),
            "accepted": pa.array(ii[:, 4].astype(bool), pa.bool_()),
            **{f"innov_{j}": pa.array(ff[:, 2 + j], pa.float64()) for j in range(3)},
            **{f"innov_sigma_{j}": pa.array(ff[:, 5 + j], pa.float64()) for j in range(3)},
        }
    )


class VehicleFamily:
    """The vehicle-model EKFs of paper 003 over wheel speed, steering and GNSS fixes."""

    name = "vehicle"
    filters = VEHICLE_FILTERS
    inputs = INPUTS

    def run(
        self, inputs: RunInputs, name: str, section: VehicleFilterParams, backend: Backend
    ) -> RunOutput:
        wb = inputs.sensors.wheelbase_m if inputs.sensors is not None else None
        model_wb = section.vehicle.wheelbase_m
        if wb is not None and abs(wb - model_wb) > 0.05:
            log.warning("dataset wheelbase %.2f m differs from the filter's %.2f m", wb, model_wb)
        result = run_vehicle_filter(inputs.tables, name, section, backend=backend)
        metrics = compute_metrics(result, inputs.tables.get("truth"))
        metrics["dataset"] = inputs.dataset
        estimate = from_columns("estimator", estimate_columns(result))
        return RunOutput.decode(
            result, estimate, innovations_table(result), metrics, inputs.sources, section.integrity
        )

    def track(self, run: RunOutput, inputs: RunInputs) -> ErrorTrack | None:
        """Planar errors read from ``estimate.parquet`` (``windows.table_track``)."""
        tables = inputs.tables
        return table_track(run.tables.estimate, tables.get("truth"), tables.get("gnss"))


VEHICLE = VehicleFamily()
