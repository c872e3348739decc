"""Open an HTML file in headless Chromium (selenium + chromedriver): console errors, broken images, a screenshot.

``python -m tests.browser REPORT.html SHOT.png`` prints what it found (and exits 1 on errors); the report test
(tests/stages/test_report_browser.py) uses :func:`check_page`. :func:`browser_problem` says why no browser can
be had (None when one can), so tests skip with that reason.
"""
from __future__ import annotations

import os
import shutil
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

WINDOW = (1400, 900)
CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync",
                  "--disable-dev-shm-usage", "--hide-scrollbars")
BROWSERS = ("chromium", "chromium-browser", "google-chrome")
DRIVERS = ("chromedriver",)

# every <img> that failed to load or decoded to nothing
BROKEN_IMAGES_JS = """return Array.from(document.images).filter(
    im => !im.complete || im.naturalWidth === 0).map(im => im.title || im.alt || im.src.slice(0, 60));"""
# the page's vertical position of the first figure image, and the visible table rows before it (document order)
ABOVE_FIRST_FIGURE_JS = """
const img = document.querySelector('figure img');
const visible = tr => tr.getBoundingClientRect().height > 0;
if (!img) return {top: null, rows: Array.from(document.querySelectorAll('tr')).filter(visible).length};
const top = img.getBoundingClientRect().top + window.scrollY;
const rows = Array.from(document.querySelectorAll('tr')).filter(
    tr => visible(tr) && (tr.compareDocumentPosition(img) & Node.DOCUMENT_POSITION_FOLLOWING)).length;
return {top: top, rows: rows};"""


@dataclass
class PageCheck:
    """What a page showed: console errors, broken images, table rows before the first figure, its top."""
    console_errors: list[str] = field(default_factory=list)
    broken_images: list[str] = field(default_factory=list)
    n_images: int = 0
    rows_before_first_figure: int = 0
    first_figure_top: float | None = None
    screenshot: str | None = None


def _which(names) -> str | None:
    return next((p for p in (shutil.which(n) for n in names) if p), None)


def browser_problem() -> str | None:
    """Why no headless browser can be had here (None: one can)."""
    try:
        import selenium  # noqa: F401
    except ImportError:
        return "selenium is not installed (pip install -e '.[test]')"
    if not _which(BROWSERS):
        return "no Chromium found (apt-get install -y chromium chromium-driver)"
    if not _which(DRIVERS):
        return "no chromedriver found (apt-get install -y chromium-driver)"
    return None


def check_page(html_path: str | os.PathLike, screenshot: str | os.PathLike | None = None) -> PageCheck:
    """Load ``html_path`` in a 1400x900 headless Chromium window and report what it showed; save the first
    screen as PNG to ``screenshot`` when given. Raises RuntimeError when no browser can be had."""
    problem = browser_problem()
    if problem:
        raise RuntimeError(problem)
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    profile = tempfile.mkdtemp(prefix="chromium-profile-")
    opts = webdriver.ChromeOptions()
    opts.binary_location = _which(BROWSERS)
    for flag in CHROMIUM_FLAGS + (f"--user-data-dir={profile}", f"--window-size={WINDOW[0]},{WINDOW[1]}"):
        opts.add_argument(flag)
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(service=Service(_which(DRIVERS)), options=opts)
    try:
        driver.set_page_load_timeout(120)
        driver.get(Path(html_path).resolve().as_uri())
        # the window size includes the browser frame in some versions: make the viewport itself 1400x900
        inner = driver.execute_script("return [window.innerWidth, window.innerHeight];")
        driver.set_window_size(2 * WINDOW[0] - inner[0], 2 * WINDOW[1] - inner[1])
        out = PageCheck()
        out.console_errors = [e["message"] for e in driver.get_log("browser") if e.get("level") == "SEVERE"]
        out.broken_images = list(driver.execute_script(BROKEN_IMAGES_JS))
        out.n_images = int(driver.execute_script("return document.images.length;"))
        above = driver.execute_script(ABOVE_FIRST_FIGURE_JS)
        out.rows_before_first_figure, out.first_figure_top = int(above["rows"]), above["top"]
        if screenshot:
            os.makedirs(os.path.dirname(os.path.abspath(screenshot)), exist_ok=True)
            driver.save_screenshot(str(screenshot))
            out.screenshot = str(screenshot)
        return out
    finally:
        driver.quit()
        shutil.rmtree(profile, ignore_errors=True)


if __name__ == "__main__":
    result = check_page(sys.argv[1], sys.argv[2] if len(sys.argv) > 2 else None)
    print(result)
    sys.exit(1 if result.console_errors or result.broken_images else 0)
