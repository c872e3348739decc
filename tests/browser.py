"""Open an HTML file in headless Chromium (selenium + chromedriver): console errors, broken images, boxes that
overlap, content wider than the window, a screenshot.

``python -m tests.browser REPORT.html SHOT_FOLDER`` checks the page at every width of :data:`WIDTHS`, saves a
screenshot per width there (``first_screen_<width>.png``), prints what it found and exits 1 on any problem; the
report test (tests/stages/test_report_browser.py) uses :func:`check_page`. :func:`browser_problem` says why no
browser can be had (None when one can), so tests skip with that reason.
"""
from __future__ import annotations

import os
import shutil
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

WINDOW = (1400, 900)
WIDTHS = {"phone": (390, 844), "1000": (1000, 800), "1400": WINDOW, "1920": (1920, 1080)}   # viewports checked
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
# the layout: pairs of content boxes that overlap on screen, and what runs off the right edge of the page.
# A box is clipped by every ancestor that scrolls or hides its overflow (a wide table in its own scrolling box
# only takes the box's room); boxes nested in each other are not compared.
LAYOUT_JS = """
const SEL = 'h1, h2, h3, h4, p, pre, table, figure, img, nav, details > summary, .ptable, .pfigs';
function clipped(el) {
  let r = el.getBoundingClientRect();
  let box = {l: r.left, t: r.top, r: r.right, b: r.bottom};
  for (let a = el.parentElement; a; a = a.parentElement) {
    const cs = getComputedStyle(a);
    if (cs.overflowX === 'visible' && cs.overflowY === 'visible') continue;
    const q = a.getBoundingClientRect();
    if (cs.overflowX !== 'visible') { box.l = Math.max(box.l, q.left); box.r = Math.min(box.r, q.right); }
    if (cs.overflowY !== 'visible') { box.t = Math.max(box.t, q.top); box.b = Math.min(box.b, q.bottom); }
  }
  return box;
}
function name(el) {
  const text = (el.getAttribute('title') || el.textContent || '').trim().replace(/\\s+/g, ' ').slice(0, 40);
  return el.tagName.toLowerCase() + (el.className ? '.' + el.className : '') + ' "' + text + '"';
}
function folded(el) {   // inside a closed <details> (its own <summary> is shown)
  for (let d = el.parentElement; d; d = d.parentElement) {
    if (d.tagName === 'DETAILS' && !d.open && !(el.tagName === 'SUMMARY' && el.parentElement === d)) return true;
  }
  return false;
}
const els = Array.from(document.querySelectorAll(SEL)).filter(el => {
  const r = el.getBoundingClientRect();
  return r.width > 0 && r.height > 0 && getComputedStyle(el).visibility !== 'hidden' && !folded(el);
});
const boxes = els.map(clipped);
const overlaps = [];
for (let i = 0; i < els.length; i++) {
  for (let j = i + 1; j < els.length; j++) {
    if (els[i].contains(els[j]) || els[j].contains(els[i])) continue;
    const a = boxes[i], b = boxes[j];
    const w = Math.min(a.r, b.r) - Math.max(a.l, b.l), h = Math.min(a.b, b.b) - Math.max(a.t, b.t);
    if (w > 1 && h > 1) overlaps.push(name(els[i]) + ' overlaps ' + name(els[j]));
  }
}
const vw = document.documentElement.clientWidth;
const off = els.filter((el, i) => boxes[i].r > vw + 1 && boxes[i].r > boxes[i].l).map(name);
return {overlaps: overlaps.slice(0, 50), n_overlaps: overlaps.length, off: off.slice(0, 50),
        scroll_width: document.documentElement.scrollWidth, width: vw};"""


