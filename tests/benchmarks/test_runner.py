"""The benchmark runner discovers `benchmarks/bench_*.py` modules (no registry to edit)."""

from __future__ import annotations

from pathlib import Path

import pytest

from benchmarks.__main__ import discover, main


def test_every_bench_module_is_discovered_with_a_run_function() -> None:
    found = discover()
    assert {"ros_ingest", "ingest_memory"} <= set(found)
    for module in found.values():
        assert callable(module.run)
        assert module.__doc__


def test_unknown_benchmark_is_a_usage_error(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["no_such_benchmark"])
    assert exc.value.code == 2
    assert "ros_ingest" in capsys.readouterr().err


def test_the_memory_benchmark_child_ingests_a_log(tmp_path: Path) -> None:
    """The code the memory benchmark runs in a fresh interpreter works as written."""
    from benchmarks.bench_ingest_memory import INGEST_CODE, _child, write_log

    n = write_log(tmp_path / "small.mcap", 1 << 16)
    code = INGEST_CODE.format(log=str(tmp_path / "small.mcap"), out=str(tmp_path / "out"))
    out, rss_mb, _ = _child(code)
    assert int(out) == n
    assert rss_mb > 0
