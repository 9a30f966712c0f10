"""Method labels as the answer names them: without their trailing training settings where that stays unambiguous.

Shared by :mod:`compare.report.answer` and :mod:`compare.report.ladder`, which name the same methods; and
the one way the report's sentences list things (:func:`join_words`) and count their words (:func:`words`).
"""

from __future__ import annotations

import re

__all__ = ["SETTINGS_SUFFIX", "MAX_WORDS", "join_words", "short_names", "words"]

#: At most this many words in a sentence of the report's answer (:func:`words`).
MAX_WORDS = 40

#: A trailing parenthesis that names training settings, not the design: "(β path, 150 steps, 3 hops)".
SETTINGS_SUFFIX = re.compile(r" \((β path|γ path|\d+ steps)[^()]*\)$")


def short_names(labels) -> dict[str, str]:
    """Label -> its name without a trailing parenthesis of training settings ("GRNN-Sparse (β path)" ->
    "GRNN-Sparse"), where that leaves no two labels of the report one name."""
    labels = sorted(set(labels))
    short = {x: SETTINGS_SUFFIX.sub("", x) for x in labels}
    taken: dict[str, int] = {}
    for x in short.values():
        taken[x] = taken.get(x, 0) + 1
    return {x: s if s == x or (taken[s] == 1 and s not in labels) else x for x, s in short.items()}


def join_words(parts) -> str:
    """"a", "a and b", "a, b and c": a list as the report's sentences write it."""
    parts = list(parts)
    return parts[0] if len(parts) == 1 else ", ".join(parts[:-1]) + " and " + parts[-1]


def words(text: str) -> int:
    """Words as the limits count them: whitespace-separated tokens with a letter or a digit."""
    return sum(1 for w in text.split() if any(ch.isalnum() for ch in w))
