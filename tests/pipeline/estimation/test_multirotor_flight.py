"""The INS filters on the synthesized quadrotor flight (``multirotor_flight``): a log whose
course is not its heading (yaw in place, sideways, backwards, figure eights) with a consumer
IMU and a calibrated compass, through the tlog and ingest as a user's log would come."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from navreplay.ingest.api import ingest
from navreplay.ingest.schema import TableName
from navreplay.pipeline.analyze import NHC_REASON, plan
from navreplay.pipeline.estimation.config import FiltersParams
from navreplay.pipeline.estimation.core.contract import RunInputs
from navreplay.pipeline.estimation.ins.models import ins
from navreplay.pipeline.estimation.ins.replay import RunResult, run_filter
from navreplay.pipeline.synth import multirotor
from navreplay.pipeline.synth.multirotor_params import MultirotorFlightParams

PARAMS = MultirotorFlightParams()


@pytest.fixture(scope="module")
def tables_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("quad")
    multirotor.write(PARAMS, 20261203, root / "raw")
    ingest([root / "raw/multirotor_flight.tlog"], root / "tables")  # no descriptor: a user's log
    return root / "tables"


@pytest.fixture(scope="module")
def run(tables_dir: Path, filters: FiltersParams) -> tuple[RunInputs, RunResult]:
    names = (TableName.IMU, TableName.GNSS, TableName.MAG, TableName.TRUTH)
    inputs = RunInputs.read(tables_dir, names)
    return inputs, run_filter(inputs.tables, inputs.sensors, "lc_ekf", filters.lc_ekf)


def _yaw(x: np.ndarray) -> np.ndarray:
    q0, q1, q2, q3 = (x[:, ins.X_Q + j] for j in range(4))
    yaw: np.ndarray = np.arctan2(2 * (q0 * q3 + q1 * q2), 1 - 2 * (q2**2 + q3**2))
    return yaw


def test_the_quadrotor_starts_on_the_ground_and_holds_its_heading_in_flight(
    run: tuple[RunInputs, RunResult],
) -> None:
    """Aligned on the ground within a second of the first fix from the compass and the motion
    that follows; from take-off the yaw within 5 deg RMS of the truth, the horizontal position
    within 2 m RMS, and the run ok."""
    inputs, r = run
    assert r.status == "ok", r.failure
    al = r.alignments[0]
    t_fix = int(inputs.tables["gnss"]["t_ns"][0].as_py())
    assert (al.t_ns - t_fix) * 1e-9 <= 1.0
    assert "magnetometer" in al.method
    truth = inputs.tables["truth"]
    t_truth = truth["t_ns"].to_numpy()
    take_off = t_truth[0] + int(PARAMS.flight.ground_s * 1e9)
    air = r.t_ns >= take_off
    assert air.sum() > 100
    yaw_true = np.interp(r.t_ns[air], t_truth, np.unwrap(truth["yaw_rad"].to_numpy()))
    err = np.degrees(np.remainder(_yaw(r.x[air]) - yaw_true + math.pi, 2 * math.pi) - math.pi)
    assert math.sqrt(np.mean(err**2)) < 5.0
    lat = np.interp(r.t_ns[air], t_truth, np.radians(truth["lat_deg"].to_numpy()))
    lon = np.interp(r.t_ns[air], t_truth, np.radians(truth["lon_deg"].to_numpy()))
    north = (r.x[air, ins.X_LAT] - lat) * 6.378e6
    east = (r.x[air, ins.X_LON] - lon) * 6.378e6 * np.cos(lat)
    assert math.sqrt(np.mean(north**2 + east**2)) < 2.0


def test_no_non_holonomic_constraint_on_a_quadrotor(tables_dir: Path) -> None:
    """The NHC variants are skipped with the reason (a multirotor slides sideways)."""
    run_names, skipped = plan(tables_dir, ["lc_ekf", "lc_ekf_nhc"])
    assert run_names == ["lc_ekf"]
    assert [s.filter for s in skipped] == ["lc_ekf_nhc"]
    assert NHC_REASON in skipped[0].reason
    assert "multirotor" in skipped[0].reason
