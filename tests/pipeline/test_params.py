"""Typed parameters: strict loading with errors that name the key path."""

from __future__ import annotations

import copy
from dataclasses import FrozenInstanceError, dataclass
from pathlib import Path
from typing import Any, Literal

import pytest
import yaml

from navreplay.ingest.typed import KeyPathError, load_dataclass
from navreplay.pipeline.errors import ParamsError
from navreplay.pipeline.params import (
    BUILTIN_PARAMS,
    Params,
    load_params,
    overlay,
    params_label,
    params_source,
    parse_params,
    read_yaml,
    section,
)

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture
def raw() -> dict[str, Any]:
    data = read_yaml(REPO / "params.yaml")
    assert isinstance(data, dict)
    return copy.deepcopy(data)


def test_repository_params_load() -> None:
    params = load_params(REPO / "params.yaml")
    assert isinstance(params, Params)
    assert params.run.backend in ("numba", "filterpy")
    assert isinstance(params.run.filters, tuple)


def test_params_are_frozen() -> None:
    params = load_params(REPO / "params.yaml")
    with pytest.raises(FrozenInstanceError):
        params.synth.seed = 3  # type: ignore[misc]


def test_misspelled_key_is_named_with_a_suggestion(raw: dict[str, Any], tmp_path: Path) -> None:
    raw["ingest"]["reorder_windw_s"] = raw["ingest"].pop("reorder_window_s")
    path = tmp_path / "params.yaml"
    path.write_text(yaml.safe_dump(raw))
    with pytest.raises(ParamsError) as err:
        load_params(path)
    assert err.value.key_path == "ingest.reorder_windw_s"
    assert "did you mean 'reorder_window_s'" in str(err.value)
    assert str(path) in str(err.value)


def test_unknown_top_level_section(raw: dict[str, Any]) -> None:
    raw["reprot"] = {}
    with pytest.raises(ParamsError, match=r"reprot: unknown key; did you mean 'report'"):
        parse_params(raw)


def test_missing_section_is_named(raw: dict[str, Any]) -> None:
    del raw["run"]
    with pytest.raises(ParamsError) as err:
        parse_params(raw)
    assert err.value.key_path == "run"
    assert "missing" in err.value.reason


def test_empty_section_is_an_error(raw: dict[str, Any]) -> None:
    raw["run"] = None
    with pytest.raises(ParamsError, match="run: section is empty"):
        parse_params(raw)


@pytest.mark.parametrize(
    ("path", "value", "expect"),
    [
        (("synth", "seed"), "42", "expected an integer"),
        (("synth", "seed"), True, "expected an integer"),
        (("ingest", "strict"), "no", "expected true or false"),
        (("ingest", "gap_factor"), "five", "expected a number"),
        (("run", "backend"), "cuda", "is not one of 'numba', 'filterpy'"),
        (("run", "filters"), "lc_ekf", "expected a list"),
    ],
)
def test_wrong_type_names_key(
    raw: dict[str, Any], path: tuple[str, str], value: object, expect: str
) -> None:
    raw[path[0]][path[1]] = value
    with pytest.raises(ParamsError, match=expect) as err:
        parse_params(raw)
    assert err.value.key_path == ".".join(path)


def test_list_item_type_error_names_the_index(raw: dict[str, Any]) -> None:
    raw["run"]["filters"] = ["lc_ekf", 3]
    with pytest.raises(ParamsError) as err:
        parse_params(raw)
    assert err.value.key_path == "run.filters[1]"


def test_int_is_accepted_for_float(raw: dict[str, Any]) -> None:
    raw["ingest"]["gap_factor"] = 4
    params = parse_params(raw)
    assert params.ingest.gap_factor == 4.0
    assert isinstance(params.ingest.gap_factor, float)


def test_value_checks_name_the_key(raw: dict[str, Any]) -> None:
    raw["ingest"]["gap_factor"] = 0.5
    with pytest.raises(ParamsError, match=r"ingest.gap_factor: must be > 1"):
        parse_params(raw)


def test_duplicate_yaml_key_is_an_error(tmp_path: Path) -> None:
    path = tmp_path / "params.yaml"
    path.write_text("synth:\n  seed: 1\n  seed: 2\n")
    with pytest.raises(ParamsError, match="duplicate key 'seed'"):
        read_yaml(path)


def test_invalid_yaml_and_missing_file(tmp_path: Path) -> None:
    bad = tmp_path / "params.yaml"
    bad.write_text("synth: [unclosed\n")
    with pytest.raises(ParamsError, match="not valid YAML"):
        load_params(bad)
    with pytest.raises(ParamsError, match="cannot read"):
        load_params(tmp_path / "absent.yaml")


def test_section_returns_plain_data() -> None:
    params = load_params(REPO / "params.yaml")
    assert section(params, "run")["backend"] == params.run.backend
    assert section(params, "synth.seed") == params.synth.seed
    with pytest.raises(ParamsError, match="no such parameter section"):
        section(params, "run.nope")


@dataclass(frozen=True)
class _Inner:
    k: tuple[float, float]
    opt: int | None = None


