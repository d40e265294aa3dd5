"""`navreplay synth` for the vehicle datasets: tractor (CSV), fwekf (tlog), car (CSV),
multirotor and bench (tlog)."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from navreplay.ingest.meta import read_meta
from navreplay.pipeline.cli import main
from navreplay.pipeline.synth import DATASETS

REPO = Path(__file__).resolve().parents[3]

FILES = {
    "tractor_straight": [
        "tractor_straight_gnss.csv",
        "tractor_straight_truth.csv",
        "tractor_straight_vehicle.csv",
    ],
    "fwekf_reference": ["fwekf_reference.tlog"],
    "fwekf_reference_noise_free": ["fwekf_reference_noise_free.tlog"],
    "car_speed_ramp": [
        "car_speed_ramp_gnss.csv",
        "car_speed_ramp_truth.csv",
        "car_speed_ramp_vehicle.csv",
    ],
    "multirotor_flight": ["multirotor_flight.tlog"],
    "bench_static": ["bench_static.tlog"],
}


@pytest.fixture(scope="module")
def short_params(tmp_path_factory: pytest.TempPathFactory) -> Path:
    data = yaml.safe_load((REPO / "params.yaml").read_text())
    synth = data["synth"]
    synth["tractor_straight"]["duration_s"] = 2.0
    synth["fwekf_reference"].update(alignment_s=1.0, motion_s=2.0)
    synth["car_speed_ramp"].update(ramp_s=8.0, hold_s=2.0)
    synth["multirotor_flight"]["flight"].update(eights=1, landed_s=2.0)
    synth["multirotor_flight"]["bench"]["duration_s"] = 5.0
    path = tmp_path_factory.mktemp("params") / "params.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.mark.parametrize("name", sorted(FILES))
def test_each_vehicle_dataset_is_registered_and_written_by_the_cli(
    name: str, short_params: Path, tmp_path: Path
) -> None:
    assert name in DATASETS
    out = tmp_path / "raw"
    assert main(["synth", name, "--out", str(out), "--params", str(short_params)]) == 0
    assert sorted(p.name for p in out.iterdir()) == sorted([*FILES[name], "reference"])
    meta = read_meta(out / "reference")
    assert meta.dataset == name
    assert meta.time_base == "utc"
    assert sorted(s.name for s in meta.sources) == sorted(FILES[name])
    assert (REPO / "datasets" / name / "dataset.yaml").is_file()
