"""The ``car_speed_ramp`` dataset: a car from walking pace to highway speed through curves.

Paper 003 compares a kinematic and a dynamic (tire slip, lateral force) vehicle model per speed
band. The truth here is the linear-tire bicycle model of ``pipeline.synth.bicycle`` driven by:

- speed: ``speed_start_mps`` (walking pace) to ``speed_end_mps`` (highway) along a quintic
  smooth-step over ``ramp_s``, then held for ``hold_s``; the smooth-step lingers at both ends,
  so low and high speeds both get a fair share of the drive;
- steering: alternating curves ``kappa(t) = kappa_max(u) w(t)``, ``w = s |s|`` with
  ``s = sin(2 pi t / curve_period_s)`` (curves with near-straight stretches between them),
  where ``kappa_max(u) = min(tan(max_steer_rad) / L, max_lateral_accel_mps2 / u^2)``: sharp
  turns at walking pace, sweeping curves at speed. The road-wheel angle is the steady-state
  inverse of the model, ``delta = atan(L kappa) + K u^2 kappa``, so the car follows roughly
  that curvature; what it actually does is whatever the model integrates.

At walking pace the motion is kinematic (at 1.5 m/s and 0.4 rad of steering the yaw rate is
0.6 % and the sideslip 0.2 deg below the kinematic ``u tan(delta) / L`` and
``atan(l_r tan(delta) / L)``); at 33 m/s and 4 m/s^2 of lateral acceleration the true sideslip
is about -1.2 deg where the kinematic model predicts +0.8 deg, and the kinematic yaw rate from
the steering angle is 2.5x the true one.

Sensors (white noise, optional constant errors, all in ``synth.car_speed_ramp.sensors``):
wheel speed = ``u (1 + scale error)``, road-wheel steering angle, yaw rate (the z gyro: true
yaw rate plus the earth and transport rates about the local vertical, ~4e-5 rad/s, plus bias)
at ``vehicle_rate_hz``; GPS position (N, E, D) and NED velocity of the centre of gravity at
``gnss_rate_hz``. Truth at the vehicle rate with extra columns ``slip_angle_rad`` (sideslip at
the centre of gravity, course = yaw + slip), ``yaw_rate_radps``, ``speed_mps``, ``steer_rad``,
``lateral_accel_mps2``, ``slip_front_rad``, ``slip_rear_rad`` and the sensor errors.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pyarrow as pa

from navreplay.ingest.meta import SensorMeta
from navreplay.ingest.schema import FixType
from navreplay.ingest.typed import FieldError
from navreplay.ingest.writers.csv import CsvColumn
from navreplay.pipeline.nav.earth import OMEGA_IE, radii
from navreplay.pipeline.nav.local import LocalFrame
from navreplay.pipeline.synth import SynthResult, SynthSection
from navreplay.pipeline.synth.bicycle import COLUMNS, VehicleParams, simulate
from navreplay.pipeline.synth.checks import require_non_negative
from navreplay.pipeline.synth.output import (
    check_dataset,
    csv_tables,
    dataset_rng,
    level_truth_columns,
    synth_params,
    write_csv_dataset,
)

F64 = npt.NDArray[np.float64]

DATASET = "car_speed_ramp"


@dataclass(frozen=True)
class CarSensors:
    """Sensor rates, white noise (1 sigma per sample) and constant errors."""

    vehicle_rate_hz: int = 100
    gnss_rate_hz: int = 10
    wheel_speed_noise_mps: float = 0.05
    wheel_speed_scale_error: float = 0.0
    steer_noise_rad: float = 0.0017
    steer_bias_rad: float = 0.0
    yaw_rate_noise_radps: float = 0.005
    yaw_rate_bias_radps: float = 0.0
    gnss_horizontal_noise_m: float = 1.0
    gnss_vertical_noise_m: float = 1.5
    gnss_velocity_noise_mps: float = 0.05

    def __post_init__(self) -> None:
        if self.vehicle_rate_hz <= 0 or 1_000_000 % self.vehicle_rate_hz:
            raise FieldError("vehicle_rate_hz", "must be > 0 and divide 1e6 us evenly")
        if self.gnss_rate_hz <= 0 or self.vehicle_rate_hz % self.gnss_rate_hz:
            raise FieldError("gnss_rate_hz", "must be > 0 and divide vehicle_rate_hz")
        require_non_negative(self, [n for n in self.__dataclass_fields__ if "noise" in n])


@dataclass(frozen=True)
class CarSpeedRampParams:
    """``synth.car_speed_ramp`` (see the module docstring).

    Attributes:
        speed_start_mps, speed_end_mps: walking pace and highway speed.
        ramp_s, hold_s: duration of the speed ramp and of the hold at the end speed.
        curve_period_s: period of the left-right curve pattern.
        max_lateral_accel_mps2: lateral acceleration of the curves at speed.
        max_steer_rad: road-wheel angle of the curves at walking pace.
        heading_deg: initial heading, clockwise from north.
        integration_hz: RK4 rate of the model (a multiple of the vehicle rate).
        vehicle: mass, geometry and tires.
        sensors: rates, noise and constant errors.
        origin: start point.
        start_unix_s: UNIX time of the first sample.
    """

    speed_start_mps: float = 1.5
    speed_end_mps: float = 33.0
    ramp_s: float = 300.0
    hold_s: float = 60.0
    curve_period_s: float = 20.0
    max_lateral_accel_mps2: float = 4.0
    max_steer_rad: float = 0.45
    heading_deg: float = 0.0
    integration_hz: int = 1000
    vehicle: VehicleParams = field(default_factory=VehicleParams)
    sensors: CarSensors = field(default_factory=CarSensors)
    origin: LocalFrame = field(default_factory=lambda: LocalFrame(17.597, 78.486, 540.0))
    start_unix_s: int = 1795345200

    def __post_init__(self) -> None:
        if not 0 < self.speed_start_mps <= self.speed_end_mps:
            raise FieldError("speed_start_mps", "need 0 < speed_start_mps <= speed_end_mps")
        if self.ramp_s <= 0 or self.hold_s < 0:
            raise FieldError("ramp_s", "need ramp_s > 0 and hold_s >= 0")
        if self.integration_hz % self.sensors.vehicle_rate_hz:
            raise FieldError("integration_hz", "must be a multiple of sensors.vehicle_rate_hz")
        if not 0 < self.max_steer_rad < 1.2:
            raise FieldError("max_steer_rad", "must be within 0..1.2 rad")

    @property
    def duration_s(self) -> float:
        return self.ramp_s + self.hold_s


def speed_profile(params: CarSpeedRampParams, t_s: F64) -> F64:
    """Longitudinal speed u(t), m/s: quintic smooth-step ramp, then constant."""
    x = np.clip(np.asarray(t_s, dtype=np.float64) / params.ramp_s, 0.0, 1.0)
    smooth = x**3 * (10.0 + x * (-15.0 + 6.0 * x))
    return params.speed_start_mps + (params.speed_end_mps - params.speed_start_mps) * smooth


def steer_profile(params: CarSpeedRampParams, t_s: F64) -> F64:
    """Road-wheel steering angle delta(t), rad, for the curve pattern at speed u(t)."""
    vp = params.vehicle
    u = speed_profile(params, t_s)
    wheelbase = vp.wheelbase_m
    kappa_max = np.minimum(
        math.tan(params.max_steer_rad) / wheelbase, params.max_lateral_accel_mps2 / u**2
    )
    s = np.sin(2.0 * math.pi * np.asarray(t_s) / params.curve_period_s)
    kappa = kappa_max * s * np.abs(s)
    out: F64 = np.arctan(wheelbase * kappa) + vp.understeer_gradient_rad_per_mps2 * u**2 * kappa
    return out


def trajectory(params: CarSpeedRampParams) -> dict[str, F64]:
    """The true motion at the vehicle rate: time, model outputs (``bicycle.COLUMNS``),
    ``u_mps`` and ``delta_rad``."""
    rate = params.sensors.vehicle_rate_hz
    n_steps = round(params.duration_s * params.integration_hz)
    t_half = np.arange(2 * n_steps + 1) / (2.0 * params.integration_hz)
    u_half = speed_profile(params, t_half)
    d_half = steer_profile(params, t_half)
    o = params.origin
    out = simulate(
        u_half,
        d_half,
        1.0 / params.integration_hz,
        params.integration_hz // rate,
        params.vehicle.as_tuple(),
        math.radians(params.heading_deg),
        math.radians(o.lat_deg),
        math.radians(o.lon_deg),
        o.alt_m,
    )
    t_s = np.arange(out.shape[0]) / rate
    res = {name: out[:, i].copy() for i, name in enumerate(COLUMNS)}
    res["t_s"] = t_s
    res["u_mps"] = speed_profile(params, t_s)
    res["delta_rad"] = steer_profile(params, t_s)
    return res


def _vel_ned(tr: dict[str, F64]) -> tuple[F64, F64]:
    course = tr["psi_rad"] + np.arctan2(tr["v_y_mps"], tr["u_mps"])
    speed = np.hypot(tr["u_mps"], tr["v_y_mps"])
    return speed * np.cos(course), speed * np.sin(course)


def _csv_columns(params: CarSpeedRampParams, seed: int) -> dict[str, list[CsvColumn]]:
    sp = params.sensors
    rng = dataset_rng(seed, DATASET)
    tr = trajectory(params)
    n = tr["t_s"].size
    t_us = params.start_unix_s * 1_000_000 + np.arange(n, dtype=np.int64) * (
        1_000_000 // sp.vehicle_rate_hz
    )
    vn, ve = _vel_ned(tr)
    lat, h = tr["lat_rad"], params.origin.alt_m
    rm, rn = np.vectorize(radii)(lat)
    # z gyro of a level body: yaw rate w.r.t. NED plus (w_ie + w_en) down
    earth_z = -OMEGA_IE * np.sin(lat) - ve * np.tan(lat) / (rn + h)
    noise = rng.standard_normal((n, 3))
    idx = np.arange(0, n, sp.vehicle_rate_hz // sp.gnss_rate_hz)
    m = idx.size
    gn = rng.standard_normal((m, 6))
    const = np.ones(n)
    ones_g = np.ones(m)
    f_t = "%.10f"
    return {
        "vehicle": [
            CsvColumn("time_us", t_us, "%d"),
            CsvColumn(
                "wheel_speed_mps",
                tr["u_mps"] * (1.0 + sp.wheel_speed_scale_error)
                + sp.wheel_speed_noise_mps * noise[:, 0],
                "%.3f",
            ),
            CsvColumn(
                "steer_angle_rad",
                tr["delta_rad"] + sp.steer_bias_rad + sp.steer_noise_rad * noise[:, 1],
                "%.5f",
            ),
            CsvColumn(
                "yaw_rate_radps",
                tr["r_radps"]
                + earth_z
                + sp.yaw_rate_bias_radps
                + sp.yaw_rate_noise_radps * noise[:, 2],
                "%.5f",
            ),
        ],
        "gnss": [
            CsvColumn("time_us", t_us[idx], "%d"),
            CsvColumn(
                "lat_deg",
                np.degrees(lat[idx] + sp.gnss_horizontal_noise_m * gn[:, 0] / (rm[idx] + h)),
                "%.9f",
            ),
            CsvColumn(
                "lon_deg",
                np.degrees(
                    tr["lon_rad"][idx]
                    + sp.gnss_horizontal_noise_m * gn[:, 1] / ((rn[idx] + h) * np.cos(lat[idx]))
                ),
                "%.9f",
            ),
            CsvColumn("height_m", h - sp.gnss_vertical_noise_m * gn[:, 2], "%.3f"),
            CsvColumn("vel_n_mps", vn[idx] + sp.gnss_velocity_noise_mps * gn[:, 3], "%.3f"),
            CsvColumn("vel_e_mps", ve[idx] + sp.gnss_velocity_noise_mps * gn[:, 4], "%.3f"),
            CsvColumn("vel_d_mps", sp.gnss_velocity_noise_mps * gn[:, 5], "%.3f"),
            CsvColumn("h_acc_m", sp.gnss_horizontal_noise_m * ones_g, "%.2f"),
            CsvColumn("v_acc_m", sp.gnss_vertical_noise_m * ones_g, "%.2f"),
            CsvColumn("speed_acc_mps", sp.gnss_velocity_noise_mps * ones_g, "%.3f"),
            CsvColumn("fix_type", FixType.FIX_3D * ones_g, "%d"),
        ],
        "truth": [
            *level_truth_columns(
                t_us,
                np.degrees(lat),
                np.degrees(tr["lon_rad"]),
                h * const,
                vn,
                ve,
                tr["psi_rad"],
                f_t,
            ),
            CsvColumn("slip_angle_rad", np.arctan2(tr["v_y_mps"], tr["u_mps"]), f_t),
            CsvColumn("yaw_rate_radps", tr["r_radps"], f_t),
            CsvColumn("speed_mps", np.hypot(tr["u_mps"], tr["v_y_mps"]), f_t),
            CsvColumn("steer_rad", tr["delta_rad"], f_t),
            CsvColumn("lateral_accel_mps2", tr["a_y_mps2"], f_t),
            CsvColumn("slip_front_rad", tr["alpha_f_rad"], f_t),
            CsvColumn("slip_rear_rad", tr["alpha_r_rad"], f_t),
            CsvColumn("steer_bias_rad", sp.steer_bias_rad * const, f_t),
            CsvColumn("yaw_rate_bias_radps", sp.yaw_rate_bias_radps * const, f_t),
            CsvColumn("wheel_speed_scale_error", sp.wheel_speed_scale_error * const, f_t),
        ],
    }


def _tables(cols: dict[str, list[CsvColumn]]) -> dict[str, pa.Table]:
    """Canonical tables: measurements as the CSV holds them, truth at full precision."""
    # the GNSS log names its columns as the canonical table does, but for the height
    same: tuple[str, ...] = ("lat_deg", "lon_deg", "vel_n_mps", "vel_e_mps", "vel_d_mps")
    same += ("h_acc_m", "v_acc_m", "speed_acc_mps", "fix_type")
    return csv_tables(
        cols,
        {
            "vehicle": {
                "speed_mps": "wheel_speed_mps",
                "steer_rad": "steer_angle_rad",
                "yaw_rate_radps": "yaw_rate_radps",
            },
            "gnss": {"alt_m": "height_m", **{name: name for name in same}},
        },
    )


def _sensor_meta(params: CarSpeedRampParams) -> SensorMeta:
    return SensorMeta(wheelbase_m=params.vehicle.wheelbase_m)


def synthesize(params: CarSpeedRampParams, seed: int) -> SynthResult:
    """The ``car_speed_ramp`` dataset in memory."""
    return SynthResult(_tables(_csv_columns(params, seed)), _sensor_meta(params), time_base="utc")


def write(params: CarSpeedRampParams, seed: int, out_dir: str | Path) -> list[Path]:
    """Write the CSV logs and ``reference/`` as the folder ``out_dir``; returns the files."""
    cols = _csv_columns(params, seed)
    comment = f"navreplay synthesized {DATASET} (paper 003): linear-tire bicycle model, seed {seed}"
    result = SynthResult(_tables(cols), _sensor_meta(params), time_base="utc")
    plain = synth_params(seed, DATASET, params)
    return write_csv_dataset(out_dir, DATASET, result, cols, comment=comment, params=plain)


def write_dataset(name: str, synth: SynthSection, out_dir: Path) -> list[Path]:
    """The synth registry's entry point: ``car_speed_ramp`` from ``params.synth``."""
    check_dataset(__name__, name, DATASET)
    return write(synth.car_speed_ramp, synth.seed, out_dir)
