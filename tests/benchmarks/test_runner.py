"""The benchmark runner discovers `benchmarks/bench_*.py` modules (no registry to edit)."""

from __future__ import annotations

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
