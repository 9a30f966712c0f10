"""The comparison harness: experiment specs, runner, result store, reports, CLI.

Public names::

    from compare import load_spec, run_experiment, Store, write_report, methods, method
    from compare import Records, DesignRecord, InstanceRecord   # what Store.records() hands out
    from compare import designs_frame       # Store.records() as one pandas table (the `analysis` extra)
"""

from importlib import import_module

# Names resolve on first use, so that `compare --help` does not pay for matplotlib.
_EXPORTS = {
    "Method": "registry",
    "method": "registry",
    "register": "registry",
    "Plugin": "plugins",
    "PluginError": "plugins",
    "parse_plugin": "plugins",
    "load_plugins": "plugins",
    "fingerprint": "fingerprint",
    "get_method": "registry",
    "methods": "registry",
    "ExperimentSpec": "spec",
    "Run": "spec",
    "SpecError": "spec",
    "load_spec": "spec",
    "parse_spec": "spec",
    "preset_names": "spec",
    "Store": "store",
    "StoreError": "store",
    "run_experiment": "runner",
    "execute_run": "runner",
    "RunSummary": "runner",
    "aggregate": "report",
    "plot_cost_vs_links": "report",
    "write_report": "report",
    "Records": "records",
    "DesignRecord": "records",
    "InstanceRecord": "records",
    "designs_frame": "export",
    "write_designs": "export",
    "MissingExtra": "export",
}

__all__ = list(_EXPORTS)


def __getattr__(name):
    if name not in _EXPORTS:
        raise AttributeError(f"module 'compare' has no attribute {name!r}")
    value = getattr(import_module(f".{_EXPORTS[name]}", __name__), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(list(globals()) + __all__)
