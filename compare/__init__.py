"""The comparison harness: experiment specs, runner, result store, reports, CLI.

Public names::

    from compare import load_spec, run_experiment, Store, write_report, methods, method
    from compare import Records, DesignRecord, InstanceRecord   # what Store.records() hands out
    from compare import designs_frame       # Store.records() as one pandas table (the `analysis` extra)

Two halves: :mod:`compare.run` runs experiments into a store (specs, families, runner,
store, records, meta), :mod:`compare.report` turns records into reports. The report side
imports the run side's records and meta; the run side never imports the report side.
Only the CLI (:mod:`compare.cli`) and this package's names use both.
"""

import sys

# Names resolve on first use, so that `compare --help` does not pay for matplotlib.
_EXPORTS = {
    "Method": "run.registry",
    "method": "run.registry",
    "register": "run.registry",
    "Plugin": "run.plugins",
    "PluginError": "run.plugins",
    "parse_plugin": "run.plugins",
    "load_plugins": "run.plugins",
    "fingerprint": "run.fingerprint",
    "get_method": "run.registry",
    "methods": "run.registry",
    "ExperimentSpec": "run.spec",
    "Run": "run.spec",
    "SpecError": "run.spec",
    "load_spec": "run.spec",
    "parse_spec": "run.spec",
    "preset_names": "run.spec",
    "Store": "run.store",
    "StoreError": "run.store",
    "run_experiment": "run.runner",
    "execute_run": "run.runner",
    "RunSummary": "run.runner",
    "aggregate": "report.write",
    "plot_cost_vs_links": "report.write",
    "write_report": "report.write",
    "Records": "run.records",
    "DesignRecord": "run.records",
    "InstanceRecord": "run.records",
    "designs_frame": "run.export",
    "write_designs": "run.export",
    "MissingExtra": "run.export",
}

__all__ = list(_EXPORTS)


def __getattr__(name):
    if name not in _EXPORTS:
        raise AttributeError(f"module 'compare' has no attribute {name!r}")
    from importlib import import_module

    value = getattr(import_module(f".{_EXPORTS[name]}", __name__), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(list(globals()) + __all__)


def _old_path(name, path=None, target=None):
    """Finder (first on sys.meta_path) of the module paths from before compare/ was split in two
    (``compare.spec`` is ``compare.run.spec``): compare/_moved.py, read only when one is imported."""
    if name.startswith("compare.") and name.split(".", 2)[1] not in ("run", "report", "cli", "__main__", "_moved"):
        from ._moved import find_spec

        return find_spec(name)
    return None


_old_path.find_spec = _old_path  # the finder is the function itself (a class would cost `import compare` time)
sys.meta_path.insert(0, _old_path)
