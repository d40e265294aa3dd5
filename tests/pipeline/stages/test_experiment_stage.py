"""``navreplay experiment``: the vehicle speed-band experiment over a tables directory."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import yaml

from navreplay.ingest.meta import DatasetMeta, write_meta
from navreplay.ingest.schema import TableName
from navreplay.ingest.tables import Provenance, write_table
from navreplay.pipeline.cli import main
from navreplay.pipeline.params import load_params
from navreplay.pipeline.synth import car

REPO = Path(__file__).resolve().parents[3]


def test_vehicle_bands_writes_identical_tables_and_a_figure_twice(tmp_path: Path) -> None:
    p = load_params(REPO / "params.yaml")
    short = replace(p.synth.car_speed_ramp, ramp_s=40.0, hold_s=5.0, speed_end_mps=20.0)
    res = car.synthesize(short, p.synth.seed)
    tables = tmp_path / "tables"
    tables.mkdir()
    for name in ("vehicle", "gnss", "truth"):
        prov = Provenance.create(TableName(name), sources=())
        write_table(tables / f"{name}.parquet", TableName(name), res.tables[name], prov)
    write_meta(tables, DatasetMeta("car_short", "utc", (), {}))
    # the paired Monte Carlo synthesizes its own drives: 2 seeds of a short ramp here
    doc = yaml.safe_load((REPO / "params.yaml").read_text())
    doc["experiments"]["vehicle_bands"]["seeds"] = 2
    doc["synth"]["car_speed_ramp"].update(ramp_s=40.0, hold_s=5.0, speed_end_mps=20.0)
    params_path = tmp_path / "params.yaml"
    params_path.write_text(yaml.safe_dump(doc))
    outs = []
    for k in range(2):
        out = tmp_path / f"out{k}"
        argv = ["experiment", "vehicle_bands", "--tables", str(tables), "--out", str(out)]
        assert main([*argv, "--params", str(params_path)]) == 0
        outs.append(out)
    paired = json.loads((outs[0] / "paired.json").read_text())
    assert paired["seeds"] == 2
    assert {r["filter"] for r in paired["rows"]} == {"vehicle_switched", "vehicle_imm"}
    assert "paired over 2 noise realizations" in (outs[0] / "paired_note.md").read_text()
    for name in ("bands.json", "bands.csv", "paired.json", "paired.csv", "paired_note.md"):
        assert (outs[0] / name).read_bytes() == (outs[1] / name).read_bytes()
    assert (outs[0] / "bands.png").stat().st_size > 10_000
    bands = json.loads((outs[0] / "bands.json").read_text())["rows"]
    assert {r["filter"] for r in bands} == {
        "vehicle_kinematic", "vehicle_dynamic", "vehicle_switched", "vehicle_imm"
    }  # fmt: skip
    assert {r["scenario"] for r in bands} == {"nominal", "outages"}
