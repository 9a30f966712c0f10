"""Heavy packages loaded on first use, so that `compare --help` and `compare methods` answer at once.

torch takes about 2 s to import and most commands never train anything. A module
that needs it binds ``torch = lazy_import("torch")`` at the top as usual; the
package executes on the first attribute access (:class:`importlib.util.LazyLoader`).
"""

from __future__ import annotations

import importlib.util
import sys
import types

__all__ = ["lazy_import"]


def lazy_import(name: str) -> types.ModuleType:
    """The module ``name``, imported now if already loaded, else on its first attribute access."""
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.find_spec(name)
    if spec is None:
        raise ModuleNotFoundError(f"No module named {name!r}", name=name)
    loader = importlib.util.LazyLoader(spec.loader)
    spec.loader = loader
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    loader.exec_module(module)
    return module
