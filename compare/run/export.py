"""Stored designs as one analysis table: a row per design, settings as columns.

:func:`designs_frame` turns :meth:`Store.records` into a pandas DataFrame;
:meth:`Store.to_pandas` and ``compare export`` use it. Columns, in order:

* ``experiment`` (the experiment that computed the run), ``experiments`` (the
  experiments whose latest ``compare run`` names it, comma-separated),
  ``run_key`` and ``idx`` (``Store.controller(run_key, idx)`` rebuilds the
  controller), ``method``, ``label``;
* the instance fields: ``family``, ``n``, ``degree``, ``a_norm``, ``b_norm``,
  ``hops``, ``horizon``, ``seed`` (and any other field an instance carries);
* the outcome: ``cost``, ``cost_stderr``, ``cost_kind``, ``links``,
  ``self_loops``, ``info_model``, ``status``, ``message``, ``seconds``,
  ``controller_kind``, ``fingerprint``, and of the run that made it: ``run_seconds``
  (wall time, scoring included), ``run_designs``, ``run_peak_mb`` (its process's
  peak resident memory, MB), ``run_scoring_seconds`` (the part of the wall time spent
  scoring its designs) and ``run_baseline_mb`` (the resident memory its process started
  the run from, MB: ``run_peak_mb - run_baseline_mb`` is what the run added); empty
  where unknown, as in stores written before the last two were recorded;
* one column per hyperparameter found in any design (``gamma``, ``beta``,
  ``steps``, ...), empty (NaN) where a design has none. A hyperparameter is
  ``param_<name>`` when its name is another column of this table, ``params``, or
  an instance field of any registered family (:func:`instance_field_names`), whether
  or not this table's instances have that field: ``seed`` of a learned method and
  ``horizon`` of a method of yours are always ``param_seed`` and ``param_horizon``,
  so a bare ``horizon`` column is always the instance's. Then ``params``, all of a
  design's hyperparameters as JSON with sorted keys, a handy key for ``groupby``
  (which drops NaN groups);
* ``extra_<key>`` for each scalar entry of the designs' extras
  (``extra_spectral_radius``, ``extra_noise_cost``, ...); list- and dict-valued
  extras (training curves) are left out: :meth:`Store.records` has them.

Column types do not depend on which methods a store holds: a column whose
values are all numbers is ``float64`` for hyperparameters and extras (so
``gamma`` and ``beta`` are floats, NaN where a method has none) and an integer
type elsewhere (``Int64`` where values are missing); booleans are
``boolean``; text stays text; a column mixing kinds (``start`` is a name for
one method and a gain for another) holds each value as JSON text.

pandas (and pyarrow for parquet) come with the optional extra ``analysis``::

    pip install -e ".[analysis]"
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from .records import as_records

__all__ = ["FORMATS", "MissingExtra", "require_pandas", "designs_frame", "write_designs", "instance_field_names",
           "param_column_names"]

#: Formats ``compare export`` writes, and the file each gives.
FORMATS = {"csv": "designs.csv", "parquet": "designs.parquet"}

_IDENTITY = ("experiment", "experiments", "run_key", "idx", "method", "label")
_INSTANCE_ORDER = ("family", "n", "degree", "a_norm", "b_norm", "hops", "horizon", "seed")
_OUTCOME = ("cost", "cost_stderr", "cost_kind", "links", "self_loops", "info_model", "status", "message",
            "seconds", "controller_kind", "fingerprint", "run_seconds", "run_designs", "run_peak_mb",
            "run_scoring_seconds", "run_baseline_mb")
#: Outcome columns that are measurements: float64 even where every value happens to be whole.
_FLOAT_OUTCOME = frozenset(("cost", "cost_stderr", "seconds", "run_seconds", "run_peak_mb", "run_scoring_seconds",
                            "run_baseline_mb"))
_INSTALL = "pip install -e \".[analysis]\" (from a checkout) or pip install \"grnn-codesign[analysis]\""


class MissingExtra(ImportError):
    """pandas (or pyarrow, for parquet) is not installed; the message names the extra to install."""


def require_pandas(fmt: str = "csv"):
    """Import and return pandas, or raise :class:`MissingExtra` naming the ``analysis`` extra.

    ``fmt="parquet"`` also checks for pyarrow.
    """
    try:
        import pandas
    except ImportError:
        raise MissingExtra(f"pandas is not installed; it comes with the 'analysis' extra: {_INSTALL}") from None
    if fmt == "parquet":
        try:
            import pyarrow  # noqa: F401
        except ImportError:
            raise MissingExtra(f"writing parquet needs pyarrow, which comes with the 'analysis' extra: {_INSTALL}") \
                from None
    return pandas


def instance_field_names() -> frozenset:
    """Every name an instance spec may use as a field: the ones listed above and each registered family's."""
    from .families import family_names, get_family

    names = set(_INSTANCE_ORDER)
    for name in family_names():
        names |= get_family(name).fields
    return frozenset(names)


