"""The project's modules import one another without cycles, and the layers one way only.

Every import counts, at module level or inside a function (a lazy import is still a
dependency); for cycles, except those under ``if TYPE_CHECKING:``. A package's ``__init__``
counts as a module of its own. An old module path (``compare.spec``, kept importable for
users: ``compare/_moved.py``) counts as the module it names now.

The layers: ``codesign`` imports neither ``baselines`` nor ``compare``; ``baselines`` does
not import ``compare``; in ``compare``, the run side (``compare.run``) imports nothing of
the harness outside itself, the report side (``compare.report``) only itself and the run
side, and only the top (``compare.cli``, ``compare/__init__.py``) uses both.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import networkx as nx

from compare._moved import new_path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("codesign", "baselines", "compare")


def _modules() -> dict[str, Path]:
    found = {}
    for package in PACKAGES:
        for path in (ROOT / package).rglob("*.py"):
            parts = path.relative_to(ROOT).with_suffix("").parts
            name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            found[name] = path
    return found


def _type_checking_nodes(tree: ast.AST) -> set[int]:
    skipped = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            skipped.update(id(child) for stmt in node.body for child in ast.walk(stmt))
    return skipped


def _current(target: str) -> str:
    """The module an old path (``compare.spec``) names now (``compare.run.spec``); others unchanged."""
    return new_path(target) or target


#: A string that is a module path of the harness (``"compare.run.families.paper"``, to import by name).
_MODULE_PATH = re.compile(r"compare(\.\w+)+")


def _targets(name: str, path: Path, modules: dict, *, type_checking: bool = False) -> set[str]:
    """Every module ``name`` imports (old paths as the modules they name now), and, with
    ``type_checking``, also those under ``if TYPE_CHECKING:`` and the module paths it names
    as strings (imported by name, e.g. ``import_module(table[name])``)."""
    tree = ast.parse(path.read_text())
    skipped = set() if type_checking else _type_checking_nodes(tree)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out = set()
    for node in ast.walk(tree):
        if id(node) in skipped:
            continue
        if isinstance(node, ast.Import):
            out.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            submodules = {_current(f"{target}.{alias.name}") for alias in node.names} & set(modules)
            # `from . import fused` imports the submodule; `from .x import name` imports x.
            out.update(submodules if submodules and not node.module else {target} | submodules)
        elif (type_checking and isinstance(node, ast.Constant) and isinstance(node.value, str)
              and _MODULE_PATH.fullmatch(node.value)):
            out.add(node.value)
    return {_current(m) for m in out}


def _imports(name: str, path: Path, modules: dict) -> set[str]:
    return {m for m in _targets(name, path, modules) if m in modules and m != name}


def import_graph() -> nx.DiGraph:
    modules = _modules()
    graph = nx.DiGraph()
    graph.add_nodes_from(modules)
    for name, path in modules.items():
        graph.add_edges_from((name, target) for target in _imports(name, path, modules))
    return graph


def test_the_graph_is_read():
    graph = import_graph()
    assert graph.has_edge("compare.run.store", "compare.run.records")
    assert graph.has_edge("codesign.learned.grnn_bptt", "codesign.learned.fused")  # a lazy import counts
    assert len(graph) > 50


def test_no_import_cycles():
    cycles = sorted(nx.simple_cycles(import_graph()), key=len)
    assert not cycles, "import cycles: " + "; ".join(" -> ".join(c + c[:1]) for c in cycles[:10])


#: What each part of the project may not import: (importer, imported), each a package or module and
#: everything under it. Only the harness's top (compare/__init__.py, cli, __main__) uses both halves.
FORBIDDEN = [("codesign", "baselines"), ("codesign", "compare"), ("baselines", "compare"),
             ("compare.run", "compare.report"), ("compare.run", "compare.cli"), ("compare.run", "compare.__main__"),
             ("compare.report", "compare.cli"), ("compare.report", "compare.__main__")]
#: The run side imports the harness's top package no more than the report side (its lazy names reach both).
TOP_FORBIDDEN = ("compare.run", "compare.report")
def _under(module: str, layer: str) -> bool:
    return module == layer or module.startswith(layer + ".")


def layer_breaks() -> dict[tuple[str, str], list[str]]:
    """(module, layer it may not import) -> the modules of that layer it imports, at any level, by name too."""
    modules = _modules()
    breaks: dict[tuple[str, str], list[str]] = {}
    for name, path in sorted(modules.items()):
        targets = _targets(name, path, modules, type_checking=True)
        for importer, layer in FORBIDDEN:
            hits = sorted(t for t in targets if _under(name, importer) and _under(t, layer))
            if hits:
                breaks.setdefault((name, layer), []).extend(hits)
        if any(_under(name, side) for side in TOP_FORBIDDEN) and "compare" in targets:
            breaks.setdefault((name, "compare"), []).append("compare")
    return breaks


def test_the_layers_are_read(tmp_path):
    modules = _modules()
    assert "compare.run.store" in modules and "compare.report.write" in modules
    run_store = _targets("compare.run.store", modules["compare.run.store"], modules, type_checking=True)
    assert "compare.run.export" in run_store  # imported inside a method
    sample = tmp_path / "sample.py"
    sample.write_text("from typing import TYPE_CHECKING\n"
                      "if TYPE_CHECKING:\n    from ..report.figures import X\n"
                      "def f():\n    from compare import figures\n    import compare.report_tables\n"
                      "TABLE = {'a': 'compare.report.styles'}\n")
    assert _targets("compare.run.sample", sample, modules, type_checking=True) >= {
        "compare.report.figures", "compare.report.tables", "compare.report.styles"}
    lazy = tmp_path / "lazy.py"
    lazy.write_text("def start(instance):\n    from baselines import decentralized\n    return decentralized(instance)\n")
    assert "baselines" in _targets("codesign.learned.lazy", lazy, modules, type_checking=True)  # inside a function


def test_the_trainer_takes_its_warm_starts_from_the_caller():
    """codesign's warm starts reach the method layer's designs only through what the caller passes."""
    modules = _modules()
    for name in ("codesign.learned.warm", "codesign.learned.grnn"):
        assert not any(_under(t, "baselines") for t in _targets(name, modules[name], modules, type_checking=True))


def test_imports_go_one_way_between_layers():
    breaks = layer_breaks()
    assert not breaks, "imports against the layers:\n" + "\n".join(
        f"{module} imports {', '.join(hits)} (no {layer} here)" for (module, layer), hits in sorted(breaks.items()))


def test_the_project_imports_no_old_module_path():
    """The old paths (compare.spec, ...) are for users' code; the project's own imports name the new ones."""
    files = {**_modules(), **{str(p.relative_to(ROOT)): p for folder in ("tests", "benchmarks", "examples")
                             for p in (ROOT / folder).rglob("*.py")}}
    old = []
    for name, path in sorted(files.items()):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                found = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and not node.level and node.module:
                found = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
            else:
                continue
            old += [f"{name}:{node.lineno}: {m}" for m in found if new_path(m)]
    assert not old, "old module paths imported:\n" + "\n".join(old)


def test_old_module_paths_and_public_names_still_import():
    """Users' code keeps working: ``from compare import X`` for every public name, the report's names
    from ``compare.report``, and each old module path as the moved module itself (a fresh interpreter,
    so that this test's imports leave the others' alone)."""
    probe = """
