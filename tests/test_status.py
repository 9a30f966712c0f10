"""Design statuses are defined once (codesign/status.py) and named, never spelled, elsewhere.

A status word typed as a string literal is a second definition of it: a typo
compares false silently, and a new status or group has to be found by grep.
So the code (not its docstrings and comments) names the constants and groups.
"""

from __future__ import annotations

import ast
import io
import math
import tokenize
from pathlib import Path

import pytest

from codesign import status as status_module
from codesign.design import Design
from codesign.status import (
    DIVERGED,
    FAILED,
    INACCURATE,
    INFEASIBLE,
    NO_DESIGN,
    OPTIMAL,
    SOLVER_STATUS,
    STATUSES,
    USABLE,
    solver_status,
    vet_solver_cost,
)

ROOT = Path(__file__).resolve().parents[1]
STATUS_WORDS = {"optimal", "inaccurate", "infeasible", "diverged", "failed"}
#: The only file allowed to spell them.
DEFINING_FILE = ROOT / "codesign" / "status.py"
#: The folders held to that.
CHECKED_FOLDERS = ["codesign", "baselines", "compare", "benchmarks"]

_SKIPPED = {tokenize.NL, tokenize.COMMENT, tokenize.INDENT, tokenize.DEDENT, tokenize.ENCODING,
            tokenize.ENDMARKER}


def _logical_lines(source: str):
    """The tokens of each logical line (statement), without layout tokens."""
    line = []
    for token in tokenize.generate_tokens(io.StringIO(source).readline):
        if token.type == tokenize.NEWLINE:
            yield line
            line = []
        elif token.type not in _SKIPPED:
            line.append(token)
    if line:
        yield line


def status_literals(source: str) -> list[tuple[int, str]]:
    """(line, token) of every string literal in ``source`` equal to a status word, docstrings excepted.

    A docstring is a statement made of string tokens only; any other string
    token (an argument, a comparison, a dict key) counts.
    """
    found = []
    for line in _logical_lines(source):
        if all(token.type == tokenize.STRING for token in line):
            continue
        for token in line:
            if token.type != tokenize.STRING:
                continue
            try:
                value = ast.literal_eval(token.string)
            except (ValueError, SyntaxError):  # an f-string: not a plain status word
                continue
            if value in STATUS_WORDS:
                found.append((token.start[0], token.string))
    return found


def test_the_scanner_finds_literals_and_skips_docstrings():
    source = ('"""optimal"""\n'
              'def f(d):\n'
              '    "failed"\n'
              '    return d.status in ("optimal", \'inaccurate\') or d == f"failed"  # "diverged"\n'
              'x = {"infeasible": 1}\n')
    assert status_literals(source) == [(4, '"optimal"'), (4, "'inaccurate'"), (5, '"infeasible"')]


@pytest.mark.parametrize("folder", CHECKED_FOLDERS)
def test_no_status_literal_outside_the_status_module(folder):
    offenders = [f"{path.relative_to(ROOT)}:{line}: {text}"
                 for path in sorted((ROOT / folder).rglob("*.py")) if path != DEFINING_FILE
                 for line, text in status_literals(path.read_text(encoding="utf-8"))]
    assert not offenders, "status words spelled outside codesign/status.py:\n" + "\n".join(offenders)


def test_statuses_are_the_five_words_in_order():
    assert STATUSES == (OPTIMAL, INACCURATE, INFEASIBLE, DIVERGED, FAILED)
    assert STATUSES == ("optimal", "inaccurate", "infeasible", "diverged", "failed")


def test_groups_partition_the_statuses():
    assert set(USABLE).isdisjoint(NO_DESIGN)
    assert sorted(USABLE + NO_DESIGN, key=STATUSES.index) == list(STATUSES)
    assert USABLE == (OPTIMAL, INACCURATE)


def test_design_module_re_exports_the_status_policy():
    import codesign
    import codesign.design as design_module

    for name in ("STATUSES", "SOLVER_STATUS", "INACCURATE_RTOL", "solver_status", "vet_solver_cost"):
        assert getattr(design_module, name) is getattr(status_module, name) is getattr(codesign, name)
        assert name in design_module.__all__ and name in codesign.__all__


def test_solver_status_maps_cvxpy_words_as_before():
    cvxpy = pytest.importorskip("cvxpy")
    assert SOLVER_STATUS == {cvxpy.OPTIMAL: OPTIMAL, cvxpy.OPTIMAL_INACCURATE: INACCURATE,
                             cvxpy.INFEASIBLE: INFEASIBLE, cvxpy.INFEASIBLE_INACCURATE: INFEASIBLE}
    unknown = [cvxpy.UNBOUNDED, cvxpy.UNBOUNDED_INACCURATE, "infeasible_or_unbounded", cvxpy.USER_LIMIT,
               cvxpy.SOLVER_ERROR, None, "OPTIMAL", "screened"]
    assert [solver_status(raw) for raw in unknown] == ["failed"] * len(unknown)
    assert [solver_status(raw) for raw in ("optimal", "optimal_inaccurate", "infeasible", "infeasible_inaccurate")] \
        == ["optimal", "inaccurate", "infeasible", "infeasible"]


def test_vet_solver_cost_as_before():
    assert vet_solver_cost("optimal", 1.5, 1.5) == ("optimal", "")
    assert vet_solver_cost("inaccurate", 1.5 * (1 + 5e-4), 1.5) == ("inaccurate", "")
    status, why = vet_solver_cost("inaccurate", 1.5 * (1 + 2e-3), 1.5)
    assert status == "failed" and "relative gap 2.00e-03 > 0.001" in why
    assert vet_solver_cost("optimal", float("nan"), 1.5) == ("failed", "the solver's objective is nan")
    for status in NO_DESIGN:  # nothing to vet: returned as they are
        assert vet_solver_cost(status, 1.0, float("nan")) == (status, "")


def test_design_ok_means_usable_with_a_finite_cost():
    def design(status, cost=1.2):
        return Design(method="m", params={}, controller=None, cost=cost, links=0, self_loops=0,
                      info_model="none", status=status)

    assert design(OPTIMAL).ok and design(INACCURATE).ok
    for status in NO_DESIGN:
        failed = Design.failure("m", {}, status, "why")
        assert not failed.ok and math.isnan(failed.cost)
        assert not design(status).ok  # a cost given to a failed design is dropped, not counted
