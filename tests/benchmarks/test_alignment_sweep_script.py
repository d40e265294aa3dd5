"""`python -m benchmarks.alignment_sweep`: the grid, the CSV of every run and the table."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest

from benchmarks import alignment_sweep as sw
from navreplay.pipeline.params import load_params


def test_the_grid_is_the_issues_sweep() -> None:
    cells = sw.grid()
    assert len(cells) == 3 * 4 * 3 * 2
    assert {c.kind for c in cells} == {"static", "rolling", "reversing"}
    assert {c.bias_dps for c in cells} == {0.01, 0.1, 0.3, 1.0}
    assert {c.noise_m for c in cells} == {0.5, 1.5, 5.0}
    assert sw.Cell("static", 1.0, 5.0, False).yaw_limit_deg == 5.0
    assert sw.Cell("static", 1.0, 5.0, True).yaw_limit_deg == 3.0


def test_the_cells_are_what_they_say(tmp_path: Path) -> None:
    """The fixes' median reported accuracy is the cell's noise; the bias is in the IMU and the
    truth; without velocity the gnss table has none; the first motion is where the car
    starts (15 s at rest in stop-and-go traffic, the first sample of a rolling start)."""
    params = load_params(sw.REPO / "params.yaml")
    tables, sensors = sw.simulate(params, "static", 5.0, 1)
    h_acc = tables["gnss"].column("h_acc_m").to_numpy()
    assert float(sorted(h_acc)[h_acc.size // 2]) == pytest.approx(5.0, rel=0.01)
    biased, sens = sw.with_bias(tables, sensors, 1.0, 1)
    for axis in "xyz":
        d = biased["imu"].column(f"gyro_{axis}_radps").to_numpy()
        d = d - tables["imu"].column(f"gyro_{axis}_radps").to_numpy()
        assert abs(d.mean()) == pytest.approx(0.017453, rel=1e-3)
    assert sens.imu_noise is not None
    assert sens.imu_noise.gyro_bias_sigma_radps == pytest.approx(0.017453, rel=1e-3)
    bare = sw.without_velocity(biased)["gnss"]
    assert bare.column("vel_n_mps").null_count == bare.num_rows
    t0 = int(tables["imu"].column("t_ns")[0].as_py())
    t_motion = sw.first_motion_ns(tables["truth"], t0, "static")
    assert 15.0 < (t_motion - t0) * 1e-9 < 18.0
    assert sw.first_motion_ns(tables["truth"], t0, "rolling") == t0


def test_the_script_writes_every_run_and_prints_the_table(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "sweep.csv"
    argv = ["--csv", str(out), "--seeds", "1", "--workers", "1", "--kinds", "rolling",
            "--filters", "lc_ekf"]  # fmt: skip
    assert sw.main(argv) == 0
    rows = list(csv.DictReader(out.open()))
    assert len(rows) == 4 * 3 * 2
    assert {r["filter"] for r in rows} == {"lc_ekf"}
    assert all(r["kind"] == "rolling" for r in rows)
    printed = capsys.readouterr().out
    assert "aligned after motion s" in printed
    assert "24 runs" in printed
