"""`navreplay fleet` on this machine: the logs found, a bad log recorded, a rerun resumed,
GNSS trouble flagged. The same fleet on a Dask cluster: tests/pipeline/test_dask_cluster.py."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from navreplay.pipeline import fleet as fl
from navreplay.pipeline.cli import main
from tests.ingest.mavlogs import write_tlog_drive


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    """Two 20 s tlogs (a vehicle at rest with fixes) and a file that is no log."""
    root = tmp_path_factory.mktemp("fleet_logs")
    (root / "b").mkdir()
    first = write_tlog_drive(root / "rig.tlog", 20.0)
    second = write_tlog_drive(root / "b" / "rig.tlog", 20.0)  # the same stem: named rig_2
    bad = root / "notes.txt"
    bad.write_text("not a log\n")
    return [first, second, bad]


def test_logs_are_found_in_folders_and_named_uniquely(logs: list[Path], tmp_path: Path) -> None:
    root = logs[0].parent
    tasks, not_logs = fl.log_tasks([root / "rig.tlog", root / "b", root / "notes.txt"])
    assert [t.name for t in tasks] == ["rig", "rig_2", "notes"]  # a file named is taken
    assert tasks[1].paths == (str((root / "b" / "rig.tlog").resolve()),)
    assert not_logs == []
    # in a folder: files sharing a stem are one log, a file that is no log is listed
    folder = tmp_path / "flights"
    folder.mkdir()
    (folder / "README.md").write_text("# my flights\n")
    for suffix in ("tlog", "bin"):
        (folder / f"f1.{suffix}").write_bytes(logs[0].read_bytes())
    tasks, not_logs = fl.log_tasks([folder])
    assert [(t.name, len(t.paths)) for t in tasks] == [("f1", 2)]
    assert [Path(n["file"]).name for n in not_logs] == ["README.md"]
    assert not_logs[0]["reason"]
    with pytest.raises(FileNotFoundError, match="no such log or folder"):
        fl.log_tasks([root / "missing.bin"])


def test_a_bad_log_is_recorded_and_the_others_are_analyzed(
    logs: list[Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "fleet"
    args = ["fleet", *map(str, logs), "--filters", "lc_ekf", "--scenarios", "nominal",
            "--workers", "2", "--out", str(out)]  # fmt: skip
    assert main(args) == 4  # some logs failed
    text = capsys.readouterr()
    assert "notes: FAILED: UnsupportedFormatError" in text.err
    assert "[fleet] 3/3 done, 1 failed" in text.err
    doc = json.loads((out / "fleet.json").read_text())
    assert [r["name"] for r in doc["logs"]] == ["rig", "rig_2"]
    assert [f["name"] for f in doc["failed"]] == ["notes"]
    assert "Traceback" in doc["failed"][0]["traceback"]
    for name in ("rig", "rig_2"):
        assert (out / "logs" / name / "report" / "index.html").is_file()
        assert (out / "logs" / name / "tables" / "imu.parquet").is_file()
    page = (out / "index.html").read_text()
    assert "Logs that could not be analyzed" in page
    assert "UnsupportedFormatError" in page
    assert (out / "summary" / "index.html").is_file()
    assert not (out / ".tasks").exists()  # the task store is removed once the summary is out


def test_a_rerun_after_an_interruption_analyzes_only_what_is_missing(
    logs: list[Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from navreplay.pipeline.params import load_params

    params = load_params(None)
    real = fl.analyze_log
    calls: list[str] = []

    def interrupted(job: fl.FleetJob, task: fl.LogTask) -> Any:
        if calls:
            raise KeyboardInterrupt  # the user stops it during the second log
        calls.append(task.name)
        return real(job, task)

    monkeypatch.setattr(fl, "analyze_log", interrupted)
    kw: dict[str, Any] = {"filters": ["lc_ekf"], "scenarios": ["nominal"]}
    with pytest.raises(KeyboardInterrupt):
        fl.fleet(logs[:2], tmp_path / "f", params, **kw)
    assert calls == ["rig"]

    def counted(job: fl.FleetJob, task: fl.LogTask) -> Any:
        calls.append(task.name)
        return real(job, task)

    monkeypatch.setattr(fl, "analyze_log", counted)
    res = fl.fleet(logs[:2], tmp_path / "f", params, **kw)
    assert calls == ["rig", "rig_2"]  # rig came from the first run's store
    assert [r["name"] for r in res.rows] == ["rig", "rig_2"]


def test_gnss_trouble_is_flagged_from_the_fixes(tmp_path: Path) -> None:
    t = np.concatenate([np.arange(0, 30), np.arange(42, 60)]).astype(np.int64) * 10**9
    n = t.size
    gnss = pa.table({
        "t_ns": t, "lat_deg": np.full(n, 52.0), "lon_deg": np.full(n, 4.0),
        "alt_m": np.full(n, 10.0), "fix_type": np.full(n, 3, np.int8),
        "num_sats": np.where(np.arange(n) == 5, 4, 9).astype(np.int16),
        "h_acc_m": np.full(n, 1.2),
    })  # fmt: skip
    pq.write_table(gnss, tmp_path / "gnss.parquet")  # the columns gnss_trouble reads
    assert fl.gnss_trouble(tmp_path) == ["fixes stop for 13.0 s", "as few as 4 satellites used"]
    assert fl.gnss_trouble(tmp_path / "none") == ["no GNSS fixes"]


def test_an_output_path_that_is_a_file_is_refused(
    logs: list[Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "fleet.txt"
    out.write_text("mine\n")
    assert main(["fleet", str(logs[0]), "--out", str(out)]) == 2
    assert "the output path is a file" in capsys.readouterr().err
    assert out.read_text() == "mine\n"
    assert main(["fleet", str(tmp_path / "nothing_here"), "--out", str(tmp_path / "o")]) == 2
    assert "no such log or folder" in capsys.readouterr().err


def test_the_reduction_per_k_is_pooled_over_the_windows_of_every_log(tmp_path: Path) -> None:
    """Paired per (log, scenario, window): two logs' sats_4 windows form one sample."""
    from navreplay.pipeline.params import load_params

    params = load_params(None)
    a, b = params.outages.pairs[0]
    errs = {"one": [(10.0, 5.0), (20.0, 8.0)], "two": [(30.0, 12.0)]}
    reports = []
    for log, pairs in errs.items():
        rep = tmp_path / log / "report"
        (rep / "tables").mkdir(parents=True)
        lines = ["filter,scenario,window,sats,err_mean_m,reference"]
        for i, (ea, eb) in enumerate(pairs):
            lines += [f"{a},sats_4,{i},4,{ea},truth", f"{b},sats_4,{i},4,{eb},truth"]
        lines.append(f"{a},sats_3,0,3,1.0,truth")  # a k without its pair: no row
        (rep / "tables" / "windows.csv").write_text("\n".join(lines) + "\n")
        reports.append(rep)
    (row,) = fl.pooled_reduction(reports, params)
    assert row["pair"] == f"{a} -> {b}"
    assert row["sats"] == 4
    assert row["windows"] == 3
    assert row["logs"] == 2
    assert row["reduction_pct"] == pytest.approx(100 * (1 - 25.0 / 60.0))
    assert row["ci_low_pct"] <= row["reduction_pct"] <= row["ci_high_pct"]
    assert row["reference"] == "truth"
