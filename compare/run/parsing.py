"""Checks for the tables of an experiment spec, shared by :mod:`compare.run.spec` and the families.

Each check names the offending key in its :class:`SpecError`, so a family's ``parse``
(:class:`compare.run.families.Family`) reports a bad ``[instances]`` table as the spec
parser reports the rest of a spec::

    from compare.run.parsing import SpecError, check_keys, list_of, typed

    def parse(table, base):
        check_keys("instances", table, {"family", "n", "seeds"})
        sizes = list_of("instances.n", table.get("n", [20]), int)
        seeds = typed("instances.seeds", table.get("seeds", 1), int)
        ...

This module imports nothing of the project's, so that a family may import it without
importing :mod:`compare.run.spec`, which imports the families.
"""

from __future__ import annotations

import math

__all__ = ["SpecError", "check_keys", "list_of", "typed"]


class SpecError(ValueError):
    """A malformed experiment spec; the message names the offending key."""


def check_keys(where: str, table: dict, allowed: set) -> None:
    """Refuse a key of ``table`` that ``allowed`` does not name.

    Parameters
    ----------
    where : str
        The table's place in the spec (``"instances"``, ``"methods[2]"``), prefixed to the key.
    table : dict
        The parsed TOML table.
    allowed : set of str
        The keys the table may have.

    Raises
    ------
    SpecError
        On the first unknown key, as ``"<where>.<key>: unknown key (allowed: ...)"``.
    """
    for key in table:
        if key not in allowed:
            raise SpecError(f"{where}.{key}: unknown key (allowed: {', '.join(sorted(allowed))})")


def typed(where: str, value, kind):
    """``value``, checked to be of type ``kind``.

    A bool is no ``int`` or ``float`` here (TOML's ``true`` is not a count); an ``int`` is
    accepted as a ``float`` and converted; a ``float`` must be finite.

    Parameters
    ----------
    where : str
        The key's place in the spec (``"instances.dt"``), named in the error.
    value : object
        The parsed TOML value.
    kind : type or tuple of type
        The type (or types) expected.

    Returns
    -------
    object
        ``value``, or ``float(value)`` for an ``int`` where ``kind`` is ``float``.

    Raises
    ------
    SpecError
        If ``value`` is of another type, or a ``float`` that is not finite.
    """
    ok = isinstance(value, kind) and not (kind in (int, float) and isinstance(value, bool))
    if kind is float and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if kind is float and ok and not math.isfinite(value):
        raise SpecError(f"{where}: expected a finite number, got {value!r}")
    if not ok:
        kind_name = kind.__name__ if isinstance(kind, type) else "/".join(k.__name__ for k in kind)
        raise SpecError(f"{where}: expected {kind_name}, got {type(value).__name__} {value!r}")
    return value


def list_of(where: str, value, kind, *, positive: bool = True) -> tuple:
    """A value or a non-empty list of values, each checked by :func:`typed`, as a tuple.

    Parameters
    ----------
    where : str
        The key's place in the spec (``"instances.n"``); a list's items are named
        ``"<where>[i]"`` in errors.
    value : object or list
        One value (``n = 20``) or a list of them (``n = [20, 40]``).
    kind : type or tuple of type
        The type each value must have (see :func:`typed`).
    positive : bool, default True
        Also require every value to be > 0.

    Returns
    -------
    tuple
        The checked values, one for a single value.

    Raises
    ------
    SpecError
        If the list is empty, a value has the wrong type, or (``positive``) a value is <= 0.
    """
    items = value if isinstance(value, list) else [value]
    if not items:
        raise SpecError(f"{where}: must not be empty")
    out = tuple(typed(f"{where}[{i}]" if isinstance(value, list) else where, v, kind) for i, v in enumerate(items))
    if positive and any(v <= 0 for v in out):
        raise SpecError(f"{where}: values must be positive, got {list(out)}")
    return out
