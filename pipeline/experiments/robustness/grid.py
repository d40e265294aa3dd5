"""The cells of the robustness sweep (``robustness.sweep``, whose docstring describes the
grid): the IMU grades, a cell and the grid, the drive of a cell as tables, and the outage
windows removed from it.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

from navreplay.ingest.config import ImuNoise
from navreplay.ingest.meta import SensorMeta
from navreplay.pipeline.estimation.config import FiltersParams
from navreplay.pipeline.experiments.drives import Tables, add_imu_bias, bias_signs, with_nulls
from navreplay.pipeline.scenarios.apply import apply_scenario
from navreplay.pipeline.scenarios.config import ScenarioSpec
from navreplay.pipeline.synth import car_drives
from navreplay.pipeline.synth.car_drives import CarDriveParams
from navreplay.pipeline.synth.seoul_params import ImuErrors, SeoulCampusParams

DRIVE = "car_stop_and_go"
DURATION_S = 360.0
#: outage windows (start s from the first IMU sample, length s): >= 60 s of GNSS before the
#: first (aligned at ~16 s), between two and after the last
OUTAGES = ((80.0, 10.0), (150.0, 30.0), (240.0, 60.0))
#: the simulator's fix correlation time for white errors (it needs tau > 0)
WHITE_TAU_S = 1e-3
TAUS_S = (0.0, 10.0, 60.0)
DPS = math.pi / 180.0
COV_COLUMNS = ("h_acc_m", "v_acc_m", "speed_acc_mps")
OBS_COV_COLUMNS = ("pseudorange_std_m", "pseudorange_rate_std_mps")


@dataclass(frozen=True)
class Grade:
    """One IMU grade, per axis: white noise densities, bias random walks (the bias
    instability reached over ~100 s) and the turn-on bias added in full; ``source``: where the
    figures come from."""

    accel_noise_mps2_rthz: float
    gyro_noise_radps_rthz: float
    accel_bias_rw_mps3_rthz: float
    gyro_bias_rw_radps2_rthz: float
    accel_turn_on_mps2: float
    gyro_turn_on_radps: float
    source: str

    def errors(self) -> ImuErrors:
        """The simulator's error model (no drawn turn-on bias: ``simulate`` adds the grade's)."""
        return ImuErrors(
            self.accel_noise_mps2_rthz,
            self.gyro_noise_radps_rthz,
            0.0,
            0.0,
            self.accel_bias_rw_mps3_rthz,
            self.gyro_bias_rw_radps2_rthz,
            0.0,
            0.0,
        )

    def declared(self) -> ImuNoise:
        """An honest datasheet of the grade: its noise, and its turn-on bias as 1-sigma."""
        return ImuNoise(
            accel_noise_mps2_rthz=self.accel_noise_mps2_rthz,
            gyro_noise_radps_rthz=self.gyro_noise_radps_rthz,
            accel_bias_sigma_mps2=self.accel_turn_on_mps2,
            gyro_bias_sigma_radps=self.gyro_turn_on_radps,
            accel_bias_rw_mps3_rthz=self.accel_bias_rw_mps3_rthz,
            gyro_bias_rw_radps2_rthz=self.gyro_bias_rw_radps2_rthz,
        )


#: The IMU grades, per axis (the bias random walk reaches the grade's bias instability, BI,
#: in ~100 s: rw = BI / 10 s^0.5; the turn-on bias is added in full, signs from the seed):
#:
#: ============  ==========  ==========  ==========  ============  ========  =========
#: grade         accel       gyro        accel bias  gyro bias     accel     gyro
#:               noise       noise       rw          rw            turn-on   turn-on
#:               m/s^2/rtHz  rad/s/rtHz  m/s^3/rtHz  rad/s^2/rtHz  m/s^2     deg/s
#: ============  ==========  ==========  ==========  ============  ========  =========
#: tactical      5e-4        3.6e-5      5e-5        5e-7          0.01      1 deg/h
#: industrial    6e-4        1e-4        1.3e-5      4e-6          0.05      0.2
#: consumer      1.7e-3      2.4e-4      1e-4        1e-5          0.5       1.0
#: phone         4e-3        5e-4        5e-4        2.4e-5        0.5       1.0
#: ============  ==========  ==========  ==========  ============  ========  =========
#:
#: For comparison, params.yaml's fallback prior (``filters.<name>.imu_noise``): gyro bias
#: 0.0087 rad/s (0.5 deg/s), accel bias 0.25 m/s^2 (the consumer turn-on at two sigma).
GRADES = {
    "tactical": Grade(
        5e-4, 3.6e-5, 5e-5, 5e-7, 0.01, 1.0 / 3600 * DPS,
        "HG1700/HG1900 class: ARW 0.125 deg/rt-h, VRW 0.03 m/s/rt-h, gyro bias 1 deg/h, "
        "accel bias 1 mg",
    ),
    "industrial": Grade(
        6e-4, 1e-4, 1.3e-5, 4e-6, 0.05, 0.2 * DPS,
        "ADIS16470 class: ARW 0.34 deg/rt-h, VRW 0.037 m/s/rt-h, in-run 8 deg/h and 13 ug, "
        "turn-on 0.2 deg/s and ~5 mg",
    ),
    "consumer": Grade(
        1.7e-3, 2.4e-4, 1e-4, 1e-5, 0.5, 1.0 * DPS,
        "BMI088 / ICM-20602 class: 175 ug/rt-Hz, 0.014 deg/s/rt-Hz, in-run 20 deg/h and 0.1 mg, "
        "zero-rate offset 1 deg/s; accel offset with solder and temperature drift up to "
        "0.5 m/s^2 (issue 22)",
    ),
    "phone": Grade(
        4e-3, 5e-4, 5e-4, 2.4e-5, 0.5, 1.0 * DPS,
        "handset IMU (LSM6DSx / BMI160 in a phone): datasheet noise x3-4 for vibration and "
        "decimation, in-run 50 deg/h and 0.5 mg; turn-on as consumer after the handset's own "
        "calibration (a raw 3 deg/s would fail the static detector: issue 21's business)",
    ),
}  # fmt: skip


@dataclass(frozen=True)
class Cell:
    """One cell of the grid."""

    grade: str
    fix_tau_s: float
    covariance: bool
    gnss_hz: int = 1
    imu_hz: int = 100
    declared: bool = False

    @property
    def white(self) -> bool:
        return self.fix_tau_s == 0.0

    @property
    def sim_key(self) -> tuple[str, float, int, int]:
        """What the simulation depends on (covariance and declaration are applied after)."""
        return (self.grade, self.fix_tau_s, self.gnss_hz, self.imu_hz)

    def label(self) -> str:
        fix = "white" if self.white else f"tau{self.fix_tau_s:g}"
        cov = "cov" if self.covariance else "nocov"
        decl = " decl" if self.declared else ""
        return f"{self.grade} {fix} {cov} {self.gnss_hz}/{self.imu_hz}Hz{decl}"


BASE = Cell("consumer", 0.0, True)


def grid() -> list[Cell]:
    """Grade x fix errors x covariance (undeclared IMU, 1 Hz GNSS, 100 Hz IMU); each grade
    declared (white fixes with covariance); the rates one at a time around ``BASE``."""
    cells = [Cell(g, t, c) for g, t, c in itertools.product(GRADES, TAUS_S, (True, False))]
    cells += [Cell(g, 0.0, True, declared=True) for g in GRADES]
    cells += [dataclasses.replace(BASE, gnss_hz=hz) for hz in (5, 10)]
    cells += [dataclasses.replace(BASE, imu_hz=hz) for hz in (25, 400)]
    return cells


@dataclass(frozen=True)
class SweepParams:
    """What the sweep reads of params.yaml: the campus car's sensors
    (``synth.seoul_campus``), its stop-and-go drive (``synth.car_drives``) and the filters."""

    campus: SeoulCampusParams
    drive: CarDriveParams
    filters: FiltersParams

    @classmethod
    def of(
        cls, campus: SeoulCampusParams, drives: Mapping[str, CarDriveParams], filters: FiltersParams
    ) -> SweepParams:
        """From ``synth.seoul_campus``, ``synth.car_drives`` (its ``DRIVE``) and ``filters``."""
        return cls(campus, drives[DRIVE], filters)


def simulate(params: SweepParams, cell: Cell, seed: int) -> tuple[Tables, SensorMeta]:
    """The drive with the cell's IMU grade (its turn-on bias added), fix correlation and
    rates; covariance and declaration are ``prepare``'s."""
    campus = params.campus
    grade = GRADES[cell.grade]
    gnss = dataclasses.replace(campus.gnss, fix_tau_s=cell.fix_tau_s or WHITE_TAU_S)
    campus = dataclasses.replace(
        campus,
        imu=grade.errors(),
        gnss=gnss,
        imu_rate_hz=cell.imu_hz,
        gnss_rate_hz=cell.gnss_hz,
    )
    drive = dataclasses.replace(params.drive, duration_s=DURATION_S)
    r = car_drives.simulate(DRIVE, campus, drive, seed=seed)
    tables = add_imu_bias(
        r.tables,
        grade.gyro_turn_on_radps * bias_signs(seed, 22),
        grade.accel_turn_on_mps2 * bias_signs(seed, 23),
    )
    return tables, r.sensors


