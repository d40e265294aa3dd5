"""Every family under the scenario driver: a vehicle-model filter replayed with outages
(`navreplay run --scenario`), measured on its planar error track; fault scenarios, whose pass
criteria read the INS state, are refused for it with the reason."""

from __future__ import annotations

import copy
import json
from dataclasses import replace
from pathlib import Path

import pytest
import yaml

from navreplay.ingest.meta import SensorMeta
from navreplay.pipeline.cli import main
from navreplay.pipeline.params import load_params, read_yaml
from navreplay.pipeline.synth import car
from tests.pipeline.scenarios.drives import REPO, drive, short_window_scenarios, write_tables


@pytest.fixture(scope="module")
def car_tables(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 60 s speed ramp (vehicle, gnss, truth tables)."""
    p = load_params(REPO / "params.yaml").synth
    drive = car.synthesize(replace(p.car_speed_ramp, ramp_s=45.0, hold_s=15.0), p.seed).tables
    tables = {name: drive[name] for name in ("vehicle", "gnss", "truth")}
    sensors = SensorMeta(wheelbase_m=2.7)
    return write_tables(tmp_path_factory.mktemp("car"), tables, "car60", sensors, "utc")


@pytest.fixture(scope="module")
def params_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """params.yaml with 10 s outage windows that fit the 60 s drive."""
    data = short_window_scenarios(copy.deepcopy(read_yaml(REPO / "params.yaml")))
    path = tmp_path_factory.mktemp("params") / "params.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_a_vehicle_filter_runs_under_outage_scenarios(
    car_tables: Path, params_file: Path, tmp_path: Path
) -> None:
    out = tmp_path / "runs"
    args = ["run", str(car_tables), "--filter", "vehicle_kinematic", "--params", str(params_file),
            "--keep-going"]  # fmt: skip
    for s in ("nominal", "outage_60s", "sats_1"):
        args += ["--scenario", s]
    assert main([*args, "--out", str(out)]) == 0
    nominal = json.loads((out / "nominal" / "metrics.json").read_text())
    outage = json.loads((out / "outage_60s" / "metrics.json").read_text())
    sats_1 = json.loads((out / "sats_1" / "metrics.json").read_text())
    assert "outage_windows" not in nominal
    assert nominal["windows"] == []
    wins = outage["outage_windows"]
    assert len(wins) == 2
    for w in wins:
        assert w["reference"] == "truth"
        assert w["samples"] == 100  # 10 Hz over 10 s
        assert w["err_end_down_m"] is None  # a planar model: horizontal errors only
        assert w["err_end_m"] == pytest.approx(w["err_h_end_m"])
        assert w["err_end_m"] > w["err_start_m"]  # dead reckoning drifts
        assert w["sigma_end_m"] > 0.0
    # one satellite kept gives a loosely coupled filter no fix: the outage, replayed once
    assert [w["err_end_m"] for w in sats_1["outage_windows"]] == [w["err_end_m"] for w in wins]
    assert outage["pos_err_h_rms_m"] > nominal["pos_err_h_rms_m"]
    # the kinematic model does not fit a car at speed (paper 003): the integrity monitor says
    # so, and after the outages its course no longer follows the measured one
    assert nominal["status"] == "inconsistent"
    assert outage["status"] == "diverged"
    assert "the estimate left the gnss_course measurements" in outage["failure"]
    # without --keep-going a diverged run is an error exit (its output is written all the same)
    once = ["run", str(car_tables), "--filter", "vehicle_kinematic", "--params", str(params_file)]
    assert main([*once, "--scenario", "outage_60s", "--out", str(tmp_path / "b")]) == 3


def test_fault_scenarios_are_refused_for_a_vehicle_filter_with_the_reason(
    car_tables: Path, params_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    args = ["run", str(car_tables), "--filter", "vehicle_imm", "--params", str(params_file)]
    rc = main([*args, "--scenario", "f1_position_jump", "--out", str(tmp_path / "f1")])
    assert rc == 2
    err = capsys.readouterr().err
    assert "vehicle_imm" in err
    assert "fault scenarios (f1_position_jump)" in err
    assert not (tmp_path / "f1").exists()


def test_every_scenario_of_a_log_runs_with_the_fix_errors_learned_from_the_whole_log(
    params_file: Path, tmp_path: Path
) -> None:
    """The outage run's fixes have holes, but its fix-error model is the nominal run's: the
    one the log's own fixes show (a model learned from a scenario's leftovers would make the
    scenarios differ by more than the outage)."""
    tables, sensors = drive(150.0)
    tables_dir = write_tables(tmp_path / "tables", dict(tables), "seoul150", sensors)
    out = tmp_path / "runs"
    args = ["run", str(tables_dir), "--filter", "lc_ekf", "--params", str(params_file),
            "--keep-going", "--scenario", "nominal", "--scenario", "outage_60s"]  # fmt: skip
    assert main([*args, "--out", str(out)]) == 0
    nominal = json.loads((out / "nominal" / "metrics.json").read_text())["fix_noise"]
    outage = json.loads((out / "outage_60s" / "metrics.json").read_text())["fix_noise"]
    assert nominal["source"] == "learned"
    assert outage == nominal
