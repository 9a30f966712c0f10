"""Heavy packages loaded on first use, so that `compare --help` and `compare methods` answer at once.

torch takes about 2 s to import and most commands never train anything. A module
that needs it binds ``torch = lazy_import("torch")`` at the top as usual; the
package is imported on the first attribute access.

The stand-in stays out of ``sys.modules`` until then. (``importlib.util.LazyLoader``
puts its lazy module there, and libraries that ask ``sys.modules`` whether torch is
loaded then import it: ``import scipy.stats`` did, through its array-API checks,
in every process that writes a report, 1.5 s for nothing.)
"""

from __future__ import annotations

import importlib
import importlib.util
import sys
import types

__all__ = ["lazy_import"]


class _Deferred(types.ModuleType):
    """A module not imported yet: the first attribute access imports it and takes its namespace."""

    def __getattr__(self, attr: str):
        module = importlib.import_module(self.__name__)
        self.__dict__.update(vars(module))  # later accesses are plain lookups, not this method
        return getattr(module, attr)


def lazy_import(name: str) -> types.ModuleType:
    """The module ``name``, imported now if already loaded, else on its first attribute access."""
    if name in sys.modules:
        return sys.modules[name]
    if importlib.util.find_spec(name) is None:
        raise ModuleNotFoundError(f"No module named {name!r}", name=name)
    return _Deferred(name)
