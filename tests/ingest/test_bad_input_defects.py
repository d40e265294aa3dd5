"""Defects a first fuzzing pass over the readers found (issue 23), each pinned by a test:
a log concatenated with itself, an IMU table of NaN, bit flips in a format without checksums,
a units heuristic misled by a short log, and corrupt text headers reported as "unrecognised
content at offset 0". The output-folder defects are in ``test_output_folder``."""

from __future__ import annotations

from pathlib import Path

import pytest

from navreplay.ingest.api import IngestOptions, ingest
from navreplay.ingest.errors import CorruptLogError

from .fuzzseeds import SEEDS

pytestmark = pytest.mark.filterwarnings("ignore")


# ------------------------------------------------------------------ 3: a log twice in one file
@pytest.mark.parametrize("fmt", ["tlog", "dataflash", "csv", "nmea", "rinex_obs"])
def test_a_log_concatenated_with_itself_is_a_dropped_copy_not_a_reboot(
    tmp_path: Path, fmt: str
) -> None:
    seed = SEEDS[fmt](tmp_path)
    once = ingest(list(seed.logs), tmp_path / "once")
    size = seed.target.stat().st_size
    seed.target.write_bytes(seed.target.read_bytes() * 2)
    twice = ingest(list(seed.logs), tmp_path / "twice")
    assert twice.tables == once.tables  # the copy adds no rows and no second segment
    entry = next(f for f in twice.report["files"] if f["name"] == seed.target.name)
    assert "duplicated_copy_dropped" in entry["completeness"]
    (defect,) = (d for d in entry["defects"] if d["kind"] == "duplicated_copy_dropped")
    text_format = fmt in ("csv", "nmea", "rinex_obs")
    if not text_format:  # the copy's first rows lie past the original's end (and its FMTs)
        assert size <= defect["offset"] < size + 1000
    assert "duplicated copy" in defect["reason"]
    assert any("duplicated copy" in w and seed.target.name in w for w in twice.report["warnings"])
    for table in twice.report["tables"].values():
        assert table["hygiene"]["clock_steps_backward"] == []
        assert table["stats"]["duration_s"] < 30  # no segment appended minutes later
    # --strict refuses it (RINEX first meets the copy's header lines: text outside any epoch)
    first = "text outside any epoch" if fmt == "rinex_obs" else "duplicated copy"
    with pytest.raises(CorruptLogError, match=first):
        ingest(list(seed.logs), tmp_path / "strict", options=IngestOptions(strict=True))


def test_a_real_clock_step_with_other_values_is_still_a_step(tmp_path: Path) -> None:
    seed = SEEDS["csv"](tmp_path)
    header, *rows = seed.target.read_text().splitlines()
    again = [f"{r},".rsplit(",", 2)[0] + ",0.0123" for r in rows]  # same times, other gyro_z
    seed.target.write_text("\n".join([header, *rows, *again]) + "\n")
    result = ingest(list(seed.logs), tmp_path / "out")
    (step,) = result.report["tables"]["imu"]["hygiene"]["clock_steps_backward"]
    assert step["step_s"] < 0
    assert result.report["tables"]["imu"]["hygiene"]["duplicated_copies"] == []
    assert result.tables["imu"] == 2 * len(rows)
