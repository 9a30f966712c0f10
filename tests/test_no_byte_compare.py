"""No test compares a float-bearing file generated here with one generated elsewhere, byte for byte.

A file of floats written on one machine (BLAS build, thread count, processor) matches the same
computation on another only to its last digit or two, so a test that compares such files byte for
byte, or by their hashes, passes on the machine that wrote the shipped file and fails on a user's
(issue 60: ``ieee39.json``'s modal frequencies, ``...805751`` against ``...805749``). Such checks
compare structure exactly and floats with a tolerance (``tests/test_power_grid.py``).

Byte comparisons within one process are fine and are not flagged: rebuilding a report twice, writing a
folder again, a store left untouched by a refused command all compare what one build computed with
itself. What is flagged, in every ``tests/*.py``, is an equality (``==``, ``!=``) between

- file content read from the repository (a path built from ``__file__``, or a relative path into one of
  the repository's folders: data shipped, so written on some other machine) and content this test
  produces (anything that is not a literal and not itself read from the repository); or
- file content (text, bytes, a digest) and a literal that pins what only one machine writes: a hex
  digest, or a float written to ten or more significant digits.

File content is what ``read_bytes()`` and ``read_text()`` return, a hash of it (``hashlib``,
``hexdigest()``), what the case generator's ``dumps`` writes, and what a helper of the same file (or of a
non-test module of ``tests/``, such as ``cli_checks.file_sha``) returns from them; ``len()``, ``.count()``
and ``json.loads`` turn it into something else. A flagged site passes only if :data:`ALLOWED` names it
with the reason it holds on any machine.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent
ROOT = TESTS.parent

#: (file, function) -> why its byte comparison with a repository file holds on any machine. Kept small:
#: each entry compares values that no arithmetic touched on this machine.
ALLOWED = {
    ("test_power_grid.py", "test_shipped_case_files_are_consistent"):
        "a format check: the generator's dumps re-prints the shipped file's own parsed values; json reads and "
        "Python's repr writes a float exactly on any IEEE-754 machine, and no arithmetic is done in between",
    ("test_report_identity.py", "test_compare_report_rebuilds_quick_from_the_shipped_folder_alone"):
        "a pass-through: runs.csv, curves.csv and report.json are the shipped values parsed and printed again "
        "(exact, as above); report.md's tables print statistics of them rounded to 3-4 digits, which a "
        "last-bit difference changes only at an exact rounding tie",
}

#: Calls whose result is a file's content.
_READ = {"read_bytes", "read_text"}
#: Calls whose result is a digest or a serialization that stands for a file's bytes.
_DIGEST = {"hexdigest", "digest", "sha1", "sha256", "sha512", "md5", "blake2b", "blake2s", "file_sha"}
#: Calls that turn content into something that is no longer compared byte for byte.
_SANITIZE = {"len", "count", "loads", "load", "startswith", "endswith", "find", "index", "is_file", "exists"}
#: Path methods that give another path of the same tree.
_PATH_METHODS = {"resolve", "absolute", "joinpath", "with_name", "with_suffix", "with_stem"}
_HEX_DIGEST = re.compile(r"^[0-9a-f]{32,}$")
_LONG_FLOAT = re.compile(r"\d\.?\d{9,}")


def _call_name(node: ast.Call) -> str | None:
    func = node.func
    if isinstance(func, ast.Attribute):
        return func.attr
    return func.id if isinstance(func, ast.Name) else None


class _Module:
    """One test module: its repository-path names, its content helpers, and the comparisons to flag."""

    def __init__(self, tree: ast.Module, top_dirs: set, shared_helpers: set):
        self.tree = tree
        self.top_dirs = top_dirs
        self.repo_globals = set()
        for _ in range(5):  # module constants built from each other (ROOT, then DATA = ROOT / ...)
            for node in tree.body:
                if isinstance(node, (ast.Assign, ast.AnnAssign)) and node.value is not None:
                    if self.is_repo_path(node.value, set()):
                        for target in node.targets if isinstance(node, ast.Assign) else [node.target]:
                            self.repo_globals.update(n.id for n in ast.walk(target) if isinstance(n, ast.Name))
        self.helpers = set(shared_helpers)
        self.functions = [fn for fn in ast.walk(tree) if isinstance(fn, ast.FunctionDef)]
        for _ in range(5):  # helpers returning content, and helpers of those
            before = len(self.helpers)
            for fn in self.functions:
                returns = [r.value for r in ast.walk(fn) if isinstance(r, ast.Return) and r.value is not None]
                if fn.name not in self.helpers and returns:
                    names = self.names(fn)
                    if any(self.kind(value, names) for value in returns):
                        self.helpers.add(fn.name)
            if len(self.helpers) == before:
                break

    def is_repo_path(self, node, local_repo: set) -> bool:
        """``node`` builds a path into the repository (``ROOT / "reports"``, ``Path(__file__).parents[1]``)."""
        if isinstance(node, ast.Name):
            return node.id == "__file__" or node.id in self.repo_globals or node.id in local_repo
        if isinstance(node, ast.BinOp):  # path / "name"
            return self.is_repo_path(node.left, local_repo)
        if isinstance(node, (ast.Attribute, ast.Subscript)):  # .parent, .parents[1]
            return self.is_repo_path(node.value, local_repo)
        if isinstance(node, ast.Call):
            func = node.func
            if isinstance(func, ast.Attribute) and func.attr in _PATH_METHODS:
                return self.is_repo_path(func.value, local_repo)
            if _call_name(node) in ("Path", "PurePath", "open") and node.args:
                first = node.args[0]
                if isinstance(first, ast.Constant) and isinstance(first.value, str):
                    return first.value.split("/")[0] in self.top_dirs
                return self.is_repo_path(first, local_repo)
        return False

    def kind(self, node, names) -> set:
        """What content ``node`` carries: a subset of {"content", "repo"} (repo: read from the repository)."""
        local_repo, content = names
        found = set()
        if isinstance(node, ast.Call):
            name = _call_name(node)
            if name in _SANITIZE:
                return found
            # The case generator's dumps (a bare name, not json.dumps) stands for the file it writes.
            generator_dumps = name == "dumps" and isinstance(node.func, ast.Name)
            if name in _READ or name in _DIGEST or name in self.helpers or generator_dumps:
                found.add("content")
                receiver = node.func.value if isinstance(node.func, ast.Attribute) else None
                if any(self.is_repo_path(part, local_repo) for part in [receiver, *node.args] if part is not None):
                    found.add("repo")
        if isinstance(node, ast.Name) and node.id in content:
            found |= content[node.id]
        for child in ast.iter_child_nodes(node):
            found |= self.kind(child, names)
        return found

    def names(self, fn) -> tuple:
        """(names bound to repository paths, name -> content kind) inside ``fn``, by a few passes of its assignments."""
        local_repo, content = set(), {}
        assigns = [node for node in ast.walk(fn) if isinstance(node, ast.Assign)]
        for _ in range(4 if assigns else 0):  # a name bound from names bound later in the walk
            for node in assigns:
                pairs = []
                for target in node.targets:
                    if (isinstance(target, ast.Tuple) and isinstance(node.value, ast.Tuple)
                            and len(target.elts) == len(node.value.elts)):
                        pairs += zip(target.elts, node.value.elts)  # a, b = x, y: each its own
                    else:
                        pairs.append((target, node.value))
                for target, value in pairs:
                    bound = [n.id for n in ast.walk(target) if isinstance(n, ast.Name)]
                    if self.is_repo_path(value, local_repo):
                        local_repo.update(bound)
                    got = self.kind(value, (local_repo, content))
                    for name in bound if got else ():
                        content[name] = content.get(name, set()) | got
        return local_repo, content

    def flagged(self):
        """(function, line) of each comparison the module docstring describes."""
        for fn in self.functions:
            names = self.names(fn)
            for node in ast.walk(fn):
                if not (isinstance(node, ast.Compare) and any(isinstance(o, (ast.Eq, ast.NotEq)) for o in node.ops)):
                    continue
                sides = [node.left, *node.comparators]
                kinds = [self.kind(side, names) for side in sides]
                literals = [_literal(side) for side in sides]
                if any("repo" in k for k in kinds) and any(not lit and "repo" not in k
                                                            for k, lit in zip(kinds, literals)):
                    yield fn.name, node.lineno
                elif any("content" in k for k in kinds) and any(lit and _pins_a_machine(side)
                                                                 for side, lit in zip(sides, literals)):
                    yield fn.name, node.lineno


def _literal(node) -> bool:
    """Built from constants alone (``b"garbage" * 200``, ``"x"``)."""
    return all(isinstance(n, (ast.Constant, ast.BinOp, ast.UnaryOp, ast.Tuple, ast.List, ast.expr_context,
                              ast.operator, ast.unaryop)) for n in ast.walk(node))


def _pins_a_machine(node) -> bool:
    """A literal holding a digest or a float to ten or more digits: what only the machine that wrote it reproduces."""
    for n in ast.walk(node):
        if isinstance(n, ast.Constant) and isinstance(n.value, (str, bytes)):
            text = n.value.decode("latin-1") if isinstance(n.value, bytes) else n.value
            if _HEX_DIGEST.match(text.strip().lower()) or _LONG_FLOAT.search(text):
                return True
    return False


def _top_dirs() -> set:
    return {p.name for p in ROOT.iterdir() if p.is_dir() and not p.name.startswith(".")}


def _shared_helpers(sources: dict) -> set:
    """Content helpers of the non-test modules of tests/ (``cli_checks.file_sha``), which tests import."""
    helpers = set()
    for path, tree in sources.items():
        if not path.name.startswith("test_"):
            helpers |= _Module(tree, _top_dirs(), set()).helpers
    return helpers


def scan(sources: dict) -> list:
    """[(file name, function, line)] of the flagged comparisons in ``{path: parsed module}``."""
    shared = _shared_helpers(sources)
    top = _top_dirs()
    return sorted({(path.name, fn, line) for path, tree in sources.items()
                   for fn, line in _Module(tree, top, shared).flagged()})


def _parse(path: Path) -> ast.Module:
    return ast.parse(path.read_text(encoding="utf-8"), str(path))


def _scan_snippet(code: str) -> list:
    return [(fn, line) for _, fn, line in scan({TESTS / "test_snippet.py": ast.parse(code)})]


def test_no_test_compares_a_generated_float_file_with_one_from_another_machine_byte_for_byte():
    sites = scan({path: _parse(path) for path in sorted(TESTS.glob("*.py"))})
    unexplained = [site for site in sites if site[:2] not in ALLOWED]
    assert not unexplained, (
        "byte-for-byte comparison of a file from the repository (written on another machine) with one written "
        f"here: {unexplained}; compare structure exactly and floats with a tolerance (tests/test_power_grid.py's "
        "assert_same_case_data), or add the site to ALLOWED with why it holds on any machine")
    # An allowance whose comparison is gone would let a new one in under its name.
    stale = set(ALLOWED) - {site[:2] for site in sites}
    assert not stale, f"ALLOWED names sites that no longer compare bytes: {sorted(stale)}"


@pytest.mark.parametrize("code", [
    # The check issue 60 found failing on a user's machine.
    "DATA = Path(__file__).parent / 'data'\n"
    "def test_x(tmp_path):\n"
    "    shipped, fresh = (DATA / 'a.json').read_text(), (tmp_path / 'a.json').read_text()\n"
    "    assert fresh == shipped\n",
    "REPORTS = Path(__file__).resolve().parents[1] / 'reports'\n"
    "def test_x(tmp_path):\n"
    "    assert (tmp_path / 'runs.csv').read_bytes() == (REPORTS / 'quick' / 'runs.csv').read_bytes()\n",
    "def test_x(tmp_path):\n"
    "    text = Path('compare/run/families/power_cases/ieee39.json').read_text()\n"
    "    assert generate(tmp_path).read_text() != text\n",
    # A digest, or a full-precision float, pinned in the source.
    "import hashlib\n"
    "def test_x(tmp_path):\n"
    "    digest = hashlib.sha256((tmp_path / 'runs.csv').read_bytes()).hexdigest()\n"
    "    assert digest == '" + "0123456789abcdef" * 4 + "'\n",
    "def test_x(tmp_path):\n"
    "    assert (tmp_path / 'modes.txt').read_text() == '0.9050605901741317\\n'\n",
    # Through a helper that reads the file.
    "ROOT = Path(__file__).parents[1]\n"
    "def _body(path):\n"
    "    return path.read_text().splitlines()\n"
    "def test_x(tmp_path):\n"
    "    assert _body(tmp_path / 'report.md') == _body(ROOT / 'reports' / 'report.md')\n",
])
def test_the_scan_finds_byte_comparisons_across_machines(code):
    assert [fn for fn, _ in _scan_snippet(code)] == ["test_x"]


@pytest.mark.parametrize("code", [
    # Within one process: a rebuild compared with the first build, a store left untouched.
    "def test_x(tmp_path):\n"
    "    a, b = build(tmp_path / 'a'), build(tmp_path / 'b')\n"
    "    assert a.read_bytes() == b.read_bytes()\n",
    "def test_x(tmp_path):\n"
    "    before = file_sha(tmp_path / 'store.sqlite')\n"
    "    run()\n"
    "    assert file_sha(tmp_path / 'store.sqlite') == before\n",
    # Literals with no digest or long float; counts and parsed values.
    "def test_x(tmp_path):\n"
    "    assert (tmp_path / 'x').read_bytes() == b'garbage' * 200\n",
    "DATA = Path(__file__).parent\n"
    "def test_x(tmp_path):\n"
    "    assert len((DATA / 'a.csv').read_text()) == len((tmp_path / 'a.csv').read_text())\n"
    "    assert json.loads((DATA / 'a.json').read_text())['n'] == 3\n",
])
def test_the_scan_leaves_same_process_and_literal_checks_alone(code):
    assert _scan_snippet(code) == []
