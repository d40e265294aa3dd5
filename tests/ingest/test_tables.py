"""Atomic, checksummed Parquet I/O with provenance."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from navreplay.ingest.atomic import atomic_directory, atomic_write_json
from navreplay.ingest.errors import (
    CorruptLogError,
    IngestError,
    ProvenanceError,
    TableValidationError,
)
from navreplay.ingest.schema import from_columns
from navreplay.ingest.tables import (
    PROVENANCE_KEY,
    Provenance,
    TableWriter,
    read_provenance,
    read_table,
    sha256_file,
    write_table,
)

from .test_schema import imu_columns


@pytest.fixture
def source(tmp_path: Path) -> Path:
    p = tmp_path / "drive.mcap"
    p.write_bytes(b"\x89MCAP0\r\n fake log bytes")
    return p


def test_written_file_carries_provenance(tmp_path: Path, source: Path) -> None:
    target = tmp_path / "tables" / "imu.parquet"
    prov = Provenance.create("imu", sources=[source], params={"ingest": {"strict": False}})
    write_table(target, "imu", from_columns("imu", imu_columns()), prov)
    back = read_provenance(target)
    assert back == prov
    assert back.sources[0].name == "drive.mcap"
    assert back.sources[0].sha256 == sha256_file(source)
    assert len(back.sources[0].sha256) == 64
    assert back.package_version
    assert back.params_hash is not None
    assert len(back.params_hash) == 16
    # The record is in the Parquet schema metadata, readable by any Parquet tool.
    assert PROVENANCE_KEY in pq.read_schema(target).metadata


def test_git_commit_is_recorded_when_running_from_a_checkout(tmp_path: Path) -> None:
    repo = Path(__file__).resolve().parents[2]
    head = subprocess.run(
        ["git", "-C", str(repo), "rev-parse", "HEAD"], capture_output=True, text=True, check=False
    )
    if head.returncode != 0:
        pytest.skip("not running from a git checkout with a commit")
    prov = Provenance.create("imu")
    assert prov.git_commit is not None
    assert prov.git_commit.removesuffix("+dirty") == head.stdout.strip()


def test_round_trip_keeps_values_and_nan(tmp_path: Path) -> None:
    cols = imu_columns()
    cols["gyro_x_radps"][2] = np.nan
    target = tmp_path / "imu.parquet"
    write_table(target, "imu", from_columns("imu", cols), Provenance.create("imu"))
    back = read_table(target, "imu").table
    np.testing.assert_array_equal(back.column("t_ns").to_numpy(), cols["t_ns"])
    assert np.isnan(back.column("gyro_x_radps").to_numpy()[2])
    assert back.column("gyro_x_radps").null_count == 0


def test_same_input_gives_same_bytes(tmp_path: Path, source: Path) -> None:
    table = from_columns("imu", imu_columns())
    for name in ("a.parquet", "b.parquet"):
        write_table(tmp_path / name, "imu", table, Provenance.create("imu", sources=[source]))
    assert (tmp_path / "a.parquet").read_bytes() == (tmp_path / "b.parquet").read_bytes()


def test_exception_midway_leaves_no_file_and_keeps_earlier_one(tmp_path: Path) -> None:
    target = tmp_path / "imu.parquet"
    write_table(target, "imu", from_columns("imu", imu_columns(3)), Provenance.create("imu"))
    before = target.read_bytes()
    chunk = from_columns("imu", imu_columns(4))

    class InjectedError(Exception):
        pass

    def write_then_fail() -> None:
        with TableWriter(target, "imu", Provenance.create("imu")) as writer:
            writer.write(chunk)
            raise InjectedError

    with pytest.raises(InjectedError):
        write_then_fail()
    assert target.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["imu.parquet"]


def test_invalid_chunk_aborts_the_whole_write(tmp_path: Path) -> None:
    target = tmp_path / "imu.parquet"
    first = from_columns("imu", imu_columns(4))

    def write_twice() -> None:
        with TableWriter(target, "imu", Provenance.create("imu")) as writer:
            writer.write(first)
            writer.write(first)  # same times again: not after the previous chunk

    with pytest.raises(TableValidationError, match="previous chunk") as err:
        write_twice()
    assert err.value.path == target
    assert not target.exists()


_KILLED_WRITER = textwrap.dedent(
    """
    import sys, time
    import numpy as np
    from navreplay.ingest.schema import from_columns
    from navreplay.ingest.tables import Provenance, TableWriter

    n = 1000
    with TableWriter(sys.argv[1], "imu", Provenance.create("imu")) as w:
        for k in range(1000):
            t = (np.arange(n, dtype=np.int64) + k * n) * 10_000_000
            cols = {"t_ns": t}
            for c in ("acc_x_mps2", "acc_y_mps2", "acc_z_mps2",
                      "gyro_x_radps", "gyro_y_radps", "gyro_z_radps"):
                cols[c] = np.zeros(n)
            w.write(from_columns("imu", cols))
            if k == 20:
                print("row group 20 written", flush=True)
                time.sleep(60)
    """
)


def test_sigkilled_writer_leaves_nothing_at_target_and_earlier_file_untouched(
    tmp_path: Path,
) -> None:
    target = tmp_path / "imu.parquet"
    write_table(target, "imu", from_columns("imu", imu_columns(3)), Provenance.create("imu"))
    before = target.read_bytes()
    proc = subprocess.Popen(
        [sys.executable, "-c", _KILLED_WRITER, str(target)],
        stdout=subprocess.PIPE,
        text=True,
    )
    assert proc.stdout is not None
    assert proc.stdout.readline().strip() == "row group 20 written"
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait(timeout=30)
    assert target.read_bytes() == before
    leftovers = [p for p in tmp_path.iterdir() if p.name != "imu.parquet"]
    assert len(leftovers) == 1
    assert leftovers[0].name.startswith(".imu.parquet.")
    # The next write to the same target cleans up the dead writer's temporary.
    write_table(target, "imu", from_columns("imu", imu_columns(5)), Provenance.create("imu"))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["imu.parquet"]
    assert read_table(target, "imu").table.num_rows == 5


def test_empty_writer_produces_full_schema(tmp_path: Path) -> None:
    target = tmp_path / "gnss.parquet"
    with TableWriter(target, "gnss", Provenance.create("gnss")):
        pass
    table = read_table(target, "gnss").table
    assert table.num_rows == 0
    assert "speed_acc_mps" in table.column_names


def test_reader_rejects_foreign_parquet(tmp_path: Path) -> None:
    target = tmp_path / "imu.parquet"
    pq.write_table(from_columns("imu", imu_columns()), target)
    with pytest.raises(ProvenanceError, match="no navreplay provenance"):
        read_table(target, "imu")


def test_reader_rejects_other_table(tmp_path: Path) -> None:
    target = tmp_path / "imu.parquet"
    write_table(target, "imu", from_columns("imu", imu_columns()), Provenance.create("imu"))
    with pytest.raises(ProvenanceError, match="expected 'gnss'"):
        read_table(target, "gnss")


def test_reader_detects_a_flipped_byte(tmp_path: Path) -> None:
    target = tmp_path / "imu.parquet"
    cols = imu_columns(5000)
    cols["acc_x_mps2"] = np.random.default_rng(1).normal(size=5000)
    write_table(target, "imu", from_columns("imu", cols), Provenance.create("imu"))
    data = bytearray(target.read_bytes())
    data[len(data) // 3] ^= 0xFF
    target.write_bytes(bytes(data))
    with pytest.raises((CorruptLogError, TableValidationError)):
        read_table(target, "imu")


def test_missing_file_says_how_to_make_it(tmp_path: Path) -> None:
    with pytest.raises(IngestError, match="navreplay ingest"):
        read_table(tmp_path / "imu.parquet", "imu")


def test_provenance_must_match_table(tmp_path: Path) -> None:
    with pytest.raises(ProvenanceError, match="provenance is for table 'gnss'"):
        TableWriter(tmp_path / "imu.parquet", "imu", Provenance.create("gnss"))


def test_atomic_directory_replaces_whole_or_nothing(tmp_path: Path) -> None:
    target = tmp_path / "run"
    with atomic_directory(target) as d:
        (d / "a.json").write_text("1")

    def fill_then_fail() -> None:
        with atomic_directory(target) as d:
            (d / "b.json").write_text("2")
            raise RuntimeError("injected")

    with pytest.raises(RuntimeError, match="injected"):
        fill_then_fail()
    assert sorted(p.name for p in target.iterdir()) == ["a.json"]
    with atomic_directory(target) as d:
        (d / "c.json").write_text("3")
    assert sorted(p.name for p in target.iterdir()) == ["c.json"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]


def test_json_is_deterministic_and_has_no_nan(tmp_path: Path) -> None:
    atomic_write_json(tmp_path / "m.json", {"b": float("nan"), "a": (1, 2.5)})
    assert (
        tmp_path / "m.json"
    ).read_text() == '{\n  "a": [\n    1,\n    2.5\n  ],\n  "b": null\n}\n'
