"""The reports in a real browser: no console errors, no blank figure, tables present.

Headless Chromium from Debian's ``chromium`` and ``chromium-driver`` packages, which
``make test`` installs when they are missing (Makefile ``browser``). Without them these tests
skip, unless NAVREPLAY_REQUIRE_BROWSER=1 (set by ``make test`` when it could install them).
A screenshot of each page's first screen goes to ``test-artifacts/``.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from navreplay.pipeline.report.inputs import load_dataset
from navreplay.pipeline.report.render import render_dataset
from navreplay.pipeline.report.summary import render_summary
from tests.browser.chromium import available, check_page, open_browser

ARTIFACTS = Path(__file__).resolve().parents[2] / "test-artifacts"


@pytest.fixture(scope="module")
def driver() -> Iterator[Any]:
    if not available():
        if os.environ.get("NAVREPLAY_REQUIRE_BROWSER") == "1":
            pytest.fail("/usr/bin/chromium or /usr/bin/chromedriver missing")
        pytest.skip(
            "no /usr/bin/chromium or /usr/bin/chromedriver: Debian's chromium and "
            "chromium-driver packages are not installed (`make browser` installs them with "
            "apt-get as root or through sudo)"
        )
    with open_browser() as d:
        yield d


def _experiments(exp: Path) -> Path:
    """What the outages and experiment stages write: the reduction table with its note, and
    an experiment folder with a CSV, a Markdown note and a matplotlib PNG figure."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot as plt

    exp.mkdir(parents=True)
    (exp / "sat_reduction.csv").write_text(
        "pair,sats,err_baseline_m,err_candidate_m,reduction_pct,ci_low_pct,ci_high_pct\n"
        "tc_ukf -> tc_ukf_nhc,0,40.0,20.0,50.0,41.5,57.3\n"
    )
    (exp / "sat_reduction_vs_paper.md").write_text("Ours **50 %**, the paper's 54.4 %.\n")
    d = exp / "tractor_cascaded" / "figures"
    d.mkdir(parents=True)
    (d.parent / "bias.csv").write_text("filter,rb_s\ncascaded_ekf,12.5\n")
    (d.parent / "notes.md").write_text("# Notes\n\n- converges in *12.5 s*\n")
    fig, ax = plt.subplots(figsize=(4, 3), dpi=80)
    ax.plot([0, 1, 2], [0, 1, 0])
    fig.savefig(d / "lateral.png")
    plt.close(fig)
    return exp


