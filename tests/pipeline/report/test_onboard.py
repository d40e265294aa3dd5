"""The report against the onboard estimate (``report.onboard``), and the TUM exports in evo.

The onboard estimate here is the nominal run's own estimate moved by a known offset (2 m north,
1 m up, through pymap3d, not navreplay's NED arithmetic), its yaw turned by 3 deg, and sampled
between the run's samples, so every difference the report computes has a known value.
"""

from __future__ import annotations

import csv
import json
import math
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pymap3d
import pytest

from navreplay.ingest.schema import TableName
from navreplay.ingest.tables import Provenance, read_table, write_table
from navreplay.pipeline.report.inputs import load_dataset
from navreplay.pipeline.report.render import render_dataset
from navreplay.pipeline.report.tables import fmt
from tests.pipeline.report.conftest import OUTAGE_S

NORTH_M, UP_M, YAW_DEG = 2.0, 1.0, 3.0


def _unwrapped_at(est: pa.Table, t_ns: np.ndarray) -> np.ndarray:
    yaw = np.unwrap(np.asarray(est.column("yaw_rad").to_numpy(), dtype=np.float64))
    t = np.asarray(est.column("t_ns").to_numpy(), dtype=np.float64)
    return np.interp(t_ns.astype(np.float64), t, yaw)