@dataclass
class PageCheck:
    """What a page showed: console errors, broken images, table rows before the first figure, its top."""
    console_errors: list[str] = field(default_factory=list)
    broken_images: list[str] = field(default_factory=list)
    n_images: int = 0
    rows_before_first_figure: int = 0
    first_figure_top: float | None = None
    screenshot: str | None = None
    window: tuple[int, int] = WINDOW
    overlaps: list[str] = field(default_factory=list)       # "<box> overlaps <box>" (at most 50 shown)
    off_the_right: list[str] = field(default_factory=list)  # boxes reaching past the window's right edge
    horizontal_scroll: int = 0                              # page width beyond the window (px; 0: none)

    @property
    def layout_problems(self) -> list[str]:
        """Everything wrong with the layout at this width (empty: it reads)."""
        return (self.overlaps + [f"runs off the right edge: {x}" for x in self.off_the_right]
                + ([f"the page scrolls sideways by {self.horizontal_scroll} px"] if self.horizontal_scroll else []))


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


def check_page(html_path: str | os.PathLike, screenshot: str | os.PathLike | None = None,
               window: tuple[int, int] = WINDOW) -> PageCheck:
    """Load ``html_path`` in a headless Chromium viewport of ``window`` (width, height) pixels and report what it
    showed; save the first screen as PNG to ``screenshot`` when given. Raises RuntimeError when no browser can
    be had."""
    problem = browser_problem()
    if problem:
        raise RuntimeError(problem)
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    profile = tempfile.mkdtemp(prefix="chromium-profile-")
    opts = webdriver.ChromeOptions()
    opts.binary_location = _which(BROWSERS)
    for flag in CHROMIUM_FLAGS + (f"--user-data-dir={profile}", f"--window-size={window[0]},{window[1]}"):
        opts.add_argument(flag)
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(service=Service(_which(DRIVERS)), options=opts)
    try:
        driver.set_page_load_timeout(120)
        # the viewport itself is ``window`` (the window size includes the browser frame in some versions, and a
        # window has a minimum width): a phone's viewport is emulated as a phone (a touch screen, mobile layout)
        driver.execute_cdp_cmd("Emulation.setDeviceMetricsOverride", {
            "width": window[0], "height": window[1], "deviceScaleFactor": 1, "mobile": window[0] < 600})
        driver.get(Path(html_path).resolve().as_uri())
        out = PageCheck(window=tuple(window))
        out.console_errors = [e["message"] for e in driver.get_log("browser") if e.get("level") == "SEVERE"]
        out.broken_images = list(driver.execute_script(BROKEN_IMAGES_JS))
        out.n_images = int(driver.execute_script("return document.images.length;"))
        above = driver.execute_script(ABOVE_FIRST_FIGURE_JS)
        out.rows_before_first_figure, out.first_figure_top = int(above["rows"]), above["top"]
        layout = driver.execute_script(LAYOUT_JS)
        out.overlaps = list(layout["overlaps"]) + ([f"... {layout['n_overlaps'] - 50} more overlaps"]
                                                   if layout["n_overlaps"] > 50 else [])
        out.off_the_right = list(layout["off"])
        out.horizontal_scroll = max(0, int(layout["scroll_width"]) - int(layout["width"]))
        if screenshot:
            os.makedirs(os.path.dirname(os.path.abspath(screenshot)), exist_ok=True)
            driver.save_screenshot(str(screenshot))
            out.screenshot = str(screenshot)
        return out
    finally:
        driver.quit()
        shutil.rmtree(profile, ignore_errors=True)


if __name__ == "__main__":
    bad = False
    for label, size in WIDTHS.items():
        shot = os.path.join(sys.argv[2], f"first_screen_{label}.png") if len(sys.argv) > 2 else None
        result = check_page(sys.argv[1], shot, size)
        problems = result.console_errors + result.broken_images + result.layout_problems
        print(f"{label} ({size[0]}x{size[1]}): {len(problems)} problem(s)"
              + (f", screenshot {shot}" if shot else "") + "".join(f"\n  {p}" for p in problems))
        bad = bad or bool(problems)
    sys.exit(1 if bad else 0)
