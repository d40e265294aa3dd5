"""The non-holonomic constraint fits ground vehicles only: ``plan`` (``analyze`` and ``navreplay
run --skip-unfit``) skips the ``*_nhc`` filters on a log whose platform (``meta.json``
``sensors.platform``) is neither ``ground`` nor ``unknown``, with the reason."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from navreplay.ingest.meta import read_meta
from navreplay.pipeline.analyze import plan
from navreplay.pipeline.cli import main

FIXED_WING = (
    "the non-holonomic constraint holds for ground vehicles; this log is a fixed_wing "
    "(from HEARTBEAT type 1 (MAV_TYPE_FIXED_WING))"
)


@pytest.fixture(scope="module")
def plane_tlog(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Paper 004's drive (a tlog whose HEARTBEAT says MAV_TYPE_FIXED_WING), 30 s of it."""
    root = tmp_path_factory.mktemp("plane")
    params = root / "short.yaml"
    params.write_text("synth:\n  fwekf_reference:\n    motion_s: 30.0\n")
    assert main(["-q", "synth", "fwekf_reference", "--params", str(params),
                 "--out", str(root / "raw")]) == 0  # fmt: skip
    return root / "raw" / "fwekf_reference.tlog"


@pytest.fixture(scope="module")
def plane_tables(plane_tlog: Path) -> Path:
    tables = plane_tlog.parent.parent / "tables"
    assert main(["-q", "ingest", str(plane_tlog), "--out", str(tables)]) == 0
    return tables


def test_nhc_filters_are_skipped_on_a_fixed_wing_with_the_reason(plane_tables: Path) -> None:
    assert read_meta(plane_tables).sensors.platform.kind == "fixed_wing"
    run, skipped = plan(plane_tables, ["lc_ekf", "lc_ekf_nhc", "tc_ekf_nhc"])
    assert run == ["lc_ekf"]
    # tc_ekf_nhc lacks raw observables first: that reason is the more basic one
    assert (skipped[0].filter, skipped[0].reason) == ("lc_ekf_nhc", FIXED_WING)
    assert "no raw GNSS observables" in skipped[1].reason


def test_nhc_filters_run_when_dataset_yaml_says_ground(plane_tlog: Path, tmp_path: Path) -> None:
    descriptor = tmp_path / "dataset.yaml"
    descriptor.write_text(f"id: towed\nlogs: [{plane_tlog}]\nplatform: ground\n")
    tables = tmp_path / "tables"
    assert main(["-q", "ingest", "--dataset-config", str(descriptor), "--out", str(tables)]) == 0
    assert read_meta(tables).sensors.platform.source == "dataset.yaml"
    run, skipped = plan(tables, ["lc_ekf", "lc_ekf_nhc"])
    assert (run, skipped) == (["lc_ekf", "lc_ekf_nhc"], [])


def test_nhc_filters_run_on_an_unknown_platform(plane_tables: Path, tmp_path: Path) -> None:
    tables = tmp_path / "tables"
    tables.mkdir()
    for p in plane_tables.iterdir():
        (tables / p.name).write_bytes(p.read_bytes())
    meta = json.loads((tables / "meta.json").read_text())
    del meta["sensors"]["platform"]  # a meta.json written before platforms were recorded
    (tables / "meta.json").write_text(json.dumps(meta))
    assert plan(tables, ["lc_ekf_nhc"]) == (["lc_ekf_nhc"], [])


def test_run_skip_unfit_writes_the_nhc_skip_and_exits_0(
    plane_tables: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "run"
    argv = ["run", str(plane_tables), "--filter", "lc_ekf_nhc", "--out", str(out)]
    assert main([*argv, "--skip-unfit"]) == 0
    assert FIXED_WING in capsys.readouterr().out
    metrics = json.loads((out / "metrics.json").read_text())
    assert (metrics["status"], metrics["reason"]) == ("skipped", FIXED_WING)