def param_column_names(param_keys, instance_keys=()) -> dict[str, str]:
    """Hyperparameter -> its column: ``param_<name>`` where the bare name is taken (see the module docstring).

    Parameters
    ----------
    param_keys : iterable of str
        Hyperparameter names found in the designs.
    instance_keys : iterable of str
        The instance fields the table has columns for (a plug-in family's may be
        unregistered in this process).
    """
    taken = set(_IDENTITY) | set(_OUTCOME) | {"params"} | set(instance_keys) | instance_field_names()
    return {k: f"param_{k}" if k in taken else k for k in param_keys}


def _is_scalar(value) -> bool:
    return value is None or isinstance(value, (bool, int, float, str))


def _column(pd, values: list, *, numbers: str):
    """One column with a type fixed by the kinds of its values (see the module docstring).

    ``numbers="float"`` makes every all-numeric column float64; ``"int"`` keeps
    all-integer columns integers (``Int64`` when some values are missing).
    """
    present = [v for v in values if v is not None]
    if not present:
        return pd.Series([float("nan")] * len(values), dtype="float64")
    if all(isinstance(v, bool) for v in present):
        return pd.Series(values, dtype="boolean")
    if all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in present):
        if numbers == "int" and all(isinstance(v, int) for v in present):
            return pd.Series(values, dtype="int64" if len(present) == len(values) else "Int64")
        return pd.Series([float("nan") if v is None else float(v) for v in values], dtype="float64")
    if all(isinstance(v, str) for v in present):
        return pd.Series(values)
    return pd.Series([None if v is None else json.dumps(v, sort_keys=True) for v in values], dtype=object)


def designs_frame(records, members: dict | None = None):
    """The analysis table of ``records`` (:meth:`Store.records`): one row per design.

    Parameters
    ----------
    records : Records or list of dict
        Stored designs as :meth:`Store.records` gives them (only current designs),
        or dicts shaped like the store's rows.
    members : dict, optional
        :meth:`Store.members`, experiment name -> run keys, for the ``experiments``
        column; without it (or for a run no experiment lists) the run's own experiment.

    Returns
    -------
    pandas.DataFrame
        Columns as in the module docstring, rows in the order of ``records``.
    """
    pd = require_pandas()
    records = as_records(records)
    instance_keys = _instance_keys(records)
    columns = _identity_columns(pd, records, members)
    for key in instance_keys:
        columns[key] = _column(pd, [r.instance.spec.get(key) for r in records], numbers="int")
    for key in _OUTCOME:
        numbers = "float" if key in _FLOAT_OUTCOME else "int"
        columns[key] = _column(pd, [getattr(r, key) for r in records], numbers=numbers)
    param_columns = param_column_names(sorted({k for r in records for k in r.params}), instance_keys)
    for key, name in param_columns.items():
        columns[name] = _column(pd, [r.params.get(key) for r in records], numbers="float")
    columns["params"] = _column(pd, [r.params_key for r in records], numbers="float")
    for key in _scalar_extra_keys(records):
        columns[f"extra_{key}"] = _column(pd, [r.extras.get(key) for r in records], numbers="float")
    return pd.DataFrame(columns, index=pd.RangeIndex(len(records)))


def _identity_columns(pd, records, members: dict | None) -> dict:
    """The columns that say which run made a design: ``experiment`` to ``label``."""
    in_experiments: dict[str, list[str]] = {}
    for name, keys in sorted((members or {}).items()):
        for key in keys:
            in_experiments.setdefault(key, []).append(name)
    columns = {"experiment": _column(pd, [r.experiment for r in records], numbers="int")}
    columns["experiments"] = _column(
        pd, [",".join(in_experiments.get(r.run_key, [r.experiment] if r.experiment else [])) for r in records],
        numbers="int")
    for key in ("run_key", "idx", "method", "label"):
        columns[key] = _column(pd, [getattr(r, key) for r in records], numbers="int")
    return columns


def _instance_keys(records) -> list[str]:
    """The instance fields of ``records``: the usual ones in their usual order, then any other, sorted."""
    instance_keys = list(dict.fromkeys(k for inst in records.instances for k in inst.spec))
    return [k for k in _INSTANCE_ORDER if k in instance_keys] + sorted(
        k for k in instance_keys if k not in _INSTANCE_ORDER)


def _scalar_extra_keys(records) -> list[str]:
    """The extras' keys, sorted, whose values are scalars in every design that has one (not training curves)."""
    extras_seen: dict[str, bool] = {}
    for r in records:
        for key, value in r.extras.items():
            extras_seen[key] = extras_seen.get(key, True) and _is_scalar(value)
    return sorted(k for k, scalar in extras_seen.items() if scalar)


def write_designs(frame, out: str | Path, fmt: str = "csv") -> Path:
    """Write ``frame`` to ``<out>/designs.csv`` (or ``.parquet``), replacing the file atomically.

    ``out`` is created if missing. Returns the written path.
    """
    if fmt not in FORMATS:
        raise ValueError(f"unknown format {fmt!r} (known: {', '.join(FORMATS)})")
    require_pandas(fmt)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / FORMATS[fmt]
    tmp = out / f".{path.name}.{os.getpid()}.tmp"
    try:
        if fmt == "csv":
            frame.to_csv(tmp, index=False)
        else:
            frame.to_parquet(tmp, index=False, engine="pyarrow")
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path
