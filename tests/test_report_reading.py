"""Every shipped report reads in a minute: a short opening, findings as a table, bullets only for what a table cannot say.

Measured on each shipped ``reports/*/report.md`` (issue 61):

- the opening (between the title and the first section) answers in at most three sentences of at most
  40 words each, and holds at most 150 words with anything that follows them there (the budget
  ladder's caption); every measured number in it (a decimal, a percentage, a multiple of LQR) is one the
  rest of the page gives, to the precision the opening states it; its sentences that state a difference
  in units of LQR's cost come largest first;
- the Findings hold a table, no bullet over 60 words, and at most 500 words of prose (everything but
  the tables, the images and the markers the HTML page reads);
- no text a user reads tells the report's author what to do, and no number prints as a signed zero.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from compare.report.answer import MAX_SENTENCES, MAX_WORDS, words

REPORTS = Path(__file__).resolve().parents[1] / "reports"
SHIPPED = sorted(p.name for p in REPORTS.iterdir() if (p / "report.md").exists())

OPENING_WORDS = 150
FINDINGS_WORDS = 500
BULLET_WORDS = 60


def _sections(text: str) -> dict[str, list[str]]:
    """"" (the opening, after the title) and each "## " heading -> its lines."""
    out: dict[str, list[str]] = {"": []}
    key = ""
    for line in text.splitlines()[1:]:
        if line.startswith("## "):
            key = line[3:].strip()
            out[key] = []
        else:
            out[key].append(line)
    return out


def _prose(lines: list[str]) -> list[str]:
    """The lines a reader reads as text: no table rows, images, HTML markers or blank lines."""
    return [x for x in lines if x.strip() and not x.startswith(("|", "![", "<!--"))]


def _opening_sentences(lines: list[str]) -> list[str]:
    """The opening's first paragraph, one sentence per line."""
    out = []
    for line in lines:
        if not line.strip():
            if out:
                break
            continue
        out.append(line)
    return out


@pytest.fixture(scope="module", params=SHIPPED)
def report(request):
    return request.param, (REPORTS / request.param / "report.md").read_text(encoding="utf-8")


def test_the_opening_answers_in_three_short_sentences(report):
    name, text = report
    opening = _sections(text)[""]
    sentences = _opening_sentences(opening)
    assert sentences, f"{name}: no opening"
    assert len(sentences) <= MAX_SENTENCES, f"{name}: {len(sentences)} sentences"
    for s in sentences:
        # one sentence a line: no full stop followed by a new sentence inside it
        assert not re.search(r"[.!?] [A-Z]", s.replace("et al. ", "et al ")), f"{name}: two sentences in one: {s}"
        assert words(s) <= MAX_WORDS, f"{name}: {words(s)} words: {s}"
    total = sum(words(x) for x in _prose(opening))
    assert total <= OPENING_WORDS, f"{name}: the opening has {total} words"


#: A measured number: a decimal, a percentage or a multiple of LQR ("+0.0127", "+16 %", "2,877 × LQR").
_MEASURED = re.compile(r"[+−-]?\d[\d,]*(?:\.\d+)?(?:\s?%|\s?× LQR)|[+−-]?\d[\d,]*\.\d+")
_NUMBER = re.compile(r"[+−-]?\d[\d,]*(?:\.\d+)?")


def _value(text: str) -> tuple[float, int, bool]:
    """(value, decimals, is a percentage) of a measured number as printed."""
    percent = "%" in text
    number = _NUMBER.search(text).group(0).replace("−", "-").replace(",", "")
    decimals = len(number.split(".")[1]) if "." in number else 0
    return float(number), decimals, percent


def _page_values(text: str) -> list[float]:
    return [float(m.group(0).replace("−", "-").replace(",", "")) for m in _NUMBER.finditer(text)]


def test_every_number_in_the_opening_is_on_the_page(report):
    name, text = report
    sections = _sections(text)
    opening = "\n".join(_opening_sentences(sections[""]))
    rest = "\n".join(line for key, lines in sections.items() for line in lines
                     if key and not key.startswith("Spec "))
    # the ladder's table, where there is one, is part of the page below the sentences
    rest += "\n" + "\n".join(x for x in sections[""] if x.startswith("|"))
    values = _page_values(rest)
    missing = []
    for m in _MEASURED.finditer(opening):
        value, decimals, percent = _value(m.group(0))
        # a difference may be stated from the winner's side (its sign turned), so magnitudes are compared
        candidates = {abs(round(v, decimals)) for v in values}
        if percent:  # "+4.7 %" is a cost of 1.047 × LQR in a table of costs
            candidates |= {abs(round(100 * (v - 1), decimals)) for v in values}
        if abs(round(value, decimals)) not in candidates:
            missing.append(m.group(0))
    assert not missing, f"{name}: numbers of the opening found nowhere else on the page: {missing}"


#: The difference a sentence leads with, signed, in units of LQR's cost ("+0.81 × LQR", "+0.069 [+0.048, +0.083] ×
#: LQR"); a cost ("about 2,877 × LQR", rule 1's failures) has no sign and is no difference.
_DIFFERENCE = re.compile(r"[+−-](\d+\.\d+)(?: \[[^\]]*\])? × LQR")


def test_the_opening_states_the_largest_effect_first(report):
    """Issue 61: of the opening's sentences that state a difference × LQR, the one with the largest comes first."""
    name, text = report
    sentences = _opening_sentences(_sections(text)[""])
    sizes = [float(m.group(1)) for s in sentences if (m := _DIFFERENCE.search(s))]
    assert sizes == sorted(sizes, reverse=True), f"{name}: differences stated in the order {sizes}"


def test_findings_are_a_table_with_short_bullets_and_little_prose(report):
    name, text = report
    findings = _sections(text).get("Findings")
    if findings is None:
        pytest.skip(f"{name} has no Findings")
    assert any(x.startswith("| first − second |") for x in findings), f"{name}: no findings table"
    bullets = [x for x in findings if x.startswith("- ")]
    for b in bullets:
        assert words(b) <= BULLET_WORDS, f"{name}: a bullet of {words(b)} words: {b}"
    total = sum(words(x) for x in _prose(findings))
    assert total <= FINDINGS_WORDS, f"{name}: {total} words of findings prose"
    # what no per-panel test can reach is said once, not per bullet
    assert sum("Holm" in b for b in bullets) == 0, f"{name}: a bullet repeats the Holm verdict"


def test_no_instruction_to_the_author_and_no_signed_zero(report):
    name, text = report
    body = text.split("\n## Spec `")[0]
    assert "Add SLS" not in body and "`method = " not in body, f"{name}: tells the author what to do"
    zeros = re.findall(r"[+−-]0\.0+(?![\d])", body)
    assert not zeros, f"{name}: signed zeros {zeros[:3]}"
