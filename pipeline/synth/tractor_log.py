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
from typing import Protocol

import numpy as np
import numpy.typing as npt
import pyarrow as pa

from navreplay.ingest.meta import SensorMeta
from navreplay.ingest.schema import FixType, from_columns
from navreplay.ingest.typed import to_plain
from navreplay.ingest.writers.csv import CsvColumn, quantize, write_csv
from navreplay.pipeline.control.lqr import lqr_command, tractor_lqr_gain
from navreplay.pipeline.synth import SynthResult
from navreplay.pipeline.synth.output import dataset_seed, write_dataset_dir
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
            CsvColumn("time_us", t_us, "%d"),
            CsvColumn("lat_deg", tlat, _FMT_TRUTH),
            CsvColumn("lon_deg", tlon, _FMT_TRUTH),
            CsvColumn("alt_m", talt, _FMT_TRUTH),
            CsvColumn("vel_n_mps", v * np.cos(psi), _FMT_TRUTH),
            CsvColumn("vel_e_mps", v * np.sin(psi), _FMT_TRUTH),
            CsvColumn("vel_d_mps", 0.0 * const, _FMT_TRUTH),
            CsvColumn("roll_rad", 0.0 * const, _FMT_TRUTH),
            CsvColumn("pitch_rad", 0.0 * const, _FMT_TRUTH),
            CsvColumn("yaw_rad", (psi + math.pi) % (2 * math.pi) - math.pi, _FMT_TRUTH),
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

    def logged(c: CsvColumn) -> F64:
        return quantize(c.values, c.fmt)

    veh = {c.name: c for c in cols["vehicle"]}
    gn = {c.name: c for c in cols["gnss"]}
    tr = {c.name: c for c in cols["truth"]}
    t_ns = cols["vehicle"][0].values.astype(np.int64) * 1000
    vehicle = from_columns(
        "vehicle",
        {
            "t_ns": t_ns,
            "speed_mps": logged(veh["radar_speed_mps"]),
            "steer_rad": logged(veh["steer_pot_rad"]),
            "yaw_rate_radps": logged(veh["fog_yaw_rate_radps"]),
            "steer_rate_cmd_radps": logged(veh["steer_cmd_radps"]),
        },
    )
    gnss = from_columns(
        "gnss",
        {
            "t_ns": t_ns,
            "lat_deg": logged(gn["lat_deg"]),
            "lon_deg": logged(gn["lon_deg"]),
            "alt_m": logged(gn["height_m"]),
            "h_acc_m": logged(gn["h_acc_m"]),
            "fix_type": gn["fix_type"].values.astype(np.int8),
            "heading_rad": logged(gn["heading_deg"]) * DEG,
        },
    )
    truth_cols: dict[str, object] = {"t_ns": t_ns}
    truth_cols.update({name: c.values for name, c in tr.items() if name != "time_us"})
    truth = from_columns("truth", truth_cols)
    return {"vehicle": vehicle, "gnss": gnss, "truth": truth}


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

    def write_logs(folder: Path) -> list[tuple[Path, str]]:
        logs = []
        for name, columns in cols.items():
            path = folder / f"{DATASET}_{name}.csv"
            write_csv(path, columns, comment=comment)
            logs.append((path, "csv"))
        return logs

    result = SynthResult(_tables(cols), SensorMeta(), time_base="utc")
    plain = {"seed": seed, DATASET: to_plain(params)}
    return write_dataset_dir(out_dir, DATASET, result, write_logs, params=plain)


class SynthSection(Protocol):
    """What ``write_dataset`` reads of ``params.synth`` (``pipeline.params.SynthParams``): the
    seed and this dataset's section."""

    @property
    def seed(self) -> int: ...

    @property
    def tractor_straight(self) -> TractorStraightParams: ...


def write_dataset(name: str, synth: SynthSection, out_dir: Path) -> list[Path]:
    """The synth registry's entry point: ``tractor_straight`` from ``params.synth``."""
    if name != DATASET:
        raise ValueError(f"{__name__} makes {DATASET!r}, not {name!r}")
    return write(synth.tractor_straight, synth.seed, out_dir)
