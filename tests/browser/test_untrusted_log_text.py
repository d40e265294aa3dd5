"""Text from a log is shown as text: a log whose file name, topic names or messages
(MAVLink STATUSTEXT) carry HTML and script gives a report that escapes them (the page source),
and a browser that runs none of it and shows them as written (headless Chromium)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from navreplay.pipeline.cli import main
from tests.browser.test_reports_in_chromium import driver
from tests.ingest.mavlogs import UTC0_US, mav, tlog_drive
from tests.ingest.roslogs import fix_stream, imu_data, imu_stream, write_mcap

__all__ = ["driver"]

SCRIPT = "<script>alert(1)</script>"
IMG = '"><img src=x onerror=alert(2)>'


@pytest.fixture(scope="module")
def hostile_report(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("hostile")
    log = root / f"drive{IMG}.mcap"
    streams = [
        imu_stream(imu_data(3000), topic=f"/imu{SCRIPT}"),
        fix_stream(150, topic=f"/fix{IMG}"),
    ]
    write_mcap(log, streams)
    rc = main(["-q", "analyze", str(log), "--filters", "lc_ekf", "--scenarios", "nominal",
               "--out", str(root / "out")])  # fmt: skip
    assert rc in (0, 3)  # a log at rest may not align: the report is written either way
    return root / "out" / "report" / "index.html"


def test_the_page_source_escapes_what_the_log_says(hostile_report: Path) -> None:
    page = hostile_report.read_text()
    assert SCRIPT not in page
    assert "<img src=x" not in page
    assert "/imu&lt;script&gt;alert(1)&lt;/script&gt;" in page
    assert "&quot;&gt;&lt;img src=x onerror=alert(2)&gt;" in page
    assert page.count("<script>") == 1  # the page's own


def test_the_browser_shows_it_as_text_and_runs_none_of_it(
    driver: Any, hostile_report: Path
) -> None:
    driver.get(hostile_report.resolve().as_uri())
    driver.execute_script("document.querySelectorAll('details').forEach(d => d.open = true)")
    text = driver.execute_script("return document.body.innerText")
    assert f"/imu{SCRIPT}" in text
    assert IMG in text
    assert driver.execute_script("return document.querySelectorAll('img[onerror]').length") == 0
    assert driver.execute_script("return document.scripts.length") == 1


@pytest.fixture(scope="module")
def hostile_messages(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A tlog whose vehicle sends STATUSTEXT messages holding markup, ingested and reported."""
    root = tmp_path_factory.mktemp("hostile_tlog")
    log = tlog_drive()
    link = mav()
    for i, text in enumerate((SCRIPT, IMG)):
        log.add(UTC0_US + 1_000_000 + i, link, link.statustext_encode(2, text.encode()))
    order = sorted(range(len(log.stamps_us)), key=lambda i: log.stamps_us[i])
    records = log.records()
    path = log.write(root / "flight.tlog", [records[i] for i in order])
    assert main(["-q", "ingest", str(path), "--out", str(root / "tables")]) == 0
    assert main(["-q", "report", "flight", "--tables", str(root / "tables"),
                 "--out", str(root / "report")]) == 0  # fmt: skip
    return root / "report" / "index.html"


def test_statustext_is_escaped_in_the_page_and_shown_as_text_by_the_browser(
    driver: Any, hostile_messages: Path
) -> None:
    page = hostile_messages.read_text()
    assert SCRIPT not in page
    assert "<img src=x" not in page
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in page
    assert page.count("<script>") == 1  # the page's own
    driver.get(hostile_messages.resolve().as_uri())
    driver.execute_script("document.querySelectorAll('details').forEach(d => d.open = true)")
    text = driver.execute_script("return document.body.innerText")
    assert SCRIPT in text  # in the messages table, as the vehicle sent them
    assert IMG in text
    assert driver.execute_script("return document.querySelectorAll('img[onerror]').length") == 0
    assert driver.execute_script("return document.scripts.length") == 1
