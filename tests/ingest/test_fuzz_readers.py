"""Bad-input fuzzing over every reader (issue 23): a small valid log of each format
(``fuzzseeds``) damaged one way per case (``fuzzing``: empty, random bytes, truncated at a
random byte, bit flips, the file twice, a zeroed block, a directory in its place), ingested in
this process under a per-case time limit. Every case must end in a typed error naming a file
with nothing left at or beside the output folder (the CLI's exit 2), or in tables with each
file's completeness in the report: no traceback, no hang, nothing half-written.

Seeded: the same 267 cases every run (about 23 s of CPU: 30-70 s wall on two cores shared
with other work); three go through the CLI in a subprocess. The cases the fuzzer found, and
their fixes, are pinned by tests at the end of this module and in ``test_bad_input_defects``.
"""

from __future__ import annotations

import os
import shutil
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from navreplay.ingest.api import ingest
from navreplay.ingest.errors import CorruptLogError, IngestError

from .fuzzing import MUTATIONS, Case, run_case
from .fuzzseeds import SEEDS, Seed

#: random mutations per format and kind (truncate, bitflip, zero_block); RINEX-based seeds
#: solve satellite orbits per case and get fewer
REPEATS = {"rinex_obs": 3, "rinex_nav": 3, "gnsslogger": 3}
RANDOM_KINDS = ("truncate", "bitflip", "zero_block")


def _cases() -> list[Case]:
    cases = []
    for fmt in SEEDS:
        for mutation in MUTATIONS:
            n = REPEATS.get(fmt, 5) if mutation in RANDOM_KINDS else 1
            cases += [Case(fmt, mutation, seed) for seed in range(n)]
    return cases


CASES = _cases()


@pytest.fixture(scope="module")
def seeds(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Seed]:
    root = tmp_path_factory.mktemp("seeds")
    out = {}
    for name, make in SEEDS.items():
        (root / name).mkdir()
        out[name] = make(root / name)
        # the first ingest of a format compiles its readers' kernels (numba: tens of seconds
        # of CPU on a slow host with a cold cache); done here, so that a case's time limit
        # measures the case's own work
        ingest(list(out[name].logs), root / f"{name}-warm")
    return out


def test_there_are_a_few_hundred_cases_over_every_format() -> None:
    assert 250 <= len(CASES) <= 400
    assert {c.fmt for c in CASES} == set(SEEDS)


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.id)
def test_damaged_log_gives_a_typed_error_or_a_flagged_prefix(
    case: Case, seeds: dict[str, Seed], tmp_path: Path
) -> None:
    seed = seeds[case.fmt]
    verdict = run_case(case, seed.logs, seed.target, tmp_path)
    assert verdict.outcome != "failure", verdict.detail


def test_every_seed_ingests_cleanly(seeds: dict[str, Seed], tmp_path: Path) -> None:
    for name, seed in seeds.items():
        result = ingest(list(seed.logs), tmp_path / name)
        flags = {f for entry in result.report["files"] for f in entry["completeness"]}
        assert flags == {"complete"}, name
        assert all(result.tables.values()), (name, result.tables)


def test_an_unreadable_file_is_a_clear_error(seeds: dict[str, Seed], tmp_path: Path) -> None:
    if os.geteuid() == 0:
        pytest.skip("running as root: chmod 000 does not stop root from reading the file")
    log = tmp_path / "flight.tlog"
    shutil.copy(seeds["tlog"].target, log)
    log.chmod(0)
    try:
        with pytest.raises(IngestError, match="cannot read") as err:
            ingest([log], tmp_path / "out")
    finally:
        log.chmod(0o644)
    assert str(log) in str(err.value)
    assert not (tmp_path / "out").exists()


# ------------------------------------------------------------------------ the CLI, a sample
CLI_SAMPLE = [
    Case("tlog", "empty"),
    Case("mcap", "truncate", 1),
    Case("ulog", "bitflip", 2),
]


@pytest.mark.parametrize("case", CLI_SAMPLE, ids=lambda c: c.id)
def test_the_cli_exits_0_or_2_without_a_traceback(
    case: Case, seeds: dict[str, Seed], tmp_path: Path
) -> None:
    from .fuzzing import _copy, mutate

    seed = seeds[case.fmt]
    logs, victim = _copy(seed.logs, seed.target, tmp_path / "case")
    mutate(victim, case.mutation, np.random.default_rng(case.seed))
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "navreplay.pipeline.cli", "-q", "ingest", *map(str, logs)]
    proc = subprocess.run(
        [*cmd, "--out", str(out)], capture_output=True, text=True, timeout=120, check=False
    )
    assert "Traceback" not in proc.stderr, proc.stderr
    assert proc.returncode in (0, 2), proc.stderr
    if proc.returncode == 2:
        assert any(str(p) in proc.stderr for p in (*logs, victim)), proc.stderr
        assert not out.exists()
    else:
        assert (out / "ingest_report.json").is_file()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