@pytest.fixture(scope="module")
def pages(dataset_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("pages")
    exp = _experiments(root / "experiments")
    data = load_dataset("tiny", dataset_dir / "tables", dataset_dir / "runs", exp)
    render_dataset(data, root / "tiny", experiments_dir=exp)
    summary = render_summary([root / "tiny"], root / "summary")
    return {"tiny": root / "tiny" / "index.html", "summary": summary}


def test_dataset_report_renders_cleanly(driver: Any, pages: dict[str, Path]) -> None:
    c = check_page(driver, pages["tiny"], ARTIFACTS / "report-tiny.png")
    assert c.console_errors == []
    assert len(c.figures) >= 6  # the report's own and the experiment's PNG
    assert [f.index for f in c.figures if f.blank] == []
    # every SVG figure draws many elements; the experiment's PNG is one <img>
    drawn = sorted(f.svg_elements for f in c.figures)
    assert drawn[0] == 1
    assert drawn[1] > 20
    assert c.tables >= 7  # with the reduction table and the experiment's CSV
    assert c.title == "navreplay report: tiny"
    assert (ARTIFACTS / "report-tiny.png").stat().st_size > 10_000


def test_zoom_changes_the_view_box(driver: Any, pages: dict[str, Path]) -> None:
    from selenium.webdriver.common.by import By

    driver.get(pages["tiny"].as_uri())
    svg = driver.find_element(By.CSS_SELECTOR, "figure.zoom svg")
    driver.execute_script("arguments[0].scrollIntoView({block: 'center'})", svg)
    view_box = "return arguments[0].getAttribute('viewBox')"
    before = driver.execute_script(view_box, svg)
    driver.execute_script(
        "arguments[0].dispatchEvent(new WheelEvent('wheel', {deltaY: -100, clientX: 300,"
        " clientY: 300, bubbles: true, cancelable: true}))",
        svg,
    )
    after = driver.execute_script(view_box, svg)
    assert before != after
    w0, w1 = float(before.split()[2]), float(after.split()[2])
    assert w1 == pytest.approx(0.8 * w0)


def test_summary_renders_cleanly(driver: Any, pages: dict[str, Path]) -> None:
    c = check_page(driver, pages["summary"], ARTIFACTS / "summary.png")
    assert c.console_errors == []
    assert c.tables >= 1


# The budget of issue 24: a 15-minute drive's report with 28 runs is at most 2 MB and renders
# in headless Chromium in under 2 s.
BUDGET_BYTES = 2_000_000
BUDGET_MS = 2000.0
FILTERS = ("lc_ekf", "lc_ekf_nhc", "tc_ekf", "tc_ekf_nhc", "tc_ukf", "tc_ukf_nhc", "fwekf")
SCENARIOS = ("nominal", "outage_60s", "sats_2", "sats_4")


@pytest.fixture(scope="module")
def long_report(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The built-in 15-minute campus drive with one real lc_ekf run, given to 28 filter x
    scenario run directories (the same estimate under each name: what the page has to carry
    and draw is what 28 runs of the drive give it), five 60 s windows in the outage ones."""
    import json
    import shutil

    from navreplay.pipeline.estimation.core.contract import write_run
    from navreplay.pipeline.estimation.families import run_tables
    from navreplay.pipeline.params import load_params
    from navreplay.pipeline.synth.seoul_campus import simulate
    from tests.pipeline.report.conftest import REPO, write_tables

    root = tmp_path_factory.mktemp("long")
    params = load_params(REPO / "params.yaml")
    sim = simulate(params.synth.seoul_campus, seed=3, variant="cw")
    tables = {k: v for k, v in sim.tables.items() if k in ("imu", "gnss", "truth")}
    write_tables(root / "tables", tables, sim.sensors)
    section = params.filters.get("lc_ekf")
    first = root / "runs" / "first"
    write_run(first, run_tables(root / "tables", "lc_ekf", section, "numba"), section, "nominal")
    t0 = int(tables["imu"].column("t_ns")[0].as_py())
    windows = [
        {"start_ns": t0 + round(s * 1e9), "end_ns": t0 + round((s + 60.0) * 1e9)}
        for s in (150.0, 290.0, 430.0, 570.0, 710.0)
    ]
    for f in FILTERS:
        for sc in SCENARIOS:
            d = root / "runs" / f / sc
            shutil.copytree(first, d)
            m = json.loads((d / "metrics.json").read_text())
            m.update(filter=f, scenario=sc)
            m.pop("outage_windows", None)
            if sc != "nominal":
                sats = 0 if sc == "outage_60s" else int(sc[-1])
                m["outage_windows"] = [dict(w, sats=sats) for w in windows]
            (d / "metrics.json").write_text(json.dumps(m))
    shutil.rmtree(first)
    data = load_dataset("campus", root / "tables", root / "runs", None)
    render_dataset(data, root / "report")
    return root / "report" / "index.html"


@pytest.mark.slow
def test_a_long_report_keeps_its_size_and_render_budget(driver: Any, long_report: Path) -> None:
    size = long_report.stat().st_size
    driver.get(long_report.resolve().as_uri())
    timing = driver.execute_script(
        "var n = performance.getEntriesByType('navigation')[0];"
        "return [n.domContentLoadedEventEnd, n.loadEventEnd];"
    )
    shot = ARTIFACTS / "report-campus-first-screen.png"
    shot.parent.mkdir(parents=True, exist_ok=True)
    driver.get_screenshot_as_file(str(shot))
    # the first screen is the verdict: its top is on it
    top = driver.execute_script(
        "return document.getElementById('verdict').getBoundingClientRect().top"
    )
    print(f"campus report: {size / 1e6:.2f} MB, DOM ready {timing[0]:.0f} ms, "
          f"loaded {timing[1]:.0f} ms")  # fmt: skip
    assert size <= BUDGET_BYTES, f"{size / 1e6:.2f} MB"
    assert 0 < timing[1] < BUDGET_MS, timing
    assert 0 <= top < 900
    assert shot.stat().st_size > 10_000


@pytest.fixture(scope="module")
def known_figure(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A page with one figure of known axes: x 0..10, y 0..100 (linear) over y 1..1000 (log),
    two labelled series on the top axes."""
    from navreplay.pipeline.report import html as h
    from navreplay.pipeline.report.svg import figure_svg, style

    with style() as plt:
        fig, (top, low) = plt.subplots(2, 1, figsize=(6.0, 5.0), layout="constrained")
        top.plot([0, 10], [0, 100], label="rising")
        top.plot([0, 10], [100, 0], label="falling")
        top.set_xlim(0, 10)
        top.set_ylim(0, 100)
        top.legend(loc="upper center")
        low.plot([0, 10], [1, 1000])
        low.set_yscale("log")
        low.set_xlim(0, 10)
        low.set_ylim(1, 1000)
        svg = figure_svg(fig, "known")
    page = tmp_path_factory.mktemp("known") / "index.html"
    page.write_text(h.page("known", "", [("fig", "Figure", h.figure(svg, "known axes"))]))
    return page


def _hover(driver: Any, svg: Any, fx: float, fy: float, axes: int) -> str:
    """Move the pointer to the fraction (fx, fy) of axes ``axes``'s box (fy from its bottom)
    and read the value the page shows."""
    return str(
        driver.execute_script(
            """
            const [svg, fx, fy, i] = arguments;
            const a = JSON.parse(svg.getAttribute('data-axes'))[i];
            const b = svg.viewBox.baseVal, r = svg.getBoundingClientRect();
            const x = r.left + (a[0] + fx * (a[2] - a[0]) - b.x) / b.width * r.width;
            const y = r.top + (a[3] - fy * (a[3] - a[1]) - b.y) / b.height * r.height;
            svg.dispatchEvent(new MouseEvent('mousemove', {clientX: x, clientY: y,
                                                          bubbles: true}));
            return svg.parentNode.querySelector('.readout').textContent;
            """,
            svg,
            fx,
            fy,
            axes,
        )
    )


def _values(text: str) -> tuple[float, float]:
    """``"x 5.0000, y 50.00"`` as (5.0, 50.0)."""
    x, y = (part.split()[1] for part in text.split(","))
    return float(x), float(y)


def test_the_pointer_reads_data_values_and_a_legend_click_hides_a_series(
    driver: Any, known_figure: Path
) -> None:
    from selenium.webdriver.common.by import By

    driver.get(known_figure.as_uri())
    svg = driver.find_element(By.CSS_SELECTOR, "figure.zoom svg")
    # the middle of the linear axes is (5, 50); three quarters up the log axes is 10^2.25;
    # a mouse event's coordinates are whole pixels: 1 px is about 0.3 % of either axes
    x, y = _values(_hover(driver, svg, 0.5, 0.5, 0))
    assert x == pytest.approx(5.0, abs=0.05)
    assert y == pytest.approx(50.0, abs=0.5)
    x, y = _values(_hover(driver, svg, 0.2, 0.75, 1))
    assert x == pytest.approx(2.0, abs=0.05)
    assert y == pytest.approx(10**2.25, rel=0.02)
    entry = driver.find_element(By.CSS_SELECTOR, '[id$="-ser1t"]')
    line = driver.find_element(By.CSS_SELECTOR, '[id$="-ser1"]')
    entry.click()
    assert line.value_of_css_property("opacity") == "0"
    other = driver.find_element(By.CSS_SELECTOR, '[id$="-ser0"]')
    assert other.value_of_css_property("opacity") == "1"
    entry.click()
    assert line.value_of_css_property("opacity") == "1"
