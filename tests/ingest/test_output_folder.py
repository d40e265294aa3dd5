"""The output folder of every command (``ingest.atomic.atomic_directory``): a folder holding a
user's files, or a path that is a file, is refused with the reason and what to do, and
nothing is written, moved or deleted (bad-input defects 1 and 2 of issue 23)."""

from __future__ import annotations

from pathlib import Path

import pytest

from navreplay.ingest.api import ingest
from navreplay.ingest.atomic import atomic_directory
from navreplay.ingest.errors import OutputPathError
from navreplay.pipeline.cli import EXIT_ERROR, main

from .mavlogs import DriveSpec, tlog_drive


def _tlog(tmp_path: Path) -> Path:
    return tlog_drive(DriveSpec(seconds=1.0)).write(tmp_path / "flight.tlog")


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def test_a_folder_holding_a_users_file_is_refused_and_kept(tmp_path: Path) -> None:
    out = tmp_path / "flights"
    out.mkdir()
    (out / "notes.txt").write_text("my notes\n")
    (out / "old.tlog").write_bytes(b"\xfe" * 10)
    with pytest.raises(OutputPathError) as err:
        ingest([_tlog(tmp_path)], out)
    text = str(err.value)
    assert str(out) in text
    assert "notes.txt" in text
    assert "old.tlog" in text
    assert "new or empty folder" in text
    assert _snapshot(out) == {"notes.txt": b"my notes\n", "old.tlog": b"\xfe" * 10}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["flight.tlog", "flights"]


def test_the_cli_refuses_a_users_folder_with_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "flights"
    (out / "sub").mkdir(parents=True)
    (out / "sub" / "photo.jpg").write_bytes(b"\xff\xd8\xff")
    assert main(["ingest", str(_tlog(tmp_path)), "--out", str(out)]) == EXIT_ERROR
    err = capsys.readouterr().err
    assert "sub/photo.jpg" in err
    assert "Traceback" not in err
    assert _snapshot(out) == {"sub/photo.jpg": b"\xff\xd8\xff"}


def test_a_previous_output_and_an_empty_folder_are_replaced(tmp_path: Path) -> None:
    log = _tlog(tmp_path)
    empty = tmp_path / "empty"
    empty.mkdir()
    ingest([log], empty)
    first = _snapshot(empty)
    assert {"imu.parquet", "ingest_report.json"} <= first.keys()
    ingest([log], empty)  # a previous navreplay output: replaced whole
    assert _snapshot(empty).keys() == first.keys()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


@pytest.mark.parametrize("where", ["file", "inside_file"])
def test_an_output_path_that_is_a_file_is_refused_and_nothing_is_left(
    tmp_path: Path, where: str
) -> None:
    victim = tmp_path / "out"
    victim.write_text("a user's file\n")
    out = victim if where == "file" else victim / "tables"
    with pytest.raises(OutputPathError, match="a file, not a folder") as err:
        ingest([_tlog(tmp_path)], out)
    assert str(out) in str(err.value)
    assert victim.read_text() == "a user's file\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["flight.tlog", "out"]


def test_the_cli_refuses_a_file_as_out_with_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    victim = tmp_path / "out"
    victim.write_text("keep me\n")
    assert main(["ingest", str(_tlog(tmp_path)), "--out", str(victim)]) == EXIT_ERROR
    assert "a file, not a folder" in capsys.readouterr().err
    assert victim.read_text() == "keep me\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["flight.tlog", "out"]


def test_folders_created_for_a_failed_output_are_removed(tmp_path: Path) -> None:
    target = tmp_path / "a" / "b" / "out"

    def fill_then_fail() -> None:
        with atomic_directory(target) as tmp:
            (tmp / "x.json").write_text("{}")
            raise RuntimeError("midway")

    with pytest.raises(RuntimeError):
        fill_then_fail()
    assert list(tmp_path.iterdir()) == []


def test_a_link_in_the_output_folder_is_foreign(tmp_path: Path) -> None:
    out = tmp_path / "out"
    out.mkdir()
    (out / "data.json").symlink_to(tmp_path / "elsewhere.json")
    with pytest.raises(OutputPathError, match=r"data\.json"), atomic_directory(out):
        pass
    assert (out / "data.json").is_symlink()
