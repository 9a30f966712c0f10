"""No module of the project imports another's private name (``from x import _name``).

A name with a leading underscore is its module's own business: it may change or go
without notice, so a module that needs another's helper imports it under a public
name. Importing a public name from a private module (``from ._sparse import DecentralizedCache``)
is fine; only the imported name counts. Dunder names and ``from __future__`` are not
private. Read with :mod:`ast`, so strings and comments never count.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
#: The folders scanned, and the top-level packages whose names are the project's.
FOLDERS = ("codesign", "baselines", "compare", "benchmarks")
PACKAGES = ("codesign", "baselines", "compare")


def _private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def _project_module(node: ast.ImportFrom) -> bool:
    """Whether ``node`` imports from one of the project's modules (any relative import is)."""
    return bool(node.level) or (node.module or "").split(".")[0] in PACKAGES


def private_imports(path: Path, root: Path = ROOT) -> list[str]:
    """``file:line: name (from module)`` for each private name ``path`` imports from a project module.

    ``file`` is ``path`` relative to ``root``.
    """
    tree = ast.parse(path.read_text(), filename=str(path))
    found = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.ImportFrom) or not _project_module(node):
            continue
        module = "." * node.level + (node.module or "")
        found += [f"{path.relative_to(root)}:{node.lineno}: {alias.name} (from {module})"
                  for alias in node.names if _private(alias.name)]
    return found


def _sources() -> list[Path]:
    return sorted(path for folder in FOLDERS for path in (ROOT / folder).rglob("*.py"))


def test_the_scan_finds_private_imports(tmp_path):
    sample = tmp_path / "sample.py"
    sample.write_text("from __future__ import annotations\n"
                      "from .spec import _check_keys, parse_spec\n"
                      "from compare.report.figures import __all__, _y_limits as limits\n"
                      "from numpy import _private_of_others\n"
                      "def f():\n"
                      "    from ..execution import _limit_threads\n"
                      "text = 'from compare.run.spec import _typed'\n")
    assert private_imports(sample, tmp_path) == ["sample.py:2: _check_keys (from .spec)",
                                                 "sample.py:3: _y_limits (from compare.report.figures)",
                                                 "sample.py:6: _limit_threads (from ..execution)"]


def test_the_scan_reads_the_packages():
    sources = _sources()
    assert len(sources) > 50
    assert ROOT / "compare" / "run" / "spec.py" in sources


def test_no_module_imports_a_private_name():
    found = [hit for path in _sources() for hit in private_imports(path)]
    assert not found, "private names imported across modules (import a public name instead):\n" + "\n".join(found)