def prepare(tables: Tables, sensors: SensorMeta, cell: Cell) -> tuple[Tables, SensorMeta]:
    """The cell's covariance (absent: the accuracy columns null) and IMU declaration."""
    out = dict(tables)
    if not cell.covariance:
        out["gnss"] = with_nulls(out["gnss"], COV_COLUMNS)
        out["gnss_obs"] = with_nulls(out["gnss_obs"], OBS_COV_COLUMNS)
    noise = GRADES[cell.grade].declared() if cell.declared else None
    return out, dataclasses.replace(sensors, imu_noise=noise)


def outage_windows(tables: Tables) -> list[tuple[int, int]]:
    """``OUTAGES`` as ``[start, end)`` ns on the log's time base."""
    t0 = int(tables["imu"].column("t_ns")[0].as_py())
    return [(t0 + round(s * 1e9), t0 + round((s + n) * 1e9)) for s, n in OUTAGES]


def with_outages(tables: Tables) -> Tables:
    """The ``gnss`` and ``gnss_obs`` rows inside ``OUTAGES`` removed."""
    return dict(
        apply_scenario(tables, "outages", ScenarioSpec(), windows=outage_windows(tables)).tables
    )


GROUPS: dict[str, Callable[[Cell], bool]] = {
    "base": lambda c: c == BASE,
    "grades": lambda c: (c.gnss_hz, c.imu_hz, c.declared) == (1, 100, False),
    "declared": lambda c: c.declared,
    "rates": lambda c: (c.gnss_hz, c.imu_hz) != (1, 100),
}


def select(cells: Sequence[Cell], subsets: Sequence[str]) -> list[Cell]:
    """The cells of a group name (``GROUPS``) or whose label has every word of a subset
    (``"consumer tau60 nocov"``)."""
    if not subsets:
        return list(cells)

    def match(c: Cell, s: str) -> bool:
        if s in GROUPS:
            return GROUPS[s](c)
        return set(s.split()) <= set(c.label().split())

    return [c for c in cells if any(match(c, s) for s in subsets)]
