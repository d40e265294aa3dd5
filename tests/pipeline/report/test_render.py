"""The dataset report: sections from real runs, byte-stable, self-contained, strict on bad input."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from navreplay.pipeline.cli import main
from navreplay.pipeline.report.input_files import ReportInputError
from navreplay.pipeline.report.inputs import load_dataset
from navreplay.pipeline.report.render import render_dataset
from tests.pipeline.report.conftest import OUTAGE_S

PAIRS = (("lc_ekf", "lc_ekf_nhc"),)


def _render(root: Path, out: Path, **kw: object) -> Path:
    data = load_dataset("tiny", root / "tables", root / "runs", root / "experiments")
    render_dataset(data, out, experiments_dir=root / "experiments", **kw)  # type: ignore[arg-type]
    return out


def test_report_has_every_section_its_runs_support(dataset_dir: Path, tmp_path: Path) -> None:
    out = _render(dataset_dir, tmp_path / "r")
    page = (out / "index.html").read_text()
    for ident in ("overview", "audit", "track", "metrics", "noise", "errors", "outages", "nis",
                  "biases", "cost", "provenance"):  # fmt: skip
        assert f'<section id="{ident}">' in page, ident
    # the noise models and why: 70 s of fixes are too few to learn their correlation from
    noise = page.split('<section id="noise">')[1].split("</section>")[0]
    assert "configured" in noise
    assert "too few to learn from" in noise
    assert "dataset" in noise
    assert '<section id="experiments">' not in page  # no experiments: no section
    assert page.count("<svg") >= 5
    runs = json.loads((out / "tables" / "runs.json").read_text())
    assert {(r["filter"], r["scenario"]) for r in runs} == {
        ("lc_ekf", "nominal"),
        ("lc_ekf", "outage_15s"),
    }
    nominal = next(r for r in runs if r["scenario"] == "nominal")
    assert nominal["reference"] == "truth"
    assert 0.05 < nominal["pos_err_h_rms_m"] < 5.0
    windows = (out / "tables" / "windows.csv").read_text().splitlines()
    assert len(windows) == 2  # header + the one window
    cells = dict(zip(windows[0].split(","), windows[1].split(","), strict=True))
    assert float(cells["duration_s"]) == pytest.approx(OUTAGE_S)
    # a free-inertial 15 s costs more than the nominal error, and the end is within the max
    assert float(cells["err_end_m"]) <= float(cells["err_max_m"])
    assert float(cells["err_max_m"]) > nominal["pos_err_h_rms_m"]
    metrics = json.loads((out / "metrics.json").read_text())
    assert set(metrics["lc_ekf"]) == {"nominal", "outage_15s"}
    assert "sha256 " + "ab" * 32 in page


def test_same_inputs_give_the_same_bytes(dataset_dir: Path, tmp_path: Path) -> None:
    a = _render(dataset_dir, tmp_path / "a")
    b = _render(dataset_dir, tmp_path / "b")
    files = sorted(p.relative_to(a) for p in a.rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(b) for p in b.rglob("*") if p.is_file())
    for f in files:
        assert (a / f).read_bytes() == (b / f).read_bytes(), f


def test_page_loads_nothing_from_the_network(dataset_dir: Path, tmp_path: Path) -> None:
    page = (_render(dataset_dir, tmp_path / "r") / "index.html").read_text()
    assert not re.search(r'(src|href)\s*=\s*"(https?:)?//', page)
    assert "@import" not in page
    assert "url(http" not in page
    assert "<link" not in page


def test_ids_are_unique_across_inline_figures(dataset_dir: Path, tmp_path: Path) -> None:
    page = (_render(dataset_dir, tmp_path / "r") / "index.html").read_text()
    ids = re.findall(r'\bid="([^"]+)"', page)
    dupes = {i for i in ids if ids.count(i) > 1}
    assert not dupes


def test_tables_without_runs_still_give_a_report(dataset_dir: Path, tmp_path: Path) -> None:
    data = load_dataset("tiny", dataset_dir / "tables", tmp_path / "none", None)
    render_dataset(data, tmp_path / "r")
    page = (tmp_path / "r" / "index.html").read_text()
    assert '<section id="audit">' in page
    assert '<section id="track">' in page
    assert '<section id="errors">' not in page
    assert "No filter runs for this dataset yet." in page


def test_a_malformed_metrics_file_is_an_error_naming_it(dataset_dir: Path, tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    shutil.copytree(dataset_dir / "runs", runs)
    bad = runs / "lc_ekf" / "nominal" / "metrics.json"
    bad.write_text('{"filter": "lc_ekf", "scenario": ')
    with pytest.raises(ReportInputError, match=r"nominal/metrics.json: not valid JSON"):
        load_dataset("tiny", dataset_dir / "tables", runs, None)
    bad.write_text('{"filter": "lc_ekf", "scenario": "nominal", "outage_windows": [{"x": 1}]}')
    with pytest.raises(ReportInputError, match=r"outage_windows\[0\]"):
        load_dataset("tiny", dataset_dir / "tables", runs, None)


def test_skipped_runs_are_listed_with_their_reason(dataset_dir: Path, tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    shutil.copytree(dataset_dir / "runs", runs)
    skip = runs / "tc_ekf" / "nominal"
    skip.mkdir(parents=True)
    skip.joinpath("metrics.json").write_text(
        json.dumps(
            {
                "filter": "tc_ekf",
                "scenario": "nominal",
                "status": "skipped",
                "reason": "no raw GNSS observables",
            }
        )
    )
    data = load_dataset("tiny", dataset_dir / "tables", runs, None)
    render_dataset(data, tmp_path / "r")
    page = (tmp_path / "r" / "index.html").read_text()
    assert "no raw GNSS observables" in page


def test_report_command_writes_the_report(dataset_dir: Path, tmp_path: Path) -> None:
    rc = main(["report", "tiny", "--tables", str(dataset_dir / "tables"),
               "--out", str(tmp_path / "r")])  # fmt: skip
    assert rc == 0
    assert (tmp_path / "r" / "index.html").is_file()
    assert (tmp_path / "r" / "tables" / "provenance.json").is_file()


def test_the_page_opens_with_the_verdict_and_folds_the_details(
    dataset_dir: Path, tmp_path: Path
) -> None:
    page = (_render(dataset_dir, tmp_path / "r") / "index.html").read_text()
    main = page.split("<main>")[1]
    assert main.startswith('<section id="verdict"><h2>Verdict</h2>')
    verdict = main.split("</section>")[0]
    # the statuses, the data-quality verdict (the fixture's audit warns of NaN fixes) and
    # which filter held best in the one 15 s outage, against the truth
    assert "All 2 runs ended ok." in verdict
    assert "Data quality: 1 warning(s) from the ingest audit." in verdict
    assert "gnss: 3 fixes without a position (NaN)" in verdict
    best = verdict.split("Which filter held best")[1]
    assert "complete outage" in best
    assert "lc_ekf" in best
    assert "truth" in best
    # every other section folds under its title; the overview and the metrics start open
    assert '<section id="overview"><details open><summary>' in page
    assert '<section id="metrics"><details open><summary>' in page
    assert '<section id="nis"><details><summary>' in page
    assert '<section id="provenance"><details><summary>' in page


def test_the_best_filter_is_the_lowest_mean_with_an_interval_that_stays_positive() -> None:
    from navreplay.pipeline.report.sections import best_rows

    ends = {"a": [1.0, 2.0, 30.0], "b": [4.0, 5.0, 6.0], "c": [0.5, 0.6, 0.7]}
    windows = [
        {"filter": f, "scenario": "outage_60s", "sats": 0, "duration_s": 60.0,
         "err_end_m": e, "reference": "truth"}
        for f, es in ends.items() for e in es
    ]  # fmt: skip
    status = {("a", "outage_60s"): "ok", ("b", "outage_60s"): "inconsistent",
              ("c", "outage_60s"): "diverged"}  # fmt: skip
    (row,) = best_rows(windows, status)
    # c is lowest but diverged: it does not compete; b's mean 5 beats a's 11
    assert (row["best"], row["next"], row["filters"]) == ("b", "a", 2)
    assert row["mean_m"] == pytest.approx(5.0)
    assert 4.0 <= row["ci_low_m"] <= 5.0 <= row["ci_high_m"] <= 6.0
    # a skewed few (a's 1, 2, 30): a t-interval goes below zero, the bootstrap's does not
    from navreplay.pipeline.report.tables import drift_by_length, t_interval

    assert t_interval(np.asarray(ends["a"]))[1] < 0.0
    rows = drift_by_length([w for w in windows if w["filter"] == "a"])
    assert rows[0]["ci_low_m"] >= 1.0
