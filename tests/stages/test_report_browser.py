"""The report in a real browser: headless Chromium opens it, no console error, no broken image, the summary
(and at most 40 table rows) comes before the first figure, and a screenshot of the first screen (1400x900) is
saved to ``$REPORT_SCREENSHOT`` (default ``<temp dir>/report_first_screen.png``, e.g. /tmp/...).

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
from tests.browser import WINDOW, browser_problem, check_page
from tests.stages.test_report import project  # noqa: F401  (the fixture: a pipeline with figure stages)

pytestmark = pytest.mark.skipif(browser_problem() is not None, reason=f"no headless browser: {browser_problem()}")


def _png_size(path: str) -> tuple[int, int]:
    with open(path, "rb") as fh:
        head = fh.read(24)
    assert head[:8] == b"\x89PNG\r\n\x1a\n", f"{path} is not a PNG"
    return struct.unpack(">II", head[16:24])


def _screenshot_path() -> str:
    return os.environ.get("REPORT_SCREENSHOT") or os.path.join(tempfile.gettempdir(), "report_first_screen.png")


def test_report_in_headless_chromium(project, tmp_path):  # noqa: F811
    path = str(project)
    api.run(path, workers=0, quiet=True)
    html = write_report(path)
    shot = _screenshot_path()
    page = check_page(html, shot)
    assert page.console_errors == []
    assert page.broken_images == []
    assert page.n_images == 2 + 2 * 6            # every published figure, each once
    assert page.rows_before_first_figure <= 40
    assert page.first_figure_top is not None and page.first_figure_top < WINDOW[1]   # a figure on the first screen
    assert _png_size(shot) == WINDOW


def test_broken_image_and_console_error_are_caught(tmp_path):
    """The checker itself: a page with a broken image and a script error fails it."""
    bad = tmp_path / "bad.html"
    bad.write_text('<!DOCTYPE html><html><body><figure><img src="data:image/png;base64,AAAA" title="broken">'
                   "</figure><script>undefinedFunction();</script></body></html>")
    page = check_page(bad)
    assert page.broken_images == ["broken"]
    assert any("undefinedFunction" in e for e in page.console_errors)
