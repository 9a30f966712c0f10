"""The report's HTML page: the Markdown report with a table of contents and interactive figures.

The page is one file beside its figures: PNGs are inlined, each a link to its
full-size file, and the interactive figures (:mod:`compare.report.interactive`) load
``plotly.min.js`` from the same folder (:func:`write_plotly_js`), so the page opens
from disk without a network. It reads at any width from about 800 px: the
interactive figures' panels reflow into one column below 900 px, their legends are
HTML above the panels, and nothing scrolls the page sideways (wide tables and code
scroll in their own boxes).
"""

from __future__ import annotations

import base64
import html
import re
from collections.abc import Mapping
from pathlib import Path

import markdown
from markdown.extensions.toc import slugify_unicode

__all__ = ["render_html", "write_plotly_js", "PLOTLY_JS", "COLLAPSE_ROWS"]

#: The file name of plotly.js beside the page.
PLOTLY_JS = "plotly.min.js"
#: Tables with more rows than this start collapsed.
COLLAPSE_ROWS = 12

_CSS = """
body { font-family: system-ui, -apple-system, "Segoe UI", sans-serif; max-width: 1200px; margin: 2em auto;
       padding: 0 1em; color: #222; line-height: 1.45; overflow-wrap: break-word; }
p code, li code { overflow-wrap: anywhere; }
h1 { font-size: 1.7em; border-bottom: 2px solid #ddd; padding-bottom: 0.2em; }
h2 { font-size: 1.35em; margin-top: 2em; border-bottom: 1px solid #e3e3e3; padding-bottom: 0.15em; }
h3 { font-size: 1.1em; margin-top: 1.5em; }
a { color: #0b5cad; }
nav.toc { background: #f7f7f9; border: 1px solid #e3e3e8; border-radius: 6px; padding: 0.6em 1.2em;
          margin: 1em 0 2em; font-size: 0.93em; }
nav.toc ul { margin: 0.2em 0; padding-left: 1.3em; }
nav.toc > div > ul { columns: 2 22em; }
nav.toc li { break-inside: avoid; }
.table-wrap { overflow-x: auto; max-width: 100%; margin: 0.5em 0 1.5em; }
table { border-collapse: collapse; font-size: 0.9em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: left; }
th { background: #f3f3f3; position: sticky; top: 0; }
td { font-variant-numeric: tabular-nums; }
td:first-child { min-width: 9em; }
tbody tr:nth-child(even) { background: #fafafa; }
details { margin: 0.5em 0 1.5em; }
details > summary { cursor: pointer; color: #0b5cad; font-size: 0.93em; }
details > .table-wrap { margin-top: 0.5em; }
img { max-width: 100%; height: auto; }
a.full-size { display: inline-block; max-width: 100%; }
figure.interactive { margin: 1em 0 2em; min-width: 0; }
figure.interactive figcaption { font-size: 0.85em; color: #666; text-align: right; }
pre { background: #f6f6f6; padding: 0.8em; overflow-x: auto; }
code { font-size: 0.92em; }
"""


def write_plotly_js(folder: Path) -> Path:
    """Write the installed plotly's JavaScript as ``plotly.min.js`` in ``folder``.

    The same bytes in every report folder (git stores them once); the file is left
    untouched when it already holds them.
    """
    from plotly.offline import get_plotlyjs

    path = Path(folder) / PLOTLY_JS
    data = get_plotlyjs().encode()
    if not path.is_file() or path.read_bytes() != data:
        path.write_bytes(data)
    return path


def _figure_name(src: str, interactive: Mapping[str, str]) -> str | None:
    """The key of ``interactive`` for an image's ``src``: its file name, or the name without suffix."""
    for key in (src, Path(src).name, Path(src).stem):
        if key in interactive:
            return key
    return None


def _swap_figures(body: str, folder: Path, interactive: Mapping[str, str]) -> tuple[str, int]:
    """Put each interactive figure in the place of its ``<img>``; returns (body, figures put)."""
    count = 0

    def swap(match):
        nonlocal count
        src = html.unescape(match.group("src"))
        key = _figure_name(src, interactive)
        if key is None:
            return match.group(0)
        count += 1
        stem = Path(src).with_suffix("")
        links = [f'<a href="{html.escape(src)}">{html.escape(Path(src).name)}</a>']
        if (folder / f"{stem}.svg").is_file():
            links.append(f'<a href="{html.escape(str(stem))}.svg">{html.escape(stem.name)}.svg</a>')
        return (f'<figure class="interactive">\n{interactive[key]}\n'
                f'<figcaption>static figure: {" / ".join(links)}</figcaption>\n</figure>')

    # An image alone in its paragraph takes the paragraph with it (a <div> cannot sit in a <p>).
    pattern = r'(?:<p>\s*)?<img\b[^>]*?\bsrc="(?P<src>[^"]+)"[^>]*>(?:\s*</p>)?'
    return re.sub(pattern, swap, body), count


