"""The report in a real browser: headless Chromium opens it at a phone's width and at 1000, 1400 and 1920 px:
no console error, no broken image, no two content boxes overlapping and nothing wider than the window (wide
tables scroll inside their own box), the summary (and at most 40 table rows) before the first figure (that every
figure links to its full-size file: tests/stages/test_report.py). A screenshot of the first screen at 1400x900 is saved to
``$REPORT_SCREENSHOT`` (default ``<temp dir>/report_first_screen.png``, e.g. /tmp/...; the README's
docs/img/report_first_screen.png is this screenshot of the default pipeline's report, see tests/browser.py), and
one per width next to it (``report_first_screen_<width>.png``).

Skipped, saying why, when no browser can be had (selenium, chromium and chromedriver are needed:
``apt-get install -y chromium chromium-driver`` and ``pip install -e '.[test]'``; ``.ci/run`` installs them).
"""
from __future__ import annotations

import os
import struct
import tempfile

import pytest

from stages import api
from stages.report import write_report
from tests.browser import WIDTHS, WINDOW, browser_problem, check_page
from tests.stages.test_report import project  # noqa: F401  (the fixture: a pipeline with figure stages)

pytestmark = pytest.mark.skipif(browser_problem() is not None, reason=f"no headless browser: {browser_problem()}")


def _png_size(path: str) -> tuple[int, int]:
    with open(path, "rb") as fh:
        head = fh.read(24)
    assert head[:8] == b"\x89PNG\r\n\x1a\n", f"{path} is not a PNG"
    return struct.unpack(">II", head[16:24])


def _screenshot_path() -> str:
    return os.environ.get("REPORT_SCREENSHOT") or os.path.join(tempfile.gettempdir(), "report_first_screen.png")


@pytest.mark.e2e   # a whole multi-process run: .ci/run (pytest -m e2e), not the README's test command
def test_report_in_headless_chromium(project, tmp_path):  # noqa: F811
    path = str(project)
    api.run(path, workers=0, quiet=True)
    api.sweep(path, ["sigma=0.5,1,2"], workers=0, quiet=True)      # a sweep table too (wide, many columns)
    html = write_report(path)
    shot = _screenshot_path()
    page = check_page(html, shot)
    assert page.console_errors == []
    assert page.broken_images == []
    assert page.n_images == 2 + 2 * 6 + 1         # every published figure, each once (and the sweep's plot)
    assert page.rows_before_first_figure <= 40
    assert page.first_figure_top is not None and page.first_figure_top < WINDOW[1]   # a figure on the first screen
    assert _png_size(shot) == WINDOW
    assert page.layout_problems == []
    for label, size in WIDTHS.items():
        if size == WINDOW:
            continue
        other = check_page(html, shot[:-4] + f"_{label}.png", size)
        assert other.window == size and _png_size(other.screenshot) == size
        assert other.layout_problems == [], f"{label} ({size[0]} px wide)"
        assert other.console_errors == [] and other.broken_images == []


def test_broken_image_and_console_error_are_caught(tmp_path):
    """The checker itself: a page with a broken image and a script error fails it."""
    bad = tmp_path / "bad.html"
    bad.write_text('<!DOCTYPE html><html><body><figure><img src="data:image/png;base64,AAAA" title="broken">'
                   "</figure><script>undefinedFunction();</script></body></html>")
    page = check_page(bad)
    assert page.broken_images == ["broken"]
    assert any("undefinedFunction" in e for e in page.console_errors)


def test_overlap_and_overflow_are_caught(tmp_path):
    """The checker itself: a figure column laid over a table and a table wider than the window fail it; the same
    wide table inside its own scrolling box does not."""
    wide = "<table><tr>" + "<td>123456.789</td>" * 40 + "</tr></table>"
    bad = tmp_path / "bad.html"
    bad.write_text('<!DOCTYPE html><html><body style="margin:0"><table style="width:600px"><tr><td>energy</td></tr>'
                   '</table><figure style="position:absolute;top:0;left:100px;width:300px;height:100px">'
                   f"<p>figure</p></figure>{wide}</body></html>")
    page = check_page(bad, window=(1000, 800))
    assert any(x.startswith("table") and "overlaps figure" in x for x in page.overlaps)
    assert page.horizontal_scroll > 0 and page.off_the_right
    good = tmp_path / "good.html"
    good.write_text(f'<!DOCTYPE html><html><body><div style="overflow-x:auto">{wide}</div></body></html>')
    assert check_page(good, window=(1000, 800)).layout_problems == []
