"""Every table of every shipped report page fits 800 px: no table scrolls in its box, no header wraps past two lines.

In a headless Chromium (Playwright) at an 800 px window, every ``<details>`` opened (folded tables
included), each table's box (``.table-wrap``) must show the whole table (its scroll width at most
its width), and each header cell must hold at most two lines of text. Issue 61 measured pair tables
wrapping "first − second" onto 7 to 9 lines and the gap table running off the page; the findings,
ladder and pair tables are laid out to fit. Table 1 is one table per ‖A‖₂ and the
compute table one row per method and N, so that they fit too. ``COMPARE_REPORTS=FOLDER`` checks
the report folders in FOLDER instead.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from test_report_browser import _browser_path  # noqa: E402  (tests/test_report_browser.py)

REPORTS = Path(os.environ.get("COMPARE_REPORTS") or Path(__file__).resolve().parents[1] / "reports")
SHIPPED = sorted(p.name for p in REPORTS.iterdir() if (p / "report.html").exists())
WIDTH = 800

_CHECK = """() => {
  for (const d of document.querySelectorAll('details')) d.open = true;
  const out = [];
  for (const wrap of document.querySelectorAll('.table-wrap')) {
    const table = wrap.querySelector('table');
    const first = (table.querySelector('th') || {}).textContent || '';
    const heading = (() => { let e = wrap; while (e && !/^H[23]$/.test(e.tagName)) e = e.previousElementSibling
                                                                                      || e.parentElement;
                             return e ? e.textContent : ''; })();
    const over = table.scrollWidth - wrap.clientWidth;
    let lines = 0, worst = '';
    for (const th of table.querySelectorAll('th')) {
      const lh = parseFloat(getComputedStyle(th).lineHeight) || 20;
      const pad = parseFloat(getComputedStyle(th).paddingTop) + parseFloat(getComputedStyle(th).paddingBottom);
      const range = document.createRange(); range.selectNodeContents(th);
      const rects = Array.from(range.getClientRects()).map(r => Math.round(r.top));
      const n = new Set(rects).size;
      if (n > lines) { lines = n; worst = th.textContent; }
    }
    out.push({first: first.trim(), heading: heading.trim(), over: over, lines: lines, worst: worst});
  }
  return out;
}"""


@pytest.fixture(scope="module")
def tab():
    sync_api = pytest.importorskip("playwright.sync_api",
                                   reason="playwright is not installed: the browser test did not run")
    executable = _browser_path()
    if executable is None:
        pytest.skip("no Chromium found (chromium, chromium-browser, google-chrome or $CHROMIUM_PATH): "
                    "the browser test did not run")
    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=executable, args=["--no-sandbox"])
        yield browser.new_page(viewport={"width": WIDTH, "height": 900})
        browser.close()


@pytest.mark.parametrize("name", SHIPPED)
def test_every_table_fits_800_px_and_no_header_wraps_past_two_lines(tab, name):
    tab.goto((REPORTS / name / "report.html").as_uri())
    tables = tab.evaluate(_CHECK)
    problems = []
    for t in tables:
        if t["over"] > 1:
            problems.append(f"{t['heading'][:50]!r} (first header {t['first']!r}): {t['over']} px too wide")
        if t["lines"] > 2:
            problems.append(f"{t['heading'][:50]!r}: header {t['worst']!r} on {t['lines']} lines")
    assert not problems, f"{name} at {WIDTH} px:\n" + "\n".join(problems)
