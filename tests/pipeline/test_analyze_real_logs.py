"""``navreplay analyze`` on real recorded logs of ../shared/data (skipped when it is absent).

Each log is ingested, ``lc_ekf`` runs (the log has an IMU and GNSS fixes), ``tc_ekf`` is
skipped with its reason (no raw observables with orbits), and the report is written. The
error is against the truth where the log has one (comma2k19's reference pose), else against
the GNSS fixes.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from navreplay.pipeline.cli import main

DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data"
# log -> (path, reference, bound on the horizontal RMS in m, status). The ArduCopter flight is
# inconsistent: on a multirotor the heading at alignment comes from the GNSS course, which is
# not its heading, and the velocity innovations say so (the alignment issue).
LOGS = {
    "robot_localization_mcap": ("robot_localization/derived/test1_ros1.mcap", "gnss", 10.0, "ok"),
    "comma2k19": ("comma2k19_example_segment/original", "truth", 6.0, "ok"),
    "ardupilot_bin": (
        "uob_flightlab_ardupilot_bin/2023-07-06_10-12-18.bin",
        "gnss",
        15.0,
        "inconsistent",
    ),
}


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(LOGS))
def test_analyze_reports_a_real_log(
    name: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rel, reference, max_rms_m, status = LOGS[name]
    log = DATA / rel
    if not log.exists():
        pytest.skip(f"{log} absent (../shared/data is not beside the checkout)")
    out = tmp_path / name
    rc = main(["analyze", str(log), "--filters", "lc_ekf,tc_ekf", "--scenarios", "nominal",
               "--out", str(out)])  # fmt: skip
    assert rc == 0
    captured = capsys.readouterr()
    assert "[analyze] ingest" in captured.err
    assert "[analyze] run 1/1: lc_ekf" in captured.err
    assert f"report: {out / 'report' / 'index.html'}" in captured.out
    assert "skipped tc_ekf / *: tight coupling needs pseudoranges and orbits" in captured.out
    runs = {(r["filter"], r["scenario"]): r for r in
            json.loads((out / "report" / "tables" / "runs.json").read_text())}  # fmt: skip
    lc = runs[("lc_ekf", "nominal")]
    assert lc["status"] == status
    assert lc["reference"] == reference
    assert 0.05 < lc["pos_err_h_rms_m"] < max_rms_m
    assert runs[("tc_ekf", "nominal")]["status"] == "skipped"
    page = (out / "report" / "index.html").read_text()
    assert '<section id="audit">' in page
    assert '<section id="errors">' in page
