"""The method registry as the harness sees it: the built-ins, plus any plug-ins loaded.

Importing this module imports :mod:`baselines` and :mod:`codesign`, whose method
modules register themselves with the :func:`codesign.methods.method` decorator;
user methods come in through :mod:`compare.run.plugins`.
"""

from __future__ import annotations

import baselines  # noqa: F401  (registers the baselines)
import codesign  # noqa: F401  (registers the GRNN variants)
from codesign.methods import Method, UnknownMethodError, get_method, method, register
from codesign.methods import registered_methods as methods

__all__ = ["Method", "method", "register", "get_method", "methods", "UnknownMethodError"]
