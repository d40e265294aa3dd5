"""Catalogue case 39 at test scale: ingest memory does not grow with the log.

The 2 GB figure is measured by ``benchmarks/bench_ingest_memory.py``; here two logs, one four
times the other, are ingested in fresh processes and their peak RSS compared. A reader that
indexed every message (rosbags keeps ~150 B per message) or sorted in RAM would add tens of MB.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from .mavlogs import write_dataflash_drive, write_tlog_drive
from .roslogs import write_imu_mcap_fast


def _peak_rss_mb(log: Path, out: Path, setup: str = "") -> float:
    script = textwrap.dedent(
        f"""
        {setup}
        import re
        from pathlib import Path
        from navreplay.ingest.api import IngestOptions, ingest
        options = IngestOptions(block_rows=8192)  # many blocks in both logs
        result = ingest([Path({str(log)!r})], Path({str(out)!r}), options=options)
        # VmHWM, not ru_maxrss: Linux carries the (large) pytest parent's peak into the child.
        status = open("/proc/self/status").read()
        print(result.tables["imu"], re.search(r"VmHWM:\\s+(\\d+)", status).group(1))
        """
    )
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=300, check=True
    )
    rows, kib = done.stdout.split()
    assert int(rows) > 0
    return int(kib) / 1024


@pytest.mark.slow
def test_peak_memory_does_not_grow_with_the_log(tmp_path: Path) -> None:
    small = write_imu_mcap_fast(tmp_path / "small.mcap", 50_000)
    large = write_imu_mcap_fast(tmp_path / "large.mcap", 200_000)
    rss_small = _peak_rss_mb(small, tmp_path / "s")
    rss_large = _peak_rss_mb(large, tmp_path / "l")
    assert rss_large < 512
    assert rss_large - rss_small < 15, (rss_small, rss_large)


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["tlog", "bin"])
def test_autopilot_log_memory_does_not_grow_with_the_log(kind: str, tmp_path: Path) -> None:
    # Survey and read passes both stream the file in blocks of BLOCK_BYTES (8 MB; 128 kB
    # here, so that both logs span many blocks): a log four times longer costs no more memory.
    write = write_tlog_drive if kind == "tlog" else write_dataflash_drive
    small = write(tmp_path / f"small.{kind}", 20.0)
    large = write(tmp_path / f"large.{kind}", 80.0)
    module = "tlogscan" if kind == "tlog" else "dfscan"
    setup = f"import navreplay.ingest.readers.mavlink.{module} as m; m.BLOCK_BYTES = 1 << 17"
    rss_small = _peak_rss_mb(small, tmp_path / "s", setup)
    rss_large = _peak_rss_mb(large, tmp_path / "l", setup)
    assert rss_large < 512
    assert rss_large - rss_small < 15, (rss_small, rss_large)
