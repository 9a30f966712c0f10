"""Code fingerprints: a stored run is reused only if the code that made it is unchanged.

A method's fingerprint hashes the source of its module and of every project module
that module uses (followed through its globals, transitively, and through the names
a module lists in ``FINGERPRINT_MODULES``: those it imports only when needed), the project's
evaluation code (instances, designs, controllers, evaluation, scoring), and the
versions of the numerical packages its numbers depend on (those every method uses, and
those a module of the closure names in ``FINGERPRINT_PACKAGES``, e.g. the ℓ1 SDP's
``("scs",)``). Editing one method's
file changes that method's fingerprint only; editing the evaluation code changes
every fingerprint.
"""

from __future__ import annotations

import hashlib
import json
import site
import sys
import sysconfig
import types
from importlib import import_module, metadata
from pathlib import Path

__all__ = ["fingerprint", "fingerprint_details", "package_versions", "EVALUATION_MODULES", "NUMERIC_PACKAGES"]

#: Modules every cost depends on, whatever the method.
EVALUATION_MODULES = ("codesign.instances", "codesign.design", "codesign.controllers", "codesign.evaluation", "codesign.estimators",
                      "codesign.scoring", "codesign.methods")
#: Packages whose version is part of every fingerprint.
NUMERIC_PACKAGES = ("numpy", "scipy", "cvxpy", "clarabel", "torch")
_PROJECT_PACKAGES = {"codesign", "baselines", "compare"}


def _installed_roots() -> tuple[str, ...]:
    roots = {sys.prefix, sys.base_prefix, sys.exec_prefix, sysconfig.get_paths()["stdlib"]}
    try:
        roots.update(site.getsitepackages())
    except AttributeError:  # pragma: no cover - virtualenvs without it
        pass
    roots.add(site.getusersitepackages())
    return tuple(str(Path(r).resolve()) for r in roots if r)


def _is_own(module: types.ModuleType, roots) -> bool:
    """A project module, or a user's module outside the installed packages (a plug-in and its helpers)."""
    name = module.__name__.split(".")[0]
    if name in _PROJECT_PACKAGES:
        return True
    path = getattr(module, "__file__", None)
    if not path or not path.endswith(".py"):
        return False
    path = str(Path(path).resolve())
    return not any(path.startswith(root + "/") or path == root for root in roots)


def _closure(names) -> list[types.ModuleType]:
    roots = _installed_roots()
    seen: dict[str, types.ModuleType] = {}
    todo = [import_module(n) if isinstance(n, str) else n for n in names]
    while todo:
        module = todo.pop()
        if module.__name__ in seen:
            continue
        seen[module.__name__] = module
        # Modules a module imports only when needed (heavy dependencies) declare themselves.
        todo.extend(import_module(name) for name in getattr(module, "FINGERPRINT_MODULES", ()))
        for value in vars(module).values():
            if isinstance(value, types.ModuleType):
                ref = value
            else:
                owner = getattr(value, "__module__", None) if isinstance(value, (type, types.FunctionType)) else None
                ref = sys.modules.get(owner) if isinstance(owner, str) else None
            if ref is not None and ref.__name__ not in seen and _is_own(ref, roots):
                # A package's __init__ re-exports everything; follow the names it was asked for instead.
                if getattr(ref, "__path__", None) is not None and ref is not value:
                    continue
                todo.append(ref)
    return sorted(seen.values(), key=lambda m: m.__name__)


def _source_hash(module: types.ModuleType) -> str:
    path = getattr(module, "__file__", None)
    data = Path(path).read_bytes() if path and Path(path).is_file() else module.__name__.encode()
    return hashlib.sha256(data).hexdigest()


def package_versions(names=NUMERIC_PACKAGES) -> dict[str, str]:
    """Installed version of each package (``"not installed"`` if missing), without importing it."""
    out = {}
    for name in names:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


_CACHE: dict[tuple, dict] = {}


def fingerprint_details(modules) -> dict:
    """``{"fingerprint", "modules": {name: sha256}, "versions"}`` for code defined in ``modules``."""
    key = tuple(modules)
    if key not in _CACHE:
        closure = _closure(list(EVALUATION_MODULES) + list(modules))
        sources = {m.__name__: _source_hash(m) for m in closure}
        # A solver only some methods use enters only their fingerprints (and leaves the
        # others' text, hence their stored runs, as they were).
        extra = sorted({p for m in closure for p in getattr(m, "FINGERPRINT_PACKAGES", ())} - set(NUMERIC_PACKAGES))
        versions = package_versions(NUMERIC_PACKAGES + tuple(extra))
        text = json.dumps({"modules": sources, "versions": versions}, sort_keys=True)
        _CACHE[key] = {"fingerprint": hashlib.sha256(text.encode()).hexdigest()[:16], "modules": sources,
                       "versions": versions}
    return _CACHE[key]


def fingerprint(method) -> str:
    """The code fingerprint of a registered :class:`~codesign.methods.Method`."""
    return fingerprint_details(method.modules)["fingerprint"]
