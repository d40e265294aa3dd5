"""Report parts: decimation keeps extremes, the reduction table, experiment sections, summary."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest

from navreplay.pipeline.report.experiments import load_experiments
from navreplay.pipeline.report.input_files import ReportInputError
from navreplay.pipeline.report.inputs import load_dataset
from navreplay.pipeline.report.render import render_dataset
from navreplay.pipeline.report.summary import paired, ranking, render_summary
from navreplay.pipeline.report.svg import decimate_minmax


def test_decimation_keeps_every_extreme_and_the_order() -> None:
    rng = np.random.default_rng(1)
    x = np.arange(100_000, dtype=float)
    y = rng.standard_normal(x.size)
    y[31_337] = 50.0
    y[77_777] = -60.0
    xd, yd = decimate_minmax(x, y, 2000)
    assert xd.size <= 2000
    assert np.all(np.diff(xd) > 0)
    assert yd.max() == 50.0
    assert yd.min() == -60.0
    short = np.arange(10.0)
    assert decimate_minmax(short, short)[0] is short


_REDUCTION = """pair,sats,err_baseline_m,err_candidate_m,reduction_pct,ci_low_pct,ci_high_pct
tc_ukf->tc_ukf_nhc,0,40.0,20.0,50.0,41.5,57.25
tc_ukf->tc_ukf_nhc,4,3.0,2.5,16.666666666666668,5.0,25.0
tc_ekf->tc_ukf,0,41.0,40.0,2.4390243902439024,-1.0,6.0
"""
_NOTE = """# Against the paper

Our drive is **shorter** than the paper's; <script>alert(1)</script> stays text.

| k | ours | paper |
|---|---|---|
| 0 | 50.0 | 54.4 |

