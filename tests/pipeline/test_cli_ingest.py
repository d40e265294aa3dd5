"""`navreplay ingest`: exit codes, messages, --list, --strict, descriptors."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from navreplay.pipeline.cli import main
from tests.ingest.roslogs import fix_stream, imu_data, imu_stream, write_mcap


@pytest.fixture
def log(tmp_path: Path) -> Path:
    return write_mcap(tmp_path / "drive.mcap", [imu_stream(imu_data(2000)), fix_stream(40)])


def test_ingest_writes_the_tables_and_says_so(
    log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "tables"
    assert main(["ingest", str(log), "--out", str(out)]) == 0
    assert (out / "imu.parquet").is_file()
    assert (out / "ingest_report.json").is_file()
    text = capsys.readouterr().out
    assert "imu" in text
    assert "2000 rows" in text
    assert "complete" in text


def test_list_shows_streams_and_selection_without_writing(
    log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["ingest", "--list", str(log)]) == 0
    text = capsys.readouterr().out
    assert "/imu/data" in text
    assert "sensor_msgs/msg/Imu" in text
    assert "2000" in text
    assert "100.00 Hz" in text
    assert "imu       <- /imu/data" in text
    assert sorted(p.name for p in tmp_path.iterdir()) == ["drive.mcap"]


def test_not_a_log_exits_2_naming_file_and_offset(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "photo.mcap"
    bad.write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(100))
    assert main(["ingest", str(bad), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert str(bad) in err
    assert "offset 0" in err
    assert "PNG" in err
    assert not (tmp_path / "out").exists()


def test_strict_turns_a_truncation_into_an_error(
    log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    os.truncate(log, log.stat().st_size // 2)
    assert main(["ingest", str(log), "--out", str(tmp_path / "s"), "--strict"]) == 2
    assert "truncated" in capsys.readouterr().err
    assert not (tmp_path / "s").exists()
    assert main(["ingest", str(log), "--out", str(tmp_path / "r")]) == 0
    assert "truncated" in capsys.readouterr().out
    assert (tmp_path / "r" / "imu.parquet").is_file()


def test_logs_come_from_the_descriptor(log: Path, tmp_path: Path) -> None:
    ds = tmp_path / "ds"
    ds.mkdir()
    (ds / "dataset.yaml").write_text(
        "id: my_drive\nlogs: [../drive.mcap]\nrequired: [imu, gnss]\nimu: {topic: /imu/data}\n"
    )
    out = ds / "tables"
    assert main(["ingest", "--dataset-config", str(ds / "dataset.yaml"), "--out", str(out)]) == 0
    assert (out / "gnss.parquet").is_file()
    assert '"dataset": "my_drive"' in (out / "meta.json").read_text()


def test_out_is_required_unless_listing(log: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["ingest", str(log)]) == 2
    assert "--out" in capsys.readouterr().err
