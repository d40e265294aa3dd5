"""``navreplay analyze`` on generated logs: a log no filter can start on exits 3 with the
reason in the summary and the report; outages asked for with ``--outage``."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from navreplay.pipeline.cli import main


@pytest.fixture(scope="module")
def still_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Paper 004's drive with no acceleration: 50 s at standstill (a bench log)."""
    root = tmp_path_factory.mktemp("still")
    params = root / "still.yaml"
    params.write_text(
        "synth:\n  fwekf_reference:\n    accel_amplitude_mps2: 0.0\n    motion_s: 30.0\n"
    )
    assert main(["-q", "synth", "fwekf_reference", "--params", str(params),
                 "--out", str(root / "raw")]) == 0  # fmt: skip
    return root / "raw" / "fwekf_reference.tlog"


def test_a_log_no_filter_can_start_on_exits_3_and_says_why(
    still_log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "a"
    rc = main(["-q", "analyze", str(still_log), "--filters", "lc_ekf", "--scenarios", "nominal",
               "--out", str(out)])  # fmt: skip
    assert rc == 3
    text = capsys.readouterr().out.splitlines()
    assert text[2] == "  no filter could run on this log:"
    assert "not aligned: the filter never aligned" in text[3]
    (run,) = json.loads((out / "report" / "tables" / "runs.json").read_text())
    assert (run["status"], run["epochs"]) == ("not_aligned", 0)
    assert "never aligned" in run["reason"]
    page = (out / "report" / "index.html").read_text()
    assert "not_aligned" in page
    assert "never aligned" in page


def test_run_of_a_filter_that_never_aligns_exits_3(
    still_log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    tables = tmp_path / "tables"
    assert main(["-q", "ingest", str(still_log), "--out", str(tables)]) == 0
    rc = main(["-q", "run", str(tables), "--filter", "lc_ekf", "--out", str(tmp_path / "run")])
    assert rc == 3
    assert "nominal: not_aligned, 0 epochs: the filter never aligned" in capsys.readouterr().out
    metrics = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert metrics["status"] == "not_aligned"


def test_a_bad_outage_option_is_a_usage_error(
    still_log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rc = main(["-q", "analyze", str(still_log), "--outage", "30 minutes",
               "--out", str(tmp_path / "a")])  # fmt: skip
    assert rc == 2
    assert "--outage '30 minutes': give a length" in capsys.readouterr().err
    assert not (tmp_path / "a").exists()