![remote](http://example.invalid/x.png)
"""


def test_outage_results_are_shown_beside_the_paper_and_copied(
    dataset_copy: Path, tmp_path: Path
) -> None:
    root = dataset_copy
    exp = root / "experiments"
    exp.mkdir()
    (exp / "sat_reduction.csv").write_text(_REDUCTION)
    (exp / "sat_reduction_vs_paper.md").write_text(_NOTE)
    (exp / "drift_vs_length.csv").write_text("filter,outage_s,err_end_mean_m\nlc_ekf,10,2.5\n")
    data = load_dataset("tiny", root / "tables", root / "runs", exp)
    assert data.experiments == []  # the outage results have their own sections
    render_dataset(data, tmp_path / "r", experiments_dir=exp)
    page = (tmp_path / "r" / "index.html").read_text()
    sat = page[page.index('id="satellites"') : page.index('id="nis"')]
    # the paper's value beside ours for its pair only; ours to 4 significant digits
    assert '<td class="t">tc_ukf-&gt;tc_ukf_nhc</td><td>0</td><td>40</td>' in sat
    assert "<td>50</td><td>41.5</td><td>57.25</td><td>54.4</td></tr>" in sat
    assert "<td>16.67</td><td>5</td><td>25</td><td>22.6</td></tr>" in sat
    assert '<td>6</td><td class="t"></td></tr>' in sat
    # the stage's explanation as prose, its raw HTML escaped and no remote image
    assert "<h4>Against the paper</h4>" in sat
    assert "<strong>shorter</strong>" in sat
    assert "&lt;script&gt;" in sat
    assert "<img" not in page
    assert "image: remote (http://example.invalid/x.png)" in sat
    drift = page[page.index('id="drift"') : page.index('id="satellites"')]
    assert '<td class="t">lc_ekf</td><td>10</td><td>2.5</td>' in drift
    tables = tmp_path / "r" / "tables"
    assert (tables / "sat_reduction.csv").read_text() == _REDUCTION
    assert (tables / "drift_vs_length.csv").is_file()
    # the summary collects the table of every dataset, beside the paper's values too
    summary = render_summary([tmp_path / "r"], tmp_path / "s").read_text()
    assert "<td>50</td><td>41.5</td><td>57.25</td><td>54.4</td></tr>" in summary
    # and draws it: a point with its interval per satellite count, the paper's values beside
    chart = summary[summary.index('id="satellites"') :].split("</figure>")[0]
    assert "<svg" in chart
    assert "paper 001, Table 1 (tc_ukf -&gt; tc_ukf_nhc)" in chart
    assert "tiny: tc_ukf-&gt;tc_ukf_nhc" in chart
    assert (
        (tmp_path / "s" / "tables" / "sat_reduction.csv")
        .read_text()
        .startswith("dataset,pair,sats,")
    )
    (exp / "sat_reduction.csv").write_text("pair,sats\na->b,0\n")
    with pytest.raises(ReportInputError, match="missing columns"):
        render_dataset(data, tmp_path / "r2", experiments_dir=exp)


def test_ranking_and_paired_ratio() -> None:
    cells = {
        ("d1", "nominal"): {"x": 1.0, "y": 2.0, "z": 4.0},
        ("d1", "outage"): {"x": 10.0, "y": 20.0},
        ("d2", "nominal"): {"x": 2.0, "y": 4.0, "z": 1.0},
    }
    rank = ranking(cells)
    assert next(r["filter"] for r in rank) == "x"
    pairs = paired(cells, [r["filter"] for r in rank])
    xy = next(p for p in pairs if (p["a"], p["b"]) == ("x", "y"))
    assert xy["cells"] == 3
    assert xy["ratio_b_over_a"] == pytest.approx(2.0)
    assert math.isnan(xy["ratio_ci_low"]) or xy["ratio_ci_low"] == pytest.approx(2.0)


def _experiment(root: Path, spec: dict[str, object]) -> Path:
    d = root / "experiments" / "cascade"
    d.mkdir(parents=True)
    (d / "convergence.csv").write_text("filter,rb_s\ncascaded_ekf,12.5\ncascaded_ukf,6.1\n")
    (d / "bands.svg").write_text('<?xml version="1.0"?><svg viewBox="0 0 10 10"><defs><path '
                                 'id="p" d="M0 0L10 10"/></defs><use xlink:href="#p"/>'
                                 '<g id="unused"></g></svg>')  # fmt: skip
    (d / "section.json").write_text(json.dumps(spec))
    return d


def test_experiment_sections_render_from_their_contract(dataset_copy: Path, tmp_path: Path) -> None:
    root = dataset_copy
    _experiment(
        root,
        {
            "title": "Cascaded filters (paper 000)",
            "summary": ["The UKF converges faster."],
            "claims": [
                {"claim": "UKF faster", "paper": "2x", "ours": "2.05x", "verdict": "agrees"}
            ],
            "tables": [{"title": "Convergence", "csv": "convergence.csv"}],
            "figures": [{"title": "Bands", "file": "bands.svg"}],
        },
    )
    data = load_dataset("tiny", root / "tables", root / "runs", root / "experiments")
    render_dataset(data, tmp_path / "r", experiments_dir=root / "experiments")
    page = (tmp_path / "r" / "index.html").read_text()
    assert '<section id="experiments">' in page
    assert "Cascaded filters (paper 000)" in page
    assert "cascaded_ukf" in page
    # the figure's ids are prefixed (several figures share the page); ids nothing refers to
    # are dropped with the rest of matplotlib's redundancy (svg.compact)
    assert 'id="exp-cascade-0-p"' in page
    assert 'xlink:href="#exp-cascade-0-p"' in page
    assert "unused" not in page


@pytest.mark.parametrize(
    ("spec", "match"),
    [
        ({"titel": "x"}, "unknown keys"),
        ({"title": "x", "tables": [{"csv": "missing.csv"}]}, "does not exist"),
        ({"title": "x", "claims": [{"claim": "c", "verdict": "maybe"}]}, "verdict"),
        ({"title": "x", "figures": [{"file": "convergence.csv"}]}, ".svg or .png"),
    ],
)
def test_a_malformed_section_is_an_error_naming_the_file(
    tmp_path: Path, spec: dict[str, object], match: str
) -> None:
    _experiment(tmp_path, spec)
    with pytest.raises(ReportInputError, match=match) as err:
        load_experiments(tmp_path / "experiments")
    assert "cascade" in str(err.value)


def test_summary_ranks_filters_across_reports(dataset_dir: Path, tmp_path: Path) -> None:
    reports = []
    for name in ("one", "two"):
        data = load_dataset(name, dataset_dir / "tables", dataset_dir / "runs", None)
        data.dataset = name
        render_dataset(data, tmp_path / name)
        reports.append(tmp_path / name)
    index = render_summary(reports, tmp_path / "summary")
    page = index.read_text()
    assert "Filters ranked" not in page  # one filter per cell: nothing to rank
    assert '<a href="../one/index.html">one</a>' in page
    assert (tmp_path / "summary" / "tables" / "ranking.csv").is_file()
    with pytest.raises(ReportInputError, match="not a dataset report"):
        render_summary([tmp_path], tmp_path / "s2")


def test_experiment_files_without_a_section_render_generically(
    dataset_copy: Path, tmp_path: Path
) -> None:
    root = dataset_copy
    exp = root / "experiments"
    (exp / "figures").mkdir(parents=True)
    rows = "\n".join(f"cascaded_ekf,{i},{0.1 * i}" for i in range(100))
    (exp / "timeseries_nominal.csv").write_text("label,k,east_m\n" + rows + "\n")
    (exp / "summary.json").write_text("{}")
    (exp / "figures" / "tracking.svg").write_text('<svg viewBox="0 0 4 4"><path d="M0 0"/></svg>')
    (exp / "figures" / "tracking.png").write_bytes(b"not read: the SVG twin wins")
    data = load_dataset("tiny", root / "tables", root / "runs", exp)
    assert [e.name for e in data.experiments] == ["results"]
    render_dataset(data, tmp_path / "r", experiments_dir=exp)
    page = (tmp_path / "r" / "index.html").read_text()
    assert "First 40 of 100 rows" in page
    assert "<td>99</td>" not in page
    copied = tmp_path / "r" / "tables" / "experiments" / "results" / "timeseries_nominal.csv"
    assert copied.read_text().count("\n") == 101
    assert '<svg viewBox="0 0 4 4">' in page
    assert "not read" not in page


def test_window_metrics_the_run_wrote_are_taken_as_they_are(
    dataset_copy: Path, tmp_path: Path
) -> None:
    root = dataset_copy
    mpath = root / "runs" / "lc_ekf" / "outage_15s" / "metrics.json"
    metrics = json.loads(mpath.read_text())
    (w,) = metrics["outage_windows"]
    measured = render_dataset(
        load_dataset("tiny", root / "tables", root / "runs", None), tmp_path / "a"
    )
    del measured
    rows = {r["scenario"]: r for r in _csv_rows(tmp_path / "a" / "tables" / "windows.csv")}
    assert float(rows["outage_15s"]["err_end_m"]) > 0.0  # measured here: the run wrote none
    # the scenario engine's layout: start_t_ns + duration_s, and its own window metrics
    w = {"start_t_ns": w["start_ns"], "duration_s": 15.0, "sats": 0, "err_end_m": 123.0,
         "err_max_m": 130.0, "err_mean_m": 60.0, "err_rms_m": 70.0, "drift_pct_distance": None,
         "inside_3sigma_frac": 0.5, "reference": "truth"}  # fmt: skip
    metrics["outage_windows"] = [w]
    mpath.write_text(json.dumps(metrics))
    render_dataset(load_dataset("tiny", root / "tables", root / "runs", None), tmp_path / "b")
    row = _csv_rows(tmp_path / "b" / "tables" / "windows.csv")[-1]
    assert row["err_end_m"] == "123.0"
    assert row["drift_pct_distance"] == ""
    assert row["inside_3sigma_frac"] == "0.5"
    assert float(row["start_s"]) == float(rows["outage_15s"]["start_s"])


def _csv_rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as fh:
        return list(csv.DictReader(fh))


def test_a_cell_of_planar_filters_is_ranked_by_horizontal_error() -> None:
    """The INS cell keeps the 3-D error; the vehicle filters (planar, no 3-D error) are
    ranked in their own cell by the horizontal one; a diverged run is left out."""
    from navreplay.pipeline.report.summary import DatasetResult, _cells, ranking

    def run(f: str, h: float, d3: float | None = None, status: str = "ok") -> dict[str, object]:
        return {"filter": f, "scenario": "nominal", "status": status,
                "pos_err_h_rms_m": h, "pos_err_3d_rms_m": d3}  # fmt: skip

    drive = DatasetResult("drive", Path(), [run("lc_ekf", 1.0, 2.0), run("tc_ukf", 1.2, 1.5)], None)
    car = DatasetResult(
        "car",
        Path(),
        [
            run("vehicle_kinematic", 3.0),
            run("vehicle_dynamic", 0.2),
            run("vehicle_imm", 0.1, status="diverged"),
        ],
        None,
    )
    cells = _cells([drive, car])
    assert cells == {
        ("car", "nominal"): {"vehicle_kinematic": 3.0, "vehicle_dynamic": 0.2},
        ("drive", "nominal"): {"lc_ekf": 2.0, "tc_ukf": 1.5},
    }
    ranks = {r["filter"]: r["mean_rank"] for r in ranking(cells)}
    assert ranks == {"vehicle_dynamic": 1.0, "tc_ukf": 1.0, "vehicle_kinematic": 2.0, "lc_ekf": 2.0}


def test_the_report_says_first_how_its_runs_ended() -> None:
    from navreplay.pipeline.report.sections import verdict

    ok = [{"status": "ok"}] * 3
    assert verdict(ok) == '<p class="verdict ok">All 3 runs ended ok.</p>'
    mixed = verdict([*ok, {"status": "inconsistent"}, {"status": "not_aligned"}])
    assert mixed.startswith(
        '<p class="verdict warn">3 of 5 runs ended ok: 1 inconsistent, 1 not aligned'
    )
    assert "an inconsistent run finished" in mixed
    none = verdict([{"status": "diverged"}, {"status": "skipped"}])
    assert none.startswith('<p class="verdict bad">No run ended ok: 1 diverged, 1 skipped')
    assert "inconsistent run" not in none


def _fake_report(root: Path, name: str, reference: str, errors: dict[str, float]) -> Path:
    tables = root / name / "tables"
    tables.mkdir(parents=True)
    runs = [
        {"filter": f, "scenario": "nominal", "status": "ok", "reference": reference,
         "pos_err_3d_rms_m": e, "pos_err_h_rms_m": e}
        for f, e in errors.items()
    ]  # fmt: skip
    (tables / "runs.json").write_text(json.dumps(runs))
    (tables / "provenance.json").write_text(json.dumps({"dataset": name}))
    return root / name


def test_the_summary_ranks_only_errors_against_a_truth(tmp_path: Path) -> None:
    # a log without truth: its "errors" are residuals to the fixes each filter fused; the
    # filter that follows its fixes best (tc_ukf here) would top a ranking it cannot earn
    sim = _fake_report(tmp_path, "sim", "truth", {"lc_ekf": 1.0, "tc_ukf": 2.0})
    flight = _fake_report(tmp_path, "flight", "fixes_residual", {"lc_ekf": 9.0, "tc_ukf": 0.1})
    index = render_summary([sim, flight], tmp_path / "summary")
    ranking = _csv_rows(tmp_path / "summary" / "tables" / "ranking.csv")
    assert [(r["filter"], r["cells"]) for r in ranking] == [("lc_ekf", "1"), ("tc_ukf", "1")]
    page = index.read_text()
    assert "Not ranked: flight." in page
    assert "residuals to the fixes the filters fused" in page


def test_logs_without_truth_rank_by_their_drift_against_the_onboard_estimate(
    tmp_path: Path,
) -> None:
    logs = []
    for name, ends in (("flight_a", {"lc_ekf": (4.0, 6.0), "tc_ekf": (9.0, 11.0)}),
                       ("flight_b", {"lc_ekf": (30.0,), "tc_ekf": (20.0,)})):  # fmt: skip
        report = _fake_report(tmp_path, name, "fixes_residual", dict.fromkeys(ends, 1.0))
        lines = ["filter,scenario,scope,window,pos_3d_end_m"]
        lines += [f"{f},nominal,run,," for f in ends]  # whole-run rows are not ranked
        lines += [f"{f},outage_30s,window,{i},{e}"
                  for f, es in ends.items() for i, e in enumerate(es)]  # fmt: skip
        (report / "tables" / "onboard_comparison.csv").write_text("\n".join(lines) + "\n")
        logs.append(report)
    index = render_summary(logs, tmp_path / "summary")
    rows = _csv_rows(tmp_path / "summary" / "tables" / "ranking_onboard.csv")
    # flight_a: lc_ekf 5 m vs tc_ekf 10 m; flight_b: tc_ekf 20 m vs lc_ekf 30 m: one each
    assert [(r["filter"], r["mean_rank"], r["wins"]) for r in rows] == [
        ("lc_ekf", "1.5", "1"), ("tc_ekf", "1.5", "1"),
    ]  # fmt: skip
    assert (
        not (tmp_path / "summary" / "tables" / "ranking.csv").read_text().strip("\n").count("\n")
    )  # nothing ranked on residuals
    assert "drift against the onboard estimate" in index.read_text()


def test_window_detail_draws_horizontal_error_where_the_reference_has_no_heights(
    tmp_path: Path,
) -> None:
    """SITL's SIMSTATE truth has no altitude: the 3-D error is NaN throughout, and the panel
    must show the horizontal error (labelled so) rather than an empty plot."""
    import re

    import pyarrow as pa

    from navreplay.pipeline.report.figures_outage import windows_detail
    from navreplay.pipeline.report.inputs import DatasetInputs, Run, Window
    from navreplay.pipeline.report.series import ErrorSeries

    t = np.arange(0, 120, 0.5)
    t_ns = (t * 1e9).astype(np.int64)
    err = np.column_stack([0.1 * t, 0.05 * t, np.full(t.size, np.nan)])
    series = {("lc_ekf", "outage_60s"): ErrorSeries(t_ns, "truth", err, np.ones_like(err))}
    estimate = pa.table({"t_ns": t_ns})
    win = Window(int(30e9), int(90e9), {"sats": 0})
    run = Run(tmp_path, "lc_ekf", "outage_60s", {}, estimate, None, [win])
    data = DatasetInputs("sitl", tmp_path, None, None, None, None, [run])
    svg = windows_detail(data, "outage_60s", series, "win")
    assert svg is not None
    assert "horizontal error, m" in svg
    assert "3-D error" not in svg
    # the line is drawn in the filter's colour: a path of many vertices, not an empty axes
    lines = re.findall(r'<path d="M([^"]+)"[^>]*stroke: #0072b2', svg)
    assert max(len(d.split()) for d in lines) > 100
