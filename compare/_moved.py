"""The module paths from before compare/ was split into compare.run and compare.report.

Users' notebooks and plug-ins import ``compare.spec``, ``compare.store``, ``compare.families``...
Each old path is the module at its new path (one object under both names, so a plug-in that
registers a family through ``compare.families`` registers it where the runner looks), and so is
each module below an old one (``compare.families.paper``). ``python -m`` runs an old path too
(the shipped power cases name ``python -m compare.families.power_cases.generate``).

compare/__init__.py's finder, first on ``sys.meta_path``, hands a name here only when it is a
``compare.<x>`` that is not a module of the package now, so ``import compare`` reads this
file only when an old path is imported. ``compare.report`` needs no entry: it is the report
package, and its names include the old module's.
"""

from __future__ import annotations

import sys
from importlib import import_module
from importlib.machinery import ModuleSpec
from importlib.util import find_spec as _spec_of

__all__ = ["MOVED", "new_path", "find_spec"]

#: ``compare.<key>`` is ``compare.<value>`` now.
MOVED = {
    **{m: f"run.{m}" for m in ("drawing", "environment", "execution", "export", "families", "fingerprint", "meta",
                               "parsing", "plugins", "pool", "records", "registry", "runner", "spec", "store")},
    **{m: f"report.{m}" for m in ("answer", "compute_report", "cost_links", "decomposition", "figures", "findings",
                                  "findings_text", "folder", "forest", "html", "interactive", "ladder",
                                  "learning_report", "names", "pattern_gaps", "statistics", "styles", "topologies")},
    "report_tables": "report.tables",
    "report_sections": "report.sections",
}


def new_path(name: str) -> str | None:
    """Where the module ``name`` is now if it is an old path or below one (``compare.families.paper``:
    ``compare.run.families.paper``), else None."""
    parts = name.split(".", 2)
    if len(parts) < 2 or parts[0] != "compare" or parts[1] not in MOVED:
        return None
    return ".".join(["compare", MOVED[parts[1]], *parts[2:]])


class _Alias:
    """Loader of an old path: the module of its new path takes its place in ``sys.modules``."""

    @staticmethod
    def create_module(spec):
        return None

    @staticmethod
    def exec_module(module):
        # The import returns what sys.modules holds under the name once this returns.
        sys.modules[module.__name__] = import_module(new_path(module.__name__))

    @staticmethod
    def get_code(name):
        """For ``python -m`` with an old path: the new module's code, run as ``__main__``."""
        new = new_path(name)
        return _spec_of(new).loader.get_code(new)


def find_spec(name: str) -> ModuleSpec | None:
    """The spec of an old path (None for any other name): the alias loader, the new module's file."""
    new = new_path(name)
    found = _spec_of(new) if new else None  # imports the new module's parent packages, not the module
    return None if found is None else ModuleSpec(name, _Alias, origin=found.origin)