import importlib, subprocess, sys
import compare
from compare._moved import MOVED, new_path
for name in compare.__all__:
    assert getattr(compare, name) is getattr(importlib.import_module("compare." + compare._EXPORTS[name]), name), name
import compare.report, compare.report.write
assert compare.report.__all__ == compare.report.write.__all__
for name in compare.report.__all__:
    assert getattr(compare.report, name) is getattr(compare.report.write, name), name
for old, new in sorted(MOVED.items()):
    assert importlib.import_module("compare." + old) is importlib.import_module("compare." + new), old
assert importlib.import_module("compare.families.paper") is importlib.import_module("compare.run.families.paper")
assert sys.modules["compare.run.families.paper"].__name__ == "compare.run.families.paper"
copies = [m for m, v in sys.modules.items() if m.startswith("compare") and v.__name__ != m
          and not (new_path(m) and v.__name__ == new_path(m))]
assert not copies, f"old paths that are not their new module: {copies}"
assert len({v.__name__ for m, v in sys.modules.items() if m.startswith("compare")}) == len(
    [m for m, v in sys.modules.items() if m.startswith("compare") and v.__name__ == m]), "a module loaded twice"
"""
    import subprocess
    import sys

    result = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, cwd=ROOT)
    assert result.returncode == 0, result.stderr
    # python -m with an old path, as the shipped power cases record their generator
    result = subprocess.run([sys.executable, "-m", "compare.families.power_cases.generate", "--help"],
                            capture_output=True, text=True, cwd=ROOT)
    assert result.returncode == 0 and "power_grid" in result.stdout, result.stderr
