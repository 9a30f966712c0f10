"""How large a report figure's text is where the page shows it, read from the figure's own files.

A report saves every figure twice (``compare.report.write``): a PNG at 130 dpi and an SVG
whose text is drawn as glyph paths (``svg.fonttype = "path"``). Matplotlib writes each text
as ``<g transform="translate(x y) scale(s -s)">`` over glyphs defined at 100 units to the
point, so ``100 s`` is its size in points, and a glyph inside it drawn at ``scale(k)`` (the
exponent of ``10^k``) is ``k`` times that. The SVG's width is in points and the PNG's in
pixels, both of the same tight bounding box: a text's height in the PNG is
``points * png_width / svg_width`` px, and on a page that shows the PNG ``w`` px wide it is
that times ``w / png_width``. Nothing here asks the code that drew the figure.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from PIL import Image

#: The report's column at an 800 px window, and the smallest text wanted there (issue 61).
PAGE_PX, SCREEN_PX = 768, 9.0
#: No PNG a report shows is wider than this.
MAX_PNG_PX = 1700

_BLOCK = re.compile(r'(?:<!-- (?P<text>.*?) -->\s*)?<g\b[^>]*?\btransform="[^"]*?scale\((?P<s>[0-9.]+) -[0-9.]+\)"'
                    r"[^>]*>(?P<body>.*?)</g>", re.S)
_INNER = re.compile(r'<use [^>]*?transform="[^"]*?scale\((?P<k>[0-9.]+)\)"')
_WIDTH = re.compile(r'<svg[^>]*?\bwidth="(?P<w>[0-9.]+)pt"')


@dataclass(frozen=True)
class Legibility:
    """A figure's width in px, its smallest text in points and in px as saved, and that text."""

    png: Path
    width: int
    points: float
    px: float
    text: str

    def on_screen(self, shown_px: float) -> float:
        """The smallest text's height in px where the page shows the PNG ``shown_px`` wide."""
        return self.px * shown_px / self.width

    @property
    def at_800(self) -> float:
        """Its height at an 800 px window, where the PNG is shown at most :data:`PAGE_PX` wide."""
        return self.on_screen(min(self.width, PAGE_PX))


def svg_text_sizes(svg: str) -> tuple[float, list[tuple[float, str]]]:
    """(the SVG's width in points, [(points, text), ...] of every text it draws)."""
    width = float(_WIDTH.search(svg).group("w"))
    sizes = []
    for block in _BLOCK.finditer(svg):
        inner = [float(k) for k in _INNER.findall(block.group("body"))] or [1.0]
        sizes.append((100.0 * float(block.group("s")) * min(1.0, *inner), block.group("text") or ""))
    return width, sizes


def legibility(png: Path) -> Legibility | None:
    """The smallest text of the figure saved as ``png`` (its SVG beside it); None where it draws no text."""
    png = Path(png)
    width_pt, sizes = svg_text_sizes(png.with_suffix(".svg").read_text(encoding="utf-8"))
    sizes = [(pt, text) for pt, text in sizes if text.strip()]
    if not sizes:
        return None
    points, text = min(sizes)
    width = Image.open(png).size[0]
    return Legibility(png, width, points, points * width / width_pt, text)


def shown_figures(folder: Path) -> list[Path]:
    """The PNGs a report's Markdown shows (``![...](name.png)``), in order."""
    text = (Path(folder) / "report.md").read_text(encoding="utf-8")
    names = dict.fromkeys(re.findall(r"!\[[^\]]*\]\(([^)\s]+\.png)\)", text))
    return [Path(folder) / name for name in names]