def _onboard(root: Path) -> pa.Table:
    """The nominal run moved and turned, at the midpoints between its samples."""
    est = read_table(root / "runs/lc_ekf/nominal/estimate.parquet", TableName.ESTIMATOR).table
    t = np.asarray(est.column("t_ns").to_numpy())
    tm = (t[:-1] + np.diff(t) // 2).astype(np.int64)

    def at(name: str) -> np.ndarray:
        v = np.asarray(est.column(name).to_numpy(), dtype=np.float64)
        return np.asarray(np.interp(tm.astype(np.float64), t.astype(np.float64), v))

    lat, lon, alt = pymap3d.ned2geodetic(
        NORTH_M, 0.0, -UP_M, at("lat_deg"), at("lon_deg"), at("alt_m")
    )
    cols = {
        "t_ns": pa.array(tm, pa.int64()),
        "lat_deg": lat,
        "lon_deg": lon,
        "alt_m": alt,
        **{c: at(c) for c in ("vel_n_mps", "vel_e_mps", "vel_d_mps", "roll_rad", "pitch_rad")},
        "yaw_rad": np.angle(np.exp(1j * (_unwrapped_at(est, tm) + math.radians(YAW_DEG)))),
        # the onboard EKF's velocity test ratio: above 1 (rejected) in one sample of ten
        "test_ratio_vel": np.where(np.arange(tm.size) % 10 == 0, 1.5, 0.2),
        # and its north velocity innovation: +0.3 and -0.1 alternating (mean 0.1, std 0.2)
        "innov_vel_n_mps": np.where(np.arange(tm.size) % 2 == 0, 0.3, -0.1),
    }
    return pa.table(cols)


@pytest.fixture(scope="module")
def with_onboard(dataset_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("onboard") / "ds"
    shutil.copytree(dataset_dir, root)
    write_table(
        root / "tables/estimator.parquet",
        TableName.ESTIMATOR,
        _onboard(root),
        Provenance.create("estimator"),
    )
    data = load_dataset("tiny", root / "tables", root / "runs", None)
    render_dataset(data, root / "report")
    return root


def _rows(root: Path) -> list[dict[str, str]]:
    with (root / "report/tables/onboard_comparison.csv").open() as f:
        return list(csv.DictReader(f))


def test_the_difference_from_the_onboard_estimate_is_the_known_offset(
    with_onboard: Path,
) -> None:
    rows = _rows(with_onboard)
    nominal = next(r for r in rows if r["scenario"] == "nominal" and r["scope"] == "run")
    # the onboard samples lie between the run's: interpolating the run costs well under 1 cm
    assert float(nominal["pos_h_rms_m"]) == pytest.approx(NORTH_M, abs=0.01)
    assert float(nominal["pos_v_rms_m"]) == pytest.approx(UP_M, abs=0.01)
    assert float(nominal["yaw_rms_deg"]) == pytest.approx(YAW_DEG, abs=0.05)
    assert float(nominal["roll_rms_deg"]) < 0.05
    assert float(nominal["vel_3d_rms_mps"]) < 0.05
    assert int(nominal["samples"]) > 100
    assert nominal["reference"] == "onboard"


def test_outage_drift_is_measured_against_the_onboard_estimate(with_onboard: Path) -> None:
    rows = _rows(with_onboard)
    (win,) = [r for r in rows if r["scenario"] == "outage_15s" and r["scope"] == "window"]
    assert float(win["duration_s"]) == pytest.approx(OUTAGE_S)
    # the onboard estimate is the nominal run moved by (2, 0, -1) m: the drift against it is
    # the outage run's departure from the nominal run plus that offset, by hand from Parquet
    root = with_onboard
    outage = read_table(root / "runs/lc_ekf/outage_15s/estimate.parquet", "estimator").table
    ob = read_table(root / "tables/estimator.parquet", "estimator").table
    w = json.loads((root / "runs/lc_ekf/outage_15s/metrics.json").read_text())["outage_windows"]
    t_ob = np.asarray(ob.column("t_ns").to_numpy())
    last = t_ob[(t_ob >= w[0]["start_ns"]) & (t_ob <= w[0]["end_ns"])][-1]

    def ecef(table: pa.Table, t: int) -> np.ndarray:
        tt = np.asarray(table.column("t_ns").to_numpy(), dtype=np.float64)
        lla = [np.interp(float(t), tt, table.column(c).to_numpy()) for c in ("lat_deg",
               "lon_deg", "alt_m")]  # fmt: skip
        return np.array(pymap3d.geodetic2ecef(*lla))

    hand = float(np.linalg.norm(ecef(ob, last) - ecef(outage, last)))
    assert float(win["pos_3d_end_m"]) == pytest.approx(hand, rel=1e-4, abs=1e-3)
    assert float(win["pos_3d_end_m"]) > math.hypot(NORTH_M, UP_M) - 0.5
    assert float(win["pos_3d_max_m"]) >= float(win["pos_3d_end_m"])
    distance = float(win["distance_m"])
    assert distance > 50.0
    assert float(win["drift_pct_distance"]) == pytest.approx(
        100.0 * float(win["pos_3d_end_m"]) / distance
    )


def test_the_page_shows_the_onboard_track_and_tables(with_onboard: Path) -> None:
    page = (with_onboard / "report/index.html").read_text()
    section = page.split('<section id="onboard">')[1].split("</section>")[0]
    assert "not truth" in section
    assert "Drift against the onboard estimate in the outage windows" in section
    # the onboard EKF's own test ratios: velocity only, rejected in one sample of ten
    ratios = section.split("innovation test ratios")[1]
    assert '<td class="t">vel</td>' in ratios
    ob = read_table(with_onboard / "tables/estimator.parquet", "estimator").table
    above = float(np.mean(np.asarray(ob.column("test_ratio_vel").to_numpy()) > 1.0))
    assert 0.09 < above < 0.11
    assert f"<td>{fmt(above)}</td>" in ratios
    assert '<td class="t">pos</td>' not in ratios
    innovations = section.split("The onboard EKF's innovations</h3>")[1]
    n = ob.num_rows
    mean = 0.1 if n % 2 == 0 else (0.3 * ((n + 1) // 2) - 0.1 * (n // 2)) / n
    assert f'<td class="t">vel_n_mps</td><td>{n}</td><td>{fmt(mean)}</td>' in innovations
    assert '<td class="t">pos_n_m</td>' not in innovations  # not logged: no row
    context = page.split('<section id="context">')[1].split("</section>")[0]
    assert "onboard test ratio" in context
    track = page.split('<section id="track">')[1].split("</section>")[0]
    assert "onboard estimate" in track


def test_without_an_onboard_estimate_there_is_no_section(dataset_dir: Path, tmp_path: Path) -> None:
    data = load_dataset("tiny", dataset_dir / "tables", dataset_dir / "runs", None)
    render_dataset(data, tmp_path / "r")
    assert '<section id="onboard">' not in (tmp_path / "r/index.html").read_text()
    assert not (tmp_path / "r/tables/onboard_comparison.csv").exists()


def _evo_ape(ref: Path, est: Path, *relation: str) -> float:
    evo = Path(sys.executable).parent / "evo_ape"  # a dev dependency: make test installs it
    done = subprocess.run(
        [str(evo), "tum", str(ref), str(est), "--t_max_diff", "0.001", *relation],
        capture_output=True, text=True, check=True, timeout=300,
    )  # fmt: skip
    found = re.search(r"^\s*rmse\s+(\S+)$", done.stdout, re.MULTILINE)
    assert found, done.stdout
    return float(found.group(1))


def test_evo_reads_the_exports_and_agrees_with_the_metrics(with_onboard: Path) -> None:
    run = with_onboard / "runs/lc_ekf/nominal"
    metrics = json.loads((run / "metrics.json").read_text())
    pair = (with_onboard / "report/trajectories/truth.tum", run / "trajectory.tum")
    assert _evo_ape(*pair) == pytest.approx(metrics["pos_err_3d_rms_m"], abs=1e-3)
    # the orientation too: evo's rotation angle against the metrics' attitude error (the RMS
    # of each component of the rotation vector, so their root sum square is the angle's RMS)
    att = math.sqrt(sum(v**2 for v in metrics["att_err_rms_rad"].values()))
    assert _evo_ape(*pair, "--pose_relation", "angle_deg") == pytest.approx(
        math.degrees(att), abs=0.01
    )


def test_a_report_and_a_run_rewrite_their_own_folders(with_onboard: Path) -> None:
    """Every kind of file navreplay writes (the TUM exports too) counts as its own: a second
    report into the same folder, and a second run into the same run folder, replace them."""
    from navreplay.ingest.atomic import check_output_dir

    data = load_dataset("tiny", with_onboard / "tables", with_onboard / "runs", None)
    render_dataset(data, with_onboard / "report")
    assert (with_onboard / "report/trajectories/onboard.tum").is_file()
    check_output_dir(with_onboard / "runs/lc_ekf/nominal")  # raises on a file it did not write
