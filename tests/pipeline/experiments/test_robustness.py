"""The robustness sweep (``experiments.robustness``, ``navreplay experiment robustness``,
``python -m benchmarks.robustness_sweep``): the cells are what they say, the outages remove
the GNSS, the recovery is read from the run's records, and the files have every run."""

from __future__ import annotations

import csv
import functools
import math
from pathlib import Path

import numpy as np
import pytest

from benchmarks import robustness_sweep as script
from navreplay.ingest.meta import SensorMeta
from navreplay.pipeline.cli import main
from navreplay.pipeline.estimation.core.tables import Event
from navreplay.pipeline.estimation.ins.models import measurement as me
from navreplay.pipeline.experiments.drives import Tables
from navreplay.pipeline.experiments.robustness import grid as gr
from navreplay.pipeline.experiments.robustness import measure as rb
from navreplay.pipeline.experiments.robustness import sweep as rs
from navreplay.pipeline.params import load_params

NS = 1_000_000_000
REPO = Path(__file__).resolve().parents[3]


@functools.cache
def _params() -> gr.SweepParams:
    p = load_params(REPO / "params.yaml")
    return gr.SweepParams.of(p.synth.seoul_campus, p.synth.car_drives, p.filters)


@functools.cache
def _base() -> tuple[Tables, SensorMeta]:
    return gr.simulate(_params(), gr.BASE, 1)


def test_the_grid_has_every_axis_and_the_subsets_select() -> None:
    cells = gr.grid()
    assert len(cells) == len(set(cells)) == 4 * 3 * 2 + 4 + 4
    assert {c.grade for c in cells} == set(gr.GRADES)
    assert {c.fix_tau_s for c in cells} == {0.0, 10.0, 60.0}
    assert {c.gnss_hz for c in cells} == {1, 5, 10}
    assert {c.imu_hz for c in cells} == {25, 100, 400}
    assert gr.select(cells, ["base"]) == [gr.BASE]
    assert len(gr.select(cells, ["rates"])) == 4
    phone = gr.select(cells, ["phone tau60"])
    assert {(c.covariance, c.declared) for c in phone} == {(True, False), (False, False)}


def test_a_white_cell_has_the_synthesized_noise_and_the_grades_bias() -> None:
    """The raw fixes' horizontal RMS against the truth's antenna is the reported per-axis
    accuracy over both axes (white errors, ~300 epochs: within 15 %); the consumer grade's
    1 deg/s and 0.5 m/s^2 turn-on biases are in the truth's bias columns."""
    tables, sensors = _base()
    ref = rb.fix_reference(tables["gnss"], tables["truth"], sensors.lever_arm_m)
    h_acc = tables["gnss"].column("h_acc_m").to_numpy()
    expected = math.sqrt(2.0 * float(np.mean(h_acc**2)))
    assert ref.t_ns.size > 300
    assert ref.rms_between(0, 2**62) == pytest.approx(expected, rel=0.15)
    # without the lever arm the fixes sit 0.3 m off (the antenna is ahead of the IMU)
    off = rb.fix_reference(tables["gnss"], tables["truth"], (0.0, 0.0, 0.0))
    assert off.rms_between(0, 2**62) > ref.rms_between(0, 2**62)
    truth = tables["truth"]
    for axis in "xyz":
        g = truth.column(f"gyro_bias_{axis}_radps").to_numpy()
        a = truth.column(f"acc_bias_{axis}_mps2").to_numpy()
        assert abs(g.mean()) == pytest.approx(math.radians(1.0), rel=0.05)
        assert abs(a.mean()) == pytest.approx(0.5, rel=0.05)


