"""Every report page reads at 800 and 1400 px: nothing overlaps, nothing scrolls sideways, every image opens.

In a headless Chromium (Playwright), for every shipped ``reports/*/report.html`` and for a
page written here by :func:`compare.report.write_report` from a small grid of panels
(two N by two ‖A‖₂, so the N × ‖A‖₂ grid with links per node): the boxes of the
interactive figures' axis titles, tick labels, legends and plot areas do not intersect
(within one panel plot, or between panels), none leaves its plot or the window, the
page is not wider than the window, every image is a link to its file, no PNG is wider
than 1,700 px, and every image's smallest text, its size read from the figure's SVG
(``figure_legibility.py``) and scaled to the width the page shows it at, is 9 px tall. One browser
and one tab serve every page; each page is loaded once at 1400 px and checked again
after the window narrows to 800 px, so that the reflow itself is checked. A shipped page
written before the per-panel figures is skipped, saying so; ``COMPARE_REPORTS=FOLDER``
checks the report folders in FOLDER instead (copies rebuilt with ``compare report``).
"""

from __future__ import annotations

import html
import os
import re
from pathlib import Path
from urllib.parse import unquote

import pytest

pytest.importorskip("plotly", reason="plotly is not installed")

from figure_legibility import MAX_PNG_PX, SCREEN_PX, legibility  # noqa: E402  (tests/figure_legibility.py)
from test_report_browser import _browser_path, _row  # noqa: E402  (tests/test_report_browser.py)

from compare.run.records import Records, canonical_key  # noqa: E402

#: The shipped reports; $COMPARE_REPORTS names another folder of report folders (rebuilt copies, say).
REPORTS = Path(os.environ.get("COMPARE_REPORTS") or Path(__file__).resolve().parents[1] / "reports")
WIDTHS = (1400, 800)
#: What marks a page written with the per-panel figures (one plotly plot per panel, an HTML legend).
NEW_PAGE = 'class="cl-figure"'

# The boxes of every plotly plot on the page, and the problems among them, in one call.
_CHECK = """() => {
  const W = window.innerWidth, problems = [];
  const sw = document.documentElement.scrollWidth;
  if (sw > W) problems.push(`the page is ${sw} px wide in a ${W} px window`);
  const tol = 0.5;
  const meets = (a, b) => a.left < b.right - tol && b.left < a.right - tol && a.top < b.bottom - tol
                          && b.top < a.bottom - tol;
  const union = rs => ({left: Math.min(...rs.map(r => r.left)), right: Math.max(...rs.map(r => r.right)),
                        top: Math.min(...rs.map(r => r.top)), bottom: Math.max(...rs.map(r => r.bottom))});
  const shown = el => { for (let e = el; e && e.nodeType === 1; e = e.parentNode) {
      const s = getComputedStyle(e); if (s.display === 'none' || s.visibility === 'hidden') return false; }
    return true; };
  const plots = Array.from(document.querySelectorAll('.js-plotly-plot'));
  const outline = [];
  for (const div of plots) {
    const name = (div.closest('.cl-figure') || div).id + ' ' + (div.id || '');
    const items = [];
    // .g-xtitle, .xtick ... and, in a plot of several subplots, .g-x2title, .x2tick ...
    for (const [sel, kind] of [['g[class^="g-x"][class$="title"]', 'x title'],
                               ['g[class^="g-y"][class$="title"]', 'y title'],
                               ['g[class^="x"][class$="tick"] text', 'x tick'],
                               ['g[class^="y"][class$="tick"] text', 'y tick'],
                               ['.legend', 'legend'], ['.nsewdrag', 'plot area']]) {
      div.querySelectorAll(sel).forEach(el => {
        const r = el.getBoundingClientRect();
        if (r.width > 0 && r.height > 0 && shown(el)) items.push({kind, text: el.textContent.trim(), r});
      });
    }
    if (!items.some(i => i.kind === 'plot area')) { problems.push(`${name}: no plot area drawn`); continue; }
    div.querySelectorAll('.legend .scrollbar').forEach(el => {
      const r = el.getBoundingClientRect();
      if (r.width > 0 && r.height > 0 && shown(el)) problems.push(`${name}: the legend is cut off (it scrolls)`);
    });
    for (let i = 0; i < items.length; i++)
      for (let j = i + 1; j < items.length; j++)
        if (meets(items[i].r, items[j].r))
          problems.push(`${name}: ${items[i].kind} "${items[i].text}" meets ${items[j].kind} "${items[j].text}"`);
    const box = div.getBoundingClientRect();
    for (const it of items) {
      if (it.r.left < box.left - 1 || it.r.right > box.right + 1 || it.r.top < box.top - 1
          || it.r.bottom > box.bottom + 1)
        problems.push(`${name}: ${it.kind} "${it.text}" leaves its plot`);
      if (it.r.left < -tol || it.r.right > W + tol) problems.push(`${name}: ${it.kind} "${it.text}" leaves the window`);
    }
    outline.push({name, r: union(items.map(i => i.r))});
  }
  for (let i = 0; i < outline.length; i++)
    for (let j = i + 1; j < outline.length; j++)
      if (meets(outline[i].r, outline[j].r)) problems.push(`${outline[i].name} meets ${outline[j].name}`);
  document.querySelectorAll('.cl-legend, .cl-bar').forEach(el => {
    const r = el.getBoundingClientRect();
    if (r.right > W + tol) problems.push(`a legend runs out of the window (${r.right} > ${W})`);
    for (const o of outline) if (meets(r, o.r)) problems.push(`a legend meets ${o.name}`);
  });
  const columns = new Set(plots.filter(d => d.closest('.cl-figure'))
                                .map(d => Math.round(d.getBoundingClientRect().left)));
  const images = Array.from(document.querySelectorAll('img')).map(img => {
    const a = img.closest('a[href]'); return a ? a.getAttribute('href') : null; });
  // Each image's file, its own width and the width it is shown at: its text's size on screen (issue 61).
  const sizes = Array.from(document.querySelectorAll('img')).map(img => {
    const a = img.closest('a[href]');
    return [a ? a.getAttribute('href') : null, img.naturalWidth, img.getBoundingClientRect().width]; });
  return {problems, plots: plots.length, columns: columns.size, images, shown: sizes};
}"""


