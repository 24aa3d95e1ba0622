"""Open report.html in headless Chromium (Debian's ``chromium`` + ``chromium-driver``,
driven by Selenium) -- for the browser test and for the committed screenshot:

    python -m contactbench.harness.report.browser OUT/report.html OUT/report-paper.png --family paper

``browser_missing()`` says why no browser can be driven here (None when one can).
"""

from __future__ import annotations

import shutil
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

CHROMIUM_PATHS = ("/usr/bin/chromium", "/usr/bin/chromium-browser", "/usr/bin/google-chrome")
DRIVER_PATHS = ("/usr/bin/chromedriver", "/usr/lib/chromium/chromedriver")
#: Count of the traces Plotly has drawn (lines, markers and bars).
VISIBLE_TRACES_JS = ("return document.querySelectorAll('.js-plotly-plot .scatterlayer .trace, "
                     ".js-plotly-plot .barlayer .trace').length;")
#: Titles of the charts that hold a point to draw (a drawn trace with a y value) but show no mark:
#: no marker, no line and no bar with a path (a bar on the wrong kind of axis is dropped).
EMPTY_CHARTS_JS = """
return [...document.querySelectorAll('.js-plotly-plot')].filter(d =>
  (d.data || []).some(t => t.visible !== 'legendonly' && (t.y || []).some(v => v !== null && v !== undefined)) &&
  ![...d.querySelectorAll('.scatterlayer path.point, .scatterlayer path.js-line, .barlayer .point path')]
    .some(p => { const s = p.getAttribute('d') || ''; return s !== '' && s !== 'M0,0Z'; })
).map(d => (d.querySelector('.gtitle') || {}).textContent || '(untitled)');
"""
#: The longest legend entry on the page, in characters.
LONGEST_LEGEND_JS = ("return Math.max(0, ...[...document.querySelectorAll('.js-plotly-plot .legendtext')]"
                     ".map(e => e.textContent.length));")
#: The most series any one chart draws (its legend may list more that it does not draw, and a
#: legend entry's stand-in of no point draws nothing: a trace counts where it has a drawn path).
MOST_DRAWN_JS = """
return Math.max(0, ...[...document.querySelectorAll('.js-plotly-plot')].map(d =>
  [...d.querySelectorAll('.scatterlayer .trace, .barlayer .trace')].filter(t => [...t.querySelectorAll('path')]
    .some(p => { const s = p.getAttribute('d') || ''; return s !== '' && s !== 'M0,0Z'; })).length));
"""


def _first(paths: tuple[str, ...], name: str) -> str | None:
    return next((p for p in paths if Path(p).is_file()), None) or shutil.which(name)


def browser_missing() -> str | None:
    """Why headless Chromium cannot be driven here, or None."""
    try:
        import selenium  # noqa: F401
    except ImportError:
        return "selenium is not installed (pip install selenium)"
    if _first(CHROMIUM_PATHS, "chromium") is None:
        return "no Chromium binary (make setup-browser installs Debian's chromium as root)"
    if _first(DRIVER_PATHS, "chromedriver") is None:
        return "no chromedriver (make setup-browser installs Debian's chromium-driver as root)"
    return None


@dataclass
class PageCheck:
    """What a headless Chromium saw of a page."""

    load_s: float
    charts: int
    expected_charts: int
    traces: int
    empty_charts: list[str] = field(default_factory=list)
    most_drawn: int = 0
    longest_legend: int = 0
    console_errors: list[str] = field(default_factory=list)
    traces_after_toggle: int | None = None


def open_driver(width: int = 1400, height: int = 1000) -> Any:
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = _first(CHROMIUM_PATHS, "chromium") or ""
    for a in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage", "--disable-gpu",
              f"--window-size={width},{height}"):
        opts.add_argument(a)
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    return webdriver.Chrome(service=Service(_first(DRIVER_PATHS, "chromedriver")), options=opts)


def load_page(driver: Any, html: Path, timeout: float = 60.0) -> float:
    """Open ``html``; seconds until the page's script has drawn every chart."""
    t0 = time.perf_counter()
    driver.get(Path(html).resolve().as_uri())
    while driver.execute_script("return document.body && document.body.dataset.ready") != "1":
        if time.perf_counter() - t0 > timeout:
            raise TimeoutError(f"{html} did not finish drawing within {timeout:g} s")
        time.sleep(0.05)
    return time.perf_counter() - t0


def console_errors(driver: Any) -> list[str]:
    return [e["message"] for e in driver.get_log("browser") if e.get("level") == "SEVERE"]


def toggle_family(driver: Any, family: str) -> None:
    """Click the family's box in the solver picker (unticks every solver of it)."""
    box = driver.find_element("css selector", f"input[data-family='{family}']")
    box.click()
    time.sleep(0.2)


def only_family(driver: Any, family: str) -> None:
    """Leave only ``family`` ticked."""
    for box in driver.find_elements("css selector", "input[data-family]"):
        if (box.get_attribute("data-family") == family) != box.is_selected():
            box.click()
    time.sleep(0.3)


def check_page(html: Path, screenshot: Path | None = None, family: str | None = None) -> PageCheck:
    """Open the page, count charts and visible traces, name the charts with data but no
    mark, find the most series one chart draws and the longest legend entry, untick
    ``family`` (when given) and count again, and save a screenshot."""
    driver = open_driver()
    try:
        load_s = load_page(driver, html)
        charts = int(driver.execute_script("return document.querySelectorAll('.js-plotly-plot').length;"))
        expected = int(driver.execute_script(
            "return window.contactbenchReport.charts.filter(c => c.div).length;"))
        traces = int(driver.execute_script(VISIBLE_TRACES_JS))
        check = PageCheck(load_s, charts, expected, traces, list(driver.execute_script(EMPTY_CHARTS_JS)),
                          int(driver.execute_script(MOST_DRAWN_JS)), int(driver.execute_script(LONGEST_LEGEND_JS)))
        if family is not None:
            toggle_family(driver, family)
            check.traces_after_toggle = int(driver.execute_script(VISIBLE_TRACES_JS))
        if screenshot is not None:
            driver.save_screenshot(str(screenshot))
        check.console_errors = console_errors(driver)
        return check
    finally:
        driver.quit()


def screenshot_with_family(html: Path, png: Path, family: str, height: int = 1600) -> float:
    """A screenshot of the page with only ``family`` selected; returns the load time."""
    driver = open_driver(1400, height)
    try:
        load_s = load_page(driver, html)
        only_family(driver, family)
        driver.save_screenshot(str(png))
        return load_s
    finally:
        driver.quit()


if __name__ == "__main__":  # pragma: no cover - a maintenance command
    args = sys.argv[1:]
    fam = args[args.index("--family") + 1] if "--family" in args else "fast"
    why = browser_missing()
    if why:
        sys.exit(f"cannot drive a browser: {why}")
    t = screenshot_with_family(Path(args[0]), Path(args[1]), fam)
    print(f"{args[1]}: {fam} only; page drawn in {t:.2f} s")