def test_the_outages_remove_the_gnss_rows_inside_the_windows_only() -> None:
    tables, _ = _base()
    gapped = gr.with_outages(tables)
    windows = gr.outage_windows(tables)
    assert [(b - a) / NS for a, b in windows] == [10.0, 30.0, 60.0]
    for name in ("gnss", "gnss_obs"):
        t = tables[name].column("t_ns").to_numpy()
        kept = gapped[name].column("t_ns").to_numpy()
        inside = np.zeros(t.size, bool)
        for a, b in windows:
            inside |= (t >= a) & (t < b)
            assert not ((kept >= a) & (kept < b)).any()
        assert inside.any()
        assert np.array_equal(kept, t[~inside])
    assert gapped["imu"] is tables["imu"]


def test_a_cell_without_covariance_or_with_a_declared_imu() -> None:
    tables, sensors = _base()
    bare, sens = gr.prepare(tables, sensors, gr.Cell("consumer", 0.0, False))
    for col in gr.COV_COLUMNS:
        assert bare["gnss"].column(col).null_count == bare["gnss"].num_rows
    for col in gr.OBS_COV_COLUMNS:
        assert bare["gnss_obs"].column(col).null_count == bare["gnss_obs"].num_rows
    assert sens.imu_noise is None
    _, decl = gr.prepare(tables, sensors, gr.Cell("consumer", 0.0, True, declared=True))
    assert decl.imu_noise is not None
    assert decl.imu_noise.gyro_bias_sigma_radps == pytest.approx(math.radians(1.0))


def test_the_recovery_is_the_first_accepted_epoch_back() -> None:
    """A hand-built log: a window ends at 100 s, the fixes come back every second; the first
    two are rejected, a reset follows, the third is accepted (velocity rows accepted all
    along do not count for the position stream)."""
    epochs = np.arange(60, 111, dtype=np.int64) * NS
    epochs = epochs[(epochs < 90 * NS) | (epochs >= 100 * NS)]  # the window: [90, 100) s
    rows = [
        (100 * NS, me.S_POS, -1, 3, 0),
        (100 * NS, me.S_VEL, -1, 3, 1),
        (101 * NS, me.S_POS, -1, 3, 0),
        (101 * NS, me.S_VEL, -1, 3, 1),
        (102 * NS, me.S_POS, -1, 3, 1),
        (103 * NS, me.S_POS, -1, 3, 1),
    ]
    inn_i = np.array(rows, dtype=np.int64)
    reset = [Event(102 * NS, "gate_reset", "gnss_pos")]
    rec = rb.recovery(inn_i, reset, epochs, me.S_POS, 100 * NS, 200 * NS)
    assert (rec.epochs, rec.reset, rec.returned) == (3, True, 11)
    assert rb.recovery(inn_i, [], epochs, me.S_POS, 100 * NS, 200 * NS).reset is False
    # a reset of another stream, or one after the first acceptance, is not this recovery's
    other = [Event(101 * NS, "gate_reset", "gnss_vel"), Event(105 * NS, "gate_reset", "gnss_pos")]
    assert rb.recovery(inn_i, other, epochs, me.S_POS, 100 * NS, 200 * NS).reset is False
    assert rb.recovery(inn_i, [], epochs, me.S_VEL, 100 * NS, 200 * NS).epochs == 1
    # the next window starts before anything is accepted: never recovered
    assert rb.recovery(inn_i, [], epochs, me.S_POS, 100 * NS, 102 * NS).epochs is None
    assert not rs.WindowOutcome(10.0, 3, True, 0.5).recovered
    assert rs.WindowOutcome(10.0, 2, False, 0.5).recovered


