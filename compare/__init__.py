"""The comparison harness: experiment specs, runner, result store, reports, CLI.

Public names::

    from compare import load_spec, run_experiment, Store, write_report, methods, register
"""

from .registry import Method, get_method, methods, register
from .report import aggregate, plot_cost_vs_links, write_report
from .runner import RunSummary, execute_run, run_experiment
from .spec import ExperimentSpec, Run, SpecError, load_spec, parse_spec, preset_names
from .store import Store, StoreError

__all__ = [
    "Method",
    "register",
    "get_method",
    "methods",
    "ExperimentSpec",
    "Run",
    "SpecError",
    "load_spec",
    "parse_spec",
    "preset_names",
    "Store",
    "StoreError",
    "run_experiment",
    "execute_run",
    "RunSummary",
    "aggregate",
    "plot_cost_vs_links",
    "write_report",
]