@dataclass(frozen=True)
class _Outer:
    mode: Literal["a", "b"]
    table: dict[str, _Inner]


def test_nested_mappings_and_fixed_tuples() -> None:
    obj = load_dataclass(_Outer, {"mode": "a", "table": {"x": {"k": [1, 2.5]}}})
    assert obj.table["x"].k == (1.0, 2.5)
    assert obj.table["x"].opt is None
    with pytest.raises(KeyPathError) as err:
        load_dataclass(_Outer, {"mode": "a", "table": {"x": {"k": [1, 2, 3]}}})
    assert err.value.key_path == "table.x.k"
    with pytest.raises(KeyPathError) as err:
        load_dataclass(_Outer, {"mode": "a", "table": {"x": {"k": [1, 2], "opt": 1.5}}})
    assert err.value.key_path == "table.x.opt"


@pytest.mark.parametrize(
    ("run", "key", "expect"),
    [
        ({"dataset": "nowhere", "filter": "vehicle_imm"}, "dataset", "neither datasets"),
        ({"dataset": "car_speed_ramp", "filter": "vehicle_pf"}, "filter", "not a filter"),
        (
            {"dataset": "car_speed_ramp", "filter": "vehicle_imm", "scenario": "outage_6s"},
            "scenario",
            "not in scenarios.named",
        ),
    ],
)
def test_a_family_run_names_a_known_dataset_filter_and_scenario(
    raw: dict[str, Any], run: dict[str, str], key: str, expect: str
) -> None:
    raw["run"]["family_runs"] = [{"dataset": "car_speed_ramp", "filter": "vehicle_imm"}, run]
    with pytest.raises(ParamsError, match=expect) as err:
        parse_params(raw)
    assert err.value.key_path == f"run.family_runs[1].{key}"


# --- the built-in defaults and files laid over them ------------------------------------------


def test_the_built_in_defaults_are_the_repository_params() -> None:
    """The package carries the repository's params.yaml (a link in the checkout, a copy in a
    wheel): the two cannot drift apart."""
    assert BUILTIN_PARAMS.read_bytes() == (REPO / "params.yaml").read_bytes()


def test_without_a_file_the_built_in_defaults_apply(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)  # no params.yaml here
    assert params_source(None) is None
    assert load_params() == load_params(REPO / "params.yaml")
    assert "built-in defaults" in params_label()


def test_a_partial_file_changes_only_its_keys(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    (tmp_path / "params.yaml").write_text(
        "run:\n  filters: [lc_ekf]\nfilters:\n  lc_ekf:\n    gnss: {elevation_mask_deg: 15.0}\n"
    )
    monkeypatch.chdir(tmp_path)  # ./params.yaml is used when present
    params, defaults = load_params(), load_params(REPO / "params.yaml")
    assert params.run.filters == ("lc_ekf",)  # a list replaces
    assert params.run.scenarios == defaults.run.scenarios  # its neighbours stay
    assert params.filters.get("lc_ekf").gnss.elevation_mask_deg == 15.0  # mappings merge
    assert params.filters.get("lc_ekf").init == defaults.filters.get("lc_ekf").init
    assert params.filters.get("tc_ekf") == defaults.filters.get("tc_ekf")
    assert params.scenarios == defaults.scenarios


def test_a_partial_file_is_checked_and_named_in_errors(tmp_path: Path) -> None:
    path = tmp_path / "mine.yaml"
    path.write_text("run:\n  filtres: [lc_ekf]\n")
    with pytest.raises(ParamsError, match=r"mine\.yaml: run\.filtres: unknown key"):
        load_params(path)
    path.write_text("- just a list\n")
    with pytest.raises(ParamsError, match=r"mine\.yaml: .*must be a mapping"):
        load_params(path)


def test_overlay_merges_mappings_and_replaces_the_rest() -> None:
    base = {"a": {"x": 1, "y": [1, 2]}, "b": 2}
    assert overlay(base, {"a": {"y": [3]}, "c": 4}) == {"a": {"x": 1, "y": [3]}, "b": 2, "c": 4}
    assert overlay(base, {"a": 5}) == {"a": 5, "b": 2}
    assert base == {"a": {"x": 1, "y": [1, 2]}, "b": 2}  # not modified


def test_navreplay_params_prints_what_loads_back(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from navreplay.pipeline.cli import main

    monkeypatch.chdir(tmp_path)
    mine = tmp_path / "mine.yaml"
    mine.write_text("run:\n  filters: [tc_ukf]\n")
    assert main(["params", "--params", str(mine)]) == 0
    printed = capsys.readouterr().out
    assert printed.startswith(f"# navreplay parameters: {mine} over the built-in defaults")
    (tmp_path / "effective.yaml").write_text(printed)
    assert load_params(tmp_path / "effective.yaml") == load_params(mine)
    assert main(["params", "--section", "run.filters"]) == 0
    assert "run.filters: [lc_ekf, tc_ekf, tc_ukf, tc_ukf_nhc]" in capsys.readouterr().out