# ------------------------------------------------------ tracebacks the fuzzer found, pinned
def test_a_ulog_format_definition_with_a_damaged_field_name_is_a_typed_error(
    seeds: dict[str, Seed], tmp_path: Path
) -> None:
    # Found as ulog-bitflip-1: a flipped bit renamed `epv` in vehicle_gps_position's format
    # message and the topic conversion ended in KeyError: 'epv'.
    log = tmp_path / "flight.ulg"
    data = seeds["ulog"].target.read_bytes()
    at = data.index(b"float epv;") + len(b"float e")
    log.write_bytes(data[:at] + b"q" + data[at + 1 :])
    with pytest.raises(CorruptLogError, match="lacks field 'epv'") as err:
        ingest([log], tmp_path / "out")
    assert "vehicle_gps_position" in str(err.value)
    assert not (tmp_path / "out").exists()


def test_a_gsdc_csv_twice_in_one_file_reads_once(seeds: dict[str, Seed], tmp_path: Path) -> None:
    # Found as gsdc-duplicate-0: the repeated header line made every column text and
    # pyarrow's fill_null raised ArrowTypeError.
    log = tmp_path / "ground_truth.csv"
    log.write_bytes(seeds["gsdc"].target.read_bytes() * 2)
    result = ingest([log], tmp_path / "out")
    assert result.tables == {"truth": 20}
    (entry,) = result.report["files"]
    assert entry["counters"]["repeated_header_lines"] == 1
    assert entry["completeness"] == ["duplicated_copy_dropped"]


def test_a_gsdc_csv_with_a_damaged_number_names_its_line(
    seeds: dict[str, Seed], tmp_path: Path
) -> None:
    log = tmp_path / "ground_truth.csv"
    lines = seeds["gsdc"].target.read_text().splitlines()
    lines[5] = lines[5].replace(",10.5,", ",1x.5,")
    log.write_text("\n".join(lines) + "\n")
    with pytest.raises(CorruptLogError, match=r"'AltitudeMeters' holds '1x\.5'") as err:
        ingest([log], tmp_path / "out")
    assert err.value.record == "line 6"


def test_a_npy_header_damaged_in_its_literal_is_a_typed_error(
    seeds: dict[str, Seed], tmp_path: Path
) -> None:
    # Found as comma2k19-bitflip-0: numpy's header parser raised tokenize.TokenError.
    seg = tmp_path / "segment"
    shutil.copytree(seeds["comma2k19"].logs[0], seg)
    value = seg / "processed_log" / "IMU" / "accelerometer" / "value"
    data = bytearray(value.read_bytes())
    data[data.index(b"}")] = ord("(")  # an unclosed bracket: EOF in a multi-line statement
    value.write_bytes(bytes(data))
    with pytest.raises(CorruptLogError, match=r"unreadable \.npy header") as err:
        ingest([seg], tmp_path / "out")
    assert str(value) in str(err.value)


def test_bytes_after_an_arrays_data_are_reported(seeds: dict[str, Seed], tmp_path: Path) -> None:
    seg = tmp_path / "segment"
    shutil.copytree(seeds["comma2k19"].logs[0], seg)
    value = seg / "processed_log" / "IMU" / "accelerometer" / "value"
    size = value.stat().st_size
    value.write_bytes(value.read_bytes() + struct.pack("<3d", 1.0, 2.0, 3.0))
    result = ingest([seg], tmp_path / "out")
    (entry,) = result.report["files"]
    (defect,) = entry["defects"]
    assert defect["kind"] == "corrupt_tail"
    assert defect["offset"] == size
    assert defect["bytes_skipped"] == 24


def test_an_mcap_file_twice_in_one_file_says_what_it_ignored(
    seeds: dict[str, Seed], tmp_path: Path
) -> None:
    # Found as mcap-duplicate-0: the reader stops at the first DataEnd, so the copy was
    # ignored without a word and the file reported complete.
    log = tmp_path / "drive.mcap"
    data = seeds["mcap"].target.read_bytes()
    log.write_bytes(data * 2)
    result = ingest([log], tmp_path / "out")
    assert result.tables == {"imu": 200, "gnss": 10}
    (entry,) = result.report["files"]
    (defect,) = entry["defects"]
    assert defect["kind"] == "corrupt_tail"
    assert defect["offset"] == len(data)
    assert defect["bytes_skipped"] == len(data)
