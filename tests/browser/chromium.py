"""Check HTML reports in headless Chromium (Debian's ``chromium`` + ``chromium-driver``).

``open_browser`` starts Chromium through chromedriver (selenium) with the sandbox-friendly
flags of ``FLAGS`` and a new, empty profile directory. ``check_page`` loads a report from
disk and returns what the tests assert: the browser console's errors, for every ``<figure>``
its number of drawn SVG elements and the pixel spread of a screenshot of it (a blank figure
has none), and the number of tables; it saves a screenshot of the first screen.

Run on built reports: ``python -m tests.browser.chromium reports/*/index.html``.
"""

from __future__ import annotations

import io
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

CHROMIUM = Path("/usr/bin/chromium")
CHROMEDRIVER = Path("/usr/bin/chromedriver")
FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--window-size=1366,900",
)
MIN_PIXEL_STD = 8.0  # 0..255 grey levels: a plot's lines and text give far more


@dataclass
class FigureCheck:
    index: int
    svg_elements: int
    pixel_std: float
    inked_fraction: float

    @property
    def blank(self) -> bool:
        return self.pixel_std < MIN_PIXEL_STD or self.inked_fraction < 0.002


@dataclass
class PageCheck:
    path: Path
    console_errors: list[str] = field(default_factory=list)
    figures: list[FigureCheck] = field(default_factory=list)
    tables: int = 0
    title: str = ""


def available() -> bool:
    return CHROMIUM.is_file() and CHROMEDRIVER.is_file()


@contextmanager
def open_browser() -> Iterator[Any]:
    """A headless Chromium session (selenium WebDriver) with a fresh profile."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    with tempfile.TemporaryDirectory(prefix="navreplay-chromium-") as profile:
        options = webdriver.ChromeOptions()
        options.binary_location = str(CHROMIUM)
        for flag in (*FLAGS, f"--user-data-dir={profile}"):
            options.add_argument(flag)
        options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
        driver = webdriver.Chrome(options=options, service=Service(str(CHROMEDRIVER)))
        try:
            yield driver
        finally:
            driver.quit()


def _pixels(png: bytes) -> tuple[float, float]:
    import matplotlib.image as mpimg

    img = mpimg.imread(io.BytesIO(png), format="png")
    grey = np.asarray(img[..., :3], dtype=np.float64).mean(axis=2) * 255.0
    return float(grey.std()), float(np.mean(grey < 200.0))


def check_page(driver: Any, path: Path, screenshot: Path | None = None) -> PageCheck:
    """Load ``path`` and inspect it (see the module docstring)."""
    from selenium.webdriver.common.by import By

    driver.get(path.resolve().as_uri())
    driver.execute_script("document.querySelectorAll('details').forEach(d => d.open = true)")
    out = PageCheck(path, title=driver.title)
    if screenshot is not None:
        screenshot.parent.mkdir(parents=True, exist_ok=True)
        driver.get_screenshot_as_file(str(screenshot))
    for i, fig in enumerate(driver.find_elements(By.CSS_SELECTOR, "figure")):
        driver.execute_script("arguments[0].scrollIntoView({block: 'start'})", fig)
        n = int(
            driver.execute_script(
                "return arguments[0].querySelectorAll('path, use, text, image, img').length", fig
            )
        )
        std, inked = _pixels(fig.screenshot_as_png)
        out.figures.append(FigureCheck(i, n, std, inked))
    out.tables = len(driver.find_elements(By.CSS_SELECTOR, "table"))
    out.console_errors = [
        e["message"] for e in driver.get_log("browser") if e.get("level") in ("SEVERE", "ERROR")
    ]
    return out


def main(argv: list[str]) -> int:
    """Check each page given; prints one line per page; exit 1 if any check fails."""
    failed = 0
    with open_browser() as driver:
        for arg in argv:
            page = Path(arg)
            shot = Path("test-artifacts") / f"{page.parent.name}.png"
            c = check_page(driver, page, shot)
            blank = [f.index for f in c.figures if f.blank]
            ok = not c.console_errors and not blank and c.tables > 0
            failed += not ok
            print(
                f"{'ok  ' if ok else 'FAIL'} {page}: {len(c.figures)} figures "
                f"(blank: {blank or 'none'}), {c.tables} tables, "
                f"console errors: {c.console_errors or 'none'}; first screen -> {shot}"
            )
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
