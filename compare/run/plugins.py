"""User methods: plug-in modules and ``module:function`` references.

A spec (or ``compare run --plugin``) names Python modules or files to import;
those register methods with :func:`codesign.methods.method`. A method entry may
also name a plain function directly, ``"my_methods:trunc10"`` or
``"path/to/file.py:trunc10"`` (a file path relative to the spec's folder): it is
registered under that reference, labelled with the function's name.

A :class:`Plugin` is a small picklable value, so worker processes and Dask
workers import the same plug-ins before they run anything.
"""

from __future__ import annotations

import hashlib
import importlib
import importlib.util
import sys
from dataclasses import dataclass
from pathlib import Path

from codesign.methods import Method, register

__all__ = ["Plugin", "PluginError", "parse_plugin", "load_plugins"]


class PluginError(ValueError):
    """A plug-in that cannot be imported or does not define what it should."""


@dataclass(frozen=True)
class Plugin:
    """A module (by name or file) to import, and optionally one function in it to register as a method.

    Attributes
    ----------
    ref : str
        What the user wrote (``"my_methods"``, ``"more.py"``, ``"my_methods:trunc10"``);
        for a function reference, the method's registered name.
    target : str
        A module name, or the absolute path of a ``.py`` file.
    function : str or None
        The function to register, for a ``module:function`` reference.
    search : tuple of str
        Folders searched first for a module name (the spec's folder, the working folder).
    """

    ref: str
    target: str
    function: str | None = None
    search: tuple = ()

    @property
    def is_file(self) -> bool:
        return self.target.endswith(".py")

    def load(self) -> None:
        """Import the module (registering its methods), and register the referenced function if any."""
        module = _import(self)
        if self.function is None:
            return
        func = getattr(module, self.function, None)
        if not callable(func):
            raise PluginError(f"plugin {self.ref!r}: {self.target_name} has no function {self.function!r}")
        try:
            register(Method.from_function(func, name=self.ref, label=self.function), replace_existing=True)
        except TypeError as exc:
            raise PluginError(f"plugin {self.ref!r}: {exc}") from None

    @property
    def target_name(self) -> str:
        return f"file {self.target}" if self.is_file else f"module {self.target!r}"


def parse_plugin(ref: str, *, base: Path | None = None, function: bool = False) -> Plugin:
    """The :class:`Plugin` for a reference, resolving file paths against ``base`` (default: the working folder).

    With ``function=True`` the reference must be ``"module:function"`` or ``"file.py:function"``.
    """
    base = Path(base or Path.cwd()).resolve()
    target, func = ref, None
    if function:
        target, sep, func = ref.rpartition(":")
        if not sep or not target or not func.isidentifier():
            raise PluginError(f"method {ref!r}: expected 'module:function' or 'path/to/file.py:function'")
    if target.endswith(".py"):
        path = (base / target).resolve()
        if not path.is_file():
            raise PluginError(f"plugin {ref!r}: file not found: {path}")
        return Plugin(ref, str(path), func)
    if not all(part.isidentifier() for part in target.split(".")):
        raise PluginError(f"plugin {ref!r}: {target!r} is neither a module name nor a .py file")
    return Plugin(ref, target, func, tuple(dict.fromkeys([str(base), str(Path.cwd().resolve())])))


def _file_module_name(path: str) -> str:
    # Deterministic, so that a class defined in the file pickles between processes.
    return f"compare_plugin_{Path(path).stem}_{hashlib.sha1(path.encode()).hexdigest()[:8]}"


def _import(plugin: Plugin):
    if plugin.is_file:
        name = _file_module_name(plugin.target)
        if name in sys.modules:
            return sys.modules[name]
        if not Path(plugin.target).is_file():
            raise PluginError(f"plugin {plugin.ref!r}: file not found: {plugin.target}")
        spec = importlib.util.spec_from_file_location(name, plugin.target)
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        try:
            spec.loader.exec_module(module)
        except (Exception, SystemExit) as exc:  # a plug-in's sys.exit must not end the command silently
            del sys.modules[name]
            raise PluginError(f"plugin {plugin.ref!r}: importing {plugin.target} raised "
                              f"{type(exc).__name__}: {exc}") from None
        return module
    added = [p for p in plugin.search if p not in sys.path]
    sys.path[:0] = added
    try:
        return importlib.import_module(plugin.target)
    except ModuleNotFoundError as exc:
        if exc.name and plugin.target.startswith(exc.name):
            raise PluginError(f"plugin {plugin.ref!r}: no module named {plugin.target!r} (searched "
                              f"{', '.join(plugin.search) or 'sys.path'} and the installed packages)") from None
        raise PluginError(f"plugin {plugin.ref!r}: importing it raised ModuleNotFoundError: {exc}") from None
    except (Exception, SystemExit) as exc:
        raise PluginError(f"plugin {plugin.ref!r}: importing it raised {type(exc).__name__}: {exc}") from None
    finally:
        # A module name keeps resolving in this process once imported; the path need not stay.
        for p in added:
            if p in sys.path:
                sys.path.remove(p)


_LOADED: set = set()


def load_plugins(plugins) -> None:
    """Import every plug-in once per process (idempotent; cheap to call before every task)."""
    for plugin in plugins:
        if plugin not in _LOADED:
            plugin.load()
            _LOADED.add(plugin)
