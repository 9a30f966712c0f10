"""The report side of the harness: from records (a store's, or a report folder's) to a report.

:mod:`~compare.report.write` writes it (``write_report``); the statistics, findings, figures,
tables and sections it calls are this package's other modules, and
:mod:`~compare.report.folder` reads a report folder back. It reads what the run side
stored through :mod:`compare.run.records` and :mod:`compare.run.meta`, and may import the run
side; the run side never imports this package.

The names of :mod:`compare.report.write` resolve here on first use (``from compare.report
import write_report``, as before the package was split), so that importing one of this
package's modules does not load the whole report.
"""

from importlib import import_module

#: :mod:`compare.report.write`'s ``__all__``.
_WRITE = ("Point", "pareto_front", "budget_costs", "plant_links", "aggregate", "plot_cost_vs_links", "write_report",
          "software_versions", "quartiles", "INFO_STYLE", "report_records")

__all__ = list(_WRITE)


def __getattr__(name):
    if name not in _WRITE:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(import_module(".write", __name__), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(list(globals()) + __all__)
