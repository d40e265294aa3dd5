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
