"""The ``tractor_straight`` dataset: a recorded run of the tractor simulator, as CSV logs.

The recording closes the loop on the TRUE state with the paper's LQR (eq. 8-14, discretized
with eq. 14 at the sample period), which is what the tractor does in paper 000's figures
(straight-line tracking North after a 3 m East step of the line), and records every sensor and
the command ``u`` applied after each sample. A filter replays it open loop; the cascaded-filter
issue closes the loop on its own estimates with ``TractorSim`` instead.

The paper's gain is aggressive and the model has no steering limits: the first second of the
3 m step takes the steer angle to 1.11 rad and the heading to 0.76 rad (commands up to
9 rad/s); the tractor is within 5 cm of the line after 2.5 s and within 1 mm after 10 s.

Files (``write``): ``tractor_straight_vehicle.csv`` (radar speed, steer potentiometer, FOG yaw
rate, steering command), ``tractor_straight_gnss.csv`` (RTK position as latitude/longitude,
multi-antenna heading in degrees), ``tractor_straight_truth.csv``; all at 50 Hz with an integer
UNIX-microsecond time column, mapped onto the canonical tables by
``datasets/tractor_straight/dataset.yaml``.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pyarrow as pa

from navreplay.ingest.meta import SensorMeta
from navreplay.ingest.schema import FixType
from navreplay.ingest.writers.csv import CsvColumn
from navreplay.pipeline.control.lqr import lqr_command, tractor_lqr_gain
from navreplay.pipeline.synth import SynthResult, SynthSection
from navreplay.pipeline.synth.output import (
    check_dataset,
    csv_tables,
    dataset_seed,
    level_truth_columns,
    synth_params,
    write_csv_dataset,
)
from navreplay.pipeline.synth.tractor import (
    TractorMeasurement,
    TractorSim,
    TractorState,
    TractorStraightParams,
)

F64 = npt.NDArray[np.float64]

DATASET = "tractor_straight"
DEG = math.pi / 180.0

# CSV formats: resolution well below each sensor's noise (Table 2), truth to ~1e-5 m.
_FMT_VEHICLE = {"speed": "%.5f", "steer": "%.6f", "yaw_rate": "%.7f", "cmd": "%.7f"}
_FMT_GNSS = {"deg": "%.10f", "alt": "%.4f", "heading_deg": "%.5f", "acc": "%.3f"}
_FMT_TRUTH = "%.10f"


def record(params: TractorStraightParams, seed: int) -> dict[str, F64]:
    """Run the simulator closed on true states with the paper's LQR; every sample's values.

    Returns:
        arrays of length ``params.steps + 1`` keyed by name: ``t_s``, the truth fields of
        ``TractorState``, the readings of ``TractorMeasurement`` (prefixed ``meas_``), and the
        command ``u`` applied after each sample.
    """
    sim = TractorSim(params, dataset_seed(seed, DATASET))
    gain = tractor_lqr_gain(params.speed_mps, params.dt_s, params.model)
    line = params.line()
    n = params.steps + 1
    rows_truth = np.empty((n, 9))
    rows_meas = np.empty((n, 8))
    u = np.empty(n)
    for k in range(n):
        x = sim.truth
        rows_truth[k] = x
        rows_meas[k] = sim.measurement
        xc = line.control_state(
            x.east_m,
            x.north_m,
            x.heading_rad,
            x.yaw_rate_radps,
            x.yaw_accel_radps2,
            x.steer_rad,
            x.steer_rate_radps,
        )
        u[k] = lqr_command(gain, xc)
        if k < n - 1:
            sim.step(u[k])
    out = {name: rows_truth[:, i].copy() for i, name in enumerate(TractorState._fields)}
    out.update(
        {
            f"meas_{name}": rows_meas[:, i].copy()
            for i, name in enumerate(TractorMeasurement._fields)
        }
    )
    out["u"] = u
    return out


def _time_us(params: TractorStraightParams, n: int) -> npt.NDArray[np.int64]:
    return params.start_unix_s * 1_000_000 + np.arange(n, dtype=np.int64) * (params.dt_ns // 1000)


def _csv_columns(params: TractorStraightParams, rec: dict[str, F64]) -> dict[str, list[CsvColumn]]:
    n = rec["t_s"].size
    t_us = _time_us(params, n)
    frame = params.origin
    lat, lon, alt = frame.to_geodetic(rec["meas_north_m"], rec["meas_east_m"])
    tlat, tlon, talt = frame.to_geodetic(rec["north_m"], rec["east_m"])
    b = params.biases
    psi = rec["heading_rad"]
    v = rec["speed_mps"]
    const = np.ones(n)
    fv, fg = _FMT_VEHICLE, _FMT_GNSS
    return {
        "vehicle": [
            CsvColumn("time_us", t_us, "%d"),
            CsvColumn("radar_speed_mps", rec["meas_speed_mps"], fv["speed"]),
            CsvColumn("steer_pot_rad", rec["meas_steer_rad"], fv["steer"]),
            CsvColumn("fog_yaw_rate_radps", rec["meas_yaw_rate_radps"], fv["yaw_rate"]),
            CsvColumn("steer_cmd_radps", rec["u"], fv["cmd"]),
        ],
        "gnss": [
            CsvColumn("time_us", t_us, "%d"),
            CsvColumn("lat_deg", lat, fg["deg"]),
            CsvColumn("lon_deg", lon, fg["deg"]),
            CsvColumn("height_m", alt, fg["alt"]),
            CsvColumn("heading_deg", rec["meas_heading_rad"] / DEG, fg["heading_deg"]),
            CsvColumn("h_acc_m", math.sqrt(params.noise.east_m2) * const, fg["acc"]),
            CsvColumn("fix_type", FixType.RTK_FIXED * const, "%d"),
        ],
        "truth": [
            *level_truth_columns(
                t_us, tlat, tlon, talt, v * np.cos(psi), v * np.sin(psi), psi, _FMT_TRUTH
            ),
            CsvColumn("speed_mps", v, _FMT_TRUTH),
            CsvColumn("yaw_rate_radps", rec["yaw_rate_radps"], _FMT_TRUTH),
            CsvColumn("yaw_accel_radps2", rec["yaw_accel_radps2"], _FMT_TRUTH),
            CsvColumn("steer_rad", rec["steer_rad"], _FMT_TRUTH),
            CsvColumn("steer_rate_radps", rec["steer_rate_radps"], _FMT_TRUTH),
            CsvColumn("steer_bias_rad", b.steer_rad * const, _FMT_TRUTH),
            CsvColumn("heading_bias_rad", b.heading_rad * const, _FMT_TRUTH),
            CsvColumn("gyro_bias_z_radps", b.gyro_radps * const, _FMT_TRUTH),
            CsvColumn("radar_bias_mps", b.radar_mps * const, _FMT_TRUTH),
        ],
    }


def _tables(cols: dict[str, list[CsvColumn]]) -> dict[str, pa.Table]:
    """Canonical tables: measurements as the CSV holds them, truth at full precision."""
    return csv_tables(
        cols,
        {
            "vehicle": {
                "speed_mps": "radar_speed_mps",
                "steer_rad": "steer_pot_rad",
                "yaw_rate_radps": "fog_yaw_rate_radps",
                "steer_rate_cmd_radps": "steer_cmd_radps",
            },
            "gnss": {
                "lat_deg": "lat_deg",
                "lon_deg": "lon_deg",
                "alt_m": "height_m",
                "h_acc_m": "h_acc_m",
                "fix_type": "fix_type",
                "heading_rad": "heading_deg",
            },
        },
        scale={"heading_rad": DEG},
    )


def synthesize(params: TractorStraightParams, seed: int) -> SynthResult:
    """The ``tractor_straight`` dataset in memory (see the module docstring)."""
    rec = record(params, seed)
    tables = _tables(_csv_columns(params, rec))
    return SynthResult(tables, SensorMeta(), time_base="utc")


def write(params: TractorStraightParams, seed: int, out_dir: str | Path) -> list[Path]:
    """Write the CSV logs and ``reference/`` as the folder ``out_dir``; returns the files.

    Byte-identical for the same parameters and seed.
    """
    rec = record(params, seed)
    cols = _csv_columns(params, rec)
    comment = (
        f"navreplay synthesized {DATASET} (paper 000): John Deere 8400 model, "
        f"{params.rate_hz:g} Hz, seed {seed}"
    )
    result = SynthResult(_tables(cols), SensorMeta(), time_base="utc")
    plain = synth_params(seed, DATASET, params)
    return write_csv_dataset(out_dir, DATASET, result, cols, comment=comment, params=plain)


def write_dataset(name: str, synth: SynthSection, out_dir: Path) -> list[Path]:
    """The synth registry's entry point: ``tractor_straight`` from ``params.synth``."""
    check_dataset(__name__, name, DATASET)
    return write(synth.tractor_straight, synth.seed, out_dir)
