"""The navreplay command line: help for every subcommand, honest exits."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from navreplay.pipeline.cli import COMMANDS, main


def test_top_level_help_lists_every_command(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    for name in ("ingest", "run", "analyze", "synth", "report", "summarize", "bench"):
        assert name in out


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_each_command_has_helpful_help(command: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main([command, "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert f"usage: navreplay {command}" in out
    # The description is the stage's docstring, not just the argument list.
    assert len(out.splitlines()) > 5


def test_missing_required_argument_is_a_usage_error(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["run", "tables"])
    assert exc.value.code == 2
    assert "--filter" in capsys.readouterr().err


def test_console_script_runs() -> None:
    exe = Path(sys.executable).with_name("navreplay")
    if not exe.exists():
        pytest.skip("console script not installed in this environment")
    done = subprocess.run(
        [str(exe), "--help"], capture_output=True, text=True, timeout=120, check=False
    )
    assert done.returncode == 0
    assert "navreplay" in done.stdout


def test_where_reports_without_reports(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["where-reports", "--root", str(tmp_path)]) == 1
    assert "dvc repro" in capsys.readouterr().out


def test_unbuilt_capability_says_so_and_exits_non_zero(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import argparse
    import types

    from navreplay.pipeline.errors import NotBuiltError

    def configure(parser: argparse.ArgumentParser) -> None:
        parser.add_argument("--out")

    def run(args: argparse.Namespace) -> int:
        raise NotBuiltError("arrives later; nothing was written")

    fake = types.ModuleType("fake_stage")
    fake.configure = configure  # type: ignore[attr-defined]
    fake.run = run  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "fake_stage", fake)
    monkeypatch.setitem(COMMANDS, "fake", ("fake_stage", "a capability of the future"))
    assert main(["fake"]) == 3
    assert "not built yet: arrives later" in capsys.readouterr().err


def test_typed_errors_exit_2_with_the_message(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    repo = Path(__file__).resolve().parents[2]
    bad = tmp_path / "params.yaml"
    bad.write_text((repo / "params.yaml").read_text().replace("  seed:", "  sed:"))
    import argparse
    import types

    from navreplay.pipeline.params import load_params

    def configure(parser: argparse.ArgumentParser) -> None:
        parser.add_argument("--params", type=Path)

    def run(args: argparse.Namespace) -> int:
        load_params(args.params)
        return 0

    fake = types.ModuleType("fake_stage2")
    fake.configure = configure  # type: ignore[attr-defined]
    fake.run = run  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "fake_stage2", fake)
    monkeypatch.setitem(COMMANDS, "fake2", ("fake_stage2", "loads params"))
    assert main(["fake2", "--params", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "synth.sed: unknown key; did you mean 'seed'" in err