def _grid_records() -> Records:
    """Two N by two ‖A‖₂, three seeds: LQR, a γ path, a delayed β path, decentralized."""
    rows, facts = [], {}
    for n in (6, 12):
        for a_norm in (0.995, 1.05):
            for seed in range(3):
                spec = {"family": "paper", "n": n, "a_norm": a_norm, "seed": seed}
                facts[canonical_key(spec)] = {"n": n, "nodes": n, "plant_links": 2 * n, "comm_links": 2 * n}
                full = n * (n - 1)
                rows.append(_row(spec, "lqr", "LQR (centralized)", {}, 1.0, full, "instantaneous", 0))
                for i, gamma in enumerate((0.01, 0.1, 1.0)):
                    rows.append(_row(spec, "sparse_admm", "Sparse K (l1 ADMM)", {"gamma": gamma, "rho": 1.0},
                                     1.0 + 0.02 * i ** 2 + 0.003 * seed, full // (2 ** (2 * i)), "instantaneous", i))
                for i, beta in enumerate((0.1, 1.0)):
                    rows.append(_row(spec, "grnn_sparse", "GRNN-Sparse (β path)", {"beta": beta},
                                     1.03 + 0.05 * i, 3 * n // (i + 1), "delayed", i))
                rows.append(_row(spec, "decentralized", "Decentralized (diagonal K)", {}, 1.4 + 0.05 * seed, 0,
                                 "none", 0))
                rows.append(_row(spec, "autonomous", "Autonomous (u = 0)", {}, 30.0 + seed, 0, "none", 0))
    return Records.from_rows(rows, facts=facts)


@pytest.fixture(scope="module")
def written_page(tmp_path_factory) -> Path:
    from compare.report.write import write_report

    out = tmp_path_factory.mktemp("grid")
    files = write_report(_grid_records(), out, title="Grid page")
    return files["html"]


def _pages() -> list[str]:
    return ["written"] + sorted(p.parent.name for p in REPORTS.glob("*/report.html"))


@pytest.fixture(scope="module")
def tab():
    sync_api = pytest.importorskip("playwright.sync_api",
                                   reason="playwright is not installed: the page layout was not checked")
    executable = _browser_path() or next((p for p in ("/usr/bin/chromium",) if Path(p).is_file()), None)
    if executable is None:
        pytest.skip("no Chromium found (chromium, chromium-browser, google-chrome or $CHROMIUM_PATH): "
                    "the page layout was not checked")
    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=executable, args=["--no-sandbox"])
        page = browser.new_page(viewport={"width": WIDTHS[0], "height": 900})
        errors: list[str] = []
        page.on("pageerror", lambda e: errors.append(str(e)))
        yield page, errors
        browser.close()


def _settled(page) -> None:
    """Wait until every plotly plot has been drawn at its box's current size (after a load or a resize)."""
    page.wait_for_function(
        """() => Array.from(document.querySelectorAll('.cl-plot')).every(d => d._fullLayout
              && d.querySelector('.main-svg')
              && Math.abs(d._fullLayout.width - d.clientWidth) <= 1
              && Math.abs(d._fullLayout.height - d.clientHeight) <= 1)""",
        timeout=30_000)
    page.wait_for_timeout(150)  # plotly's resize handler settles its last redraw


@pytest.mark.parametrize("name", _pages())
def test_page_reads_at_800_and_1400_px(tab, name, written_page):
    page, errors = tab
    path = written_page if name == "written" else REPORTS / name / "report.html"
    text = path.read_text()
    if NEW_PAGE not in text:
        pytest.skip(f"reports/{name}/report.html was written before the per-panel figures: rebuild it with "
                    f"`compare report --out reports/{name}` to check its layout")
    errors.clear()
    page.set_viewport_size({"width": WIDTHS[0], "height": 900})
    page.goto(path.as_uri())
    seen = {}
    for width in WIDTHS:
        page.set_viewport_size({"width": width, "height": 900})
        _settled(page)
        seen[width] = result = page.evaluate(_CHECK)
        assert result["problems"] == [], f"{name} at {width} px:\n" + "\n".join(result["problems"][:20])
        assert result["plots"] >= 1
    assert errors == []
    assert seen[800]["columns"] == 1  # the panels reflow into one column
    # Every image opens its own file (beside the page).
    hrefs = seen[800]["images"]
    assert None not in hrefs, f"{name}: an image that is not a link"
    for href in hrefs:
        assert (path.parent / unquote(html.unescape(href))).is_file(), href
    assert len(hrefs) == len(re.findall(r"<img\b", text))
    # Every image's smallest text is 9 px tall on screen at both widths, and no PNG is wider than 1,700 px.
    checked = 0
    for width in WIDTHS:
        for href, natural, shown in seen[width]["shown"]:
            png = path.parent / unquote(html.unescape(href))
            if png.suffix != ".png" or not png.with_suffix(".svg").is_file():
                continue
            legible = legibility(png)
            assert natural <= MAX_PNG_PX, f"{name}: {href} is {natural} px wide"
            if legible is not None:
                assert legible.on_screen(shown) >= SCREEN_PX, (
                    f"{name} at {width} px: {href} shown {shown:.0f} of {natural} px wide, its "
                    f"{legible.points:g}-point {legible.text!r} {legible.on_screen(shown):.1f} px tall")
                checked += 1
    assert checked or name != "written"  # the written page shows its forest plot


def test_the_written_page_lays_out_the_grid(written_page, tab):
    """Two N by two ‖A‖₂: rows = N, columns = ‖A‖₂ at 1400 px, links per node on x."""
    page, _ = tab
    page.set_viewport_size({"width": 1400, "height": 900})
    page.goto(written_page.as_uri())
    _settled(page)
    cells = page.evaluate("""() => Array.from(document.querySelectorAll('#fig-cost-vs-links .cl-plot')).map(d => {
        const r = d.getBoundingClientRect(); return [d.layout.meta.panel, Math.round(r.left), Math.round(r.top),
        d.layout.meta.x_per_node, d.layout.xaxis.title.text]; })""")
    assert len(cells) == 4
    lefts = {tuple(panel): left for panel, left, _, _, _ in cells}
    tops = {tuple(panel): top for panel, _, top, _, _ in cells}
    assert lefts[("paper", 6, 0.995)] == lefts[("paper", 12, 0.995)] < lefts[("paper", 6, 1.05)]
    assert tops[("paper", 6, 0.995)] == tops[("paper", 6, 1.05)] < tops[("paper", 12, 0.995)]
    assert all(per_node and "per node" in title for _, _, _, per_node, title in cells)