def _link_images(body: str) -> str:
    """Every image that is not already a link opens its full-size file: an ``<img>`` in an ``<a href>`` to its src.

    The page shows figures at the column's width (a wide figure shrinks); the link opens the file itself.
    """
    out, last = [], 0
    for match in re.finditer(r'<img\b[^>]*?\bsrc="(?P<src>[^"]+)"[^>]*>', body):
        before = body[:match.start()]
        if before.rfind("<a ") > before.rfind("</a>") or match.group("src").startswith("data:"):
            continue  # inside a link already, or not a file
        out += [body[last:match.start()], f'<a class="full-size" href="{match.group("src")}">{match.group(0)}</a>']
        last = match.end()
    return "".join(out) + body[last:]


def _inline_pngs(body: str, folder: Path) -> str:
    def inline(match):
        path = folder / html.unescape(match.group(1))
        if not path.is_file() or path.suffix.lower() != ".png":
            return match.group(0)
        return f'src="data:image/png;base64,{base64.b64encode(path.read_bytes()).decode()}"'

    return re.sub(r'src="([^":]+)"', inline, body)


def _wrap_tables(body: str) -> str:
    """Every table in a horizontally scrolling box; one longer than :data:`COLLAPSE_ROWS` rows also collapsed.

    A table the Markdown marks ``<!-- table: open -->`` stays open however long (the findings table); one
    marked ``<!-- table: folded: SUMMARY -->`` is always folded, under "SUMMARY (N rows)" (its per-panel detail).
    """
    def wrap(match):
        mode, summary, table = match.group("mode"), match.group("summary"), match.group("table")
        tbody = re.search(r"<tbody>(.*?)</tbody>", table, flags=re.S)
        rows = len(re.findall(r"<tr\b", tbody.group(1) if tbody else table))
        boxed = f'<div class="table-wrap">\n{table}\n</div>'
        if mode == "folded":
            return (f"<details>\n<summary>{html.escape(summary or 'table')} ({rows} rows): click to expand</summary>"
                    f"\n{boxed}\n</details>")
        if rows <= COLLAPSE_ROWS or mode == "open":
            return boxed
        return f"<details>\n<summary>table ({rows} rows): click to expand</summary>\n{boxed}\n</details>"

    marker = r"(?:<!-- table: (?P<mode>open|folded)(?:: (?P<summary>[^<>]*?))? -->\s*)?"
    return re.sub(marker + r"(?P<table><table>.*?</table>)", wrap, body, flags=re.S)


def _check_ids(body: str) -> None:
    """Refuse a figure whose div id is a heading's anchor too: the table of contents would jump to the wrong one."""
    ids = re.findall(r'<(?:h[1-6]|div)\b[^>]*?\bid="([^"]+)"', body)
    twice = sorted({i for i in ids if ids.count(i) > 1})
    if twice:
        raise ValueError(f"ids used twice on the page (a figure div named like a heading?): {twice}")


def _with_toc(body: str, toc: str) -> str:
    """The table of contents before the page's first h2: after the title and the answer that opens a report."""
    nav = f'<nav class="toc"><strong>Contents</strong>\n{toc}</nav>'
    first = re.search(r"<h2[ >]", body)
    if first:
        return body[:first.start()] + nav + "\n" + body[first.start():]
    head = re.search(r"</h1>", body)
    return body[:head.end()] + "\n" + nav + body[head.end():] if head else nav + "\n" + body


def render_html(markdown_text: str, folder: Path, title: str, interactive: dict[str, str] | None = None) -> str:
    """The HTML page of a Markdown report in ``folder``.

    Parameters
    ----------
    markdown_text : str
        The report (tables and fenced code allowed); its images are files in ``folder``.
    folder : Path
        The report's folder: PNGs named by the Markdown are inlined from it.
    title : str
        The page's ``<title>``.
    interactive : dict, optional
        Image file name (``"cost_vs_links.png"``, or its stem) -> the HTML of an
        interactive figure (:func:`compare.report.interactive.figure_div`), shown in the
        image's place with links to the static PNG/SVG under it.

    Returns
    -------
    str
        The page: a table of contents of the h2/h3 headings, long tables collapsed,
        every other image a link to its file, and, if any interactive figure was put
        in, a ``<script>`` that loads ``plotly.min.js`` from the page's folder (write it
        with :func:`write_plotly_js`) and the figures' script and style
        (:data:`compare.report.interactive.FIGURE_JS`, :data:`~compare.report.interactive.FIGURE_CSS`).
    """
    folder = Path(folder)
    md = markdown.Markdown(extensions=["tables", "fenced_code", "toc"],
                           extension_configs={"toc": {"toc_depth": "2-3", "slugify": slugify_unicode}})
    body = md.convert(markdown_text)
    figures = 0
    if interactive:
        body, figures = _swap_figures(body, folder, interactive)
    _check_ids(body)
    body = _wrap_tables(_inline_pngs(_link_images(body), folder))
    if "<li" in md.toc:  # any h2/h3 heading
        body = _with_toc(body, md.toc)
    css, script = _CSS, ""
    if figures:
        from .interactive import FIGURE_CSS, FIGURE_JS

        css += FIGURE_CSS
        script = f'<script src="{PLOTLY_JS}" charset="utf-8"></script>\n<script>{FIGURE_JS}</script>\n'
    return (f"<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
            f"<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n"
            f"<title>{html.escape(title)}</title>\n<style>{css}</style>\n{script}</head>\n"
            f"<body>\n{body}\n</body>\n</html>\n")