def test_the_script_writes_every_run_and_prints_the_tables(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "sweep.csv"
    argv = ["--csv", str(out), "--seeds", "1", "--first-seed", "3", "--workers", "1",
            "--cells", "base", "--filters", "lc_ekf"]  # fmt: skip
    assert script.main(argv) == 0
    rows = list(csv.DictReader(out.open()))
    assert {r["seed"] for r in rows} == {"3"}
    assert [(r["filter"], r["scenario"]) for r in rows] == [
        ("lc_ekf", "nominal"),
        ("lc_ekf", "outages"),
    ]
    for col in ("ratio", "ref_rms_h_m", "nees_per_dof", "status", "recovery_epochs_60s",
                "reset_30s", "accuracy_ok", "integrity_ok", "nees_ok", "recovery_ok"):  # fmt: skip
        assert col in rows[0]
    nominal, outages = rows
    assert float(nominal["ratio"]) == pytest.approx(
        float(nominal["rms_h_m"]) / float(nominal["ref_rms_h_m"])
    )
    assert nominal["recovery_ok"] == ""
    assert outages["accuracy_ok"] == ""
    assert outages["recovery_ok"] in ("True", "False")
    printed = capsys.readouterr().out
    assert "consumer white cov 1/100Hz" in printed
    assert "recovery" in printed
    assert "2 runs" in printed


def test_the_experiment_stage_writes_the_runs_the_tables_and_a_note(tmp_path: Path) -> None:
    out = tmp_path / "robustness"
    argv = ["experiment", "robustness", "--seeds", "1", "--first-seed", "2", "--workers", "1",
            "--cells", "base", "--out", str(out)]  # fmt: skip
    assert main(argv) == 0
    runs = list(csv.DictReader((out / "runs.csv").open()))
    assert {r["seed"] for r in runs} == {"2"}
    assert {r["filter"] for r in runs} == set(rs.FILTERS)
    assert len(runs) == 2 * len(rs.FILTERS)
    cells = list(csv.DictReader((out / "cells.csv").open()))
    assert [c["cell"] for c in cells] == [gr.BASE.label()]
    points = {r["acceptance"]: r for r in csv.DictReader((out / "acceptance.csv").open())}
    assert set(points) == {"accuracy", "integrity", "nees", "recovery"}
    n = len(rs.FILTERS)
    assert points["integrity"]["all"].split(" ")[0].endswith(f"/{2 * n}")  # both runs
    assert points["recovery"]["all"].split(" ")[0].endswith(f"/{n}")  # the outage runs
    note = (out / "note.md").read_text()
    assert "1 seeds (seed 2)" in note
    assert "| acceptance |" in note
    assert gr.BASE.label() in note
    bad = ["experiment", "robustness", "--cells", "no such cell", "--out", str(tmp_path / "x")]
    assert main(bad) == 2
    assert not (tmp_path / "x").exists()


def _outcome(cell: gr.Cell, name: str, status: str, ratio: float, sigma: float) -> rs.Outcome:
    return rs.Outcome(cell, 1, name, "nominal", status, "", ratio, 1.0, 1.0, sigma)


def test_the_acceptance_points_are_the_issues() -> None:
    """Loose coupling: 0.8 x the raw fixes on white cells, 1.0 x on correlated ones; tight:
    1.0 x SPP; ``ok`` with an error over 10x its 3 sigma fails, another status does not."""
    white, tau10 = gr.BASE, gr.Cell("consumer", 10.0, True)
    assert _outcome(white, "lc_ekf", "ok", 0.85, 1.0).accuracy_ok() is False
    assert _outcome(tau10, "lc_ekf", "ok", 0.85, 1.0).accuracy_ok() is True
    assert _outcome(tau10, "fwekf", "ok", 1.05, 1.0).accuracy_ok() is False
    assert _outcome(white, "tc_ukf_nhc", "ok", 0.95, 1.0).accuracy_ok() is True
    assert _outcome(white, "tc_ekf", "ok", 0.5, 12.0).integrity_ok() is False
    assert _outcome(white, "tc_ekf", "inconsistent", 0.5, 12.0).integrity_ok() is True
    assert _outcome(white, "tc_ekf", "ok", 0.5, 9.0).integrity_ok() is True
    counts = rs.pass_counts(
        [_outcome(white, "lc_ekf", "ok", 0.5, 1.0), _outcome(white, "lc_ekf", "ok", 0.9, 1.0)],
        ["lc_ekf"],
    )
    assert counts[0] == ["accuracy", "1/2 (0/1)", "1/2 (0/1)"]
