"""Instance families: where an experiment's systems come from, one file per family.

A family turns the ``[instances]`` table of a spec into instance specs (small
JSON-able dicts, stored with every run and used in its key) and builds the
:class:`codesign.Instance` a spec describes, in whichever process runs it.
Built-in families:

``paper``
    The paper's random family (:func:`codesign.paper_instance`), keys ``n``,
    ``a_norms``, ``seeds``, ``degree``, ``b_norm``, ``hops``, ``horizon``.
``matrices``
    Your own systems from ``.npz`` files (key ``files``); see
    :mod:`compare.run.families.matrices`.
``mass_spring``, ``random_network``
    lqrsp's two examples (Lin, Fardad & Jovanović): a chain of masses and springs,
    unstable second-order nodes placed at random.
``chain``, ``swing_grid``, ``platoon``, ``power_grid``
    The field's benchmark systems: the SLS toolboxes' doubly stochastic chain, the
    linearized swing equations on a randomized mesh (the SLS power-grid example),
    a string of vehicles (Lin, Fardad & Jovanović 2012), and published grids from ANDES
    reduced to their machines (Dörfler et al. 2014's setting); ``chain`` and
    ``swing_grid`` take an actuation density (nodes without an actuator).

A family of your own is a :class:`Family` passed to :func:`register_family` in a
plug-in module (``plugins = [...]`` in a spec).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from importlib import import_module
from typing import Callable

__all__ = ["Family", "register_family", "get_family", "family_names", "UnknownFamilyError"]

#: Modules of the built-in families, imported on first use.
_BUILTIN = {"paper": "compare.run.families.paper", "matrices": "compare.run.families.matrices",
            "mass_spring": "compare.run.families.mass_spring", "random_network": "compare.run.families.random_network",
            "chain": "compare.run.families.chain", "swing_grid": "compare.run.families.swing_grid",
            "platoon": "compare.run.families.platoon", "power_grid": "compare.run.families.power_grid"}
_FAMILIES: dict[str, "Family"] = {}


class UnknownFamilyError(KeyError):
    def __str__(self) -> str:
        return str(self.args[0])


def _whole(spec: dict) -> dict:
    return spec


def _one_state_per_node(spec: dict) -> int | None:
    return spec.get("n")


@dataclass(frozen=True)
class Family:
    """A named source of instances.

    Attributes
    ----------
    name : str
    summary : str
        One line for listings.
    parse : callable ``(table, base) -> tuple of dict``
        The spec's ``[instances]`` table (``family`` included) and the spec file's
        folder (None for presets and text) to instance specs, each a JSON-able dict
        with ``"family"``; raises :class:`compare.SpecError` naming the bad key.
    build : callable ``(spec) -> Instance``
    fields : frozenset of str
        Instance-spec fields a method entry's ``where`` may filter on.
    identity : callable ``(spec) -> dict``
        What a run key hashes of an instance spec (by default all of it); a family
        whose specs name files hashes their contents instead of their paths.
    states : callable ``(spec) -> int or None``
        How many states the instance a spec describes has (by default its ``n``,
        one state per node; None: unknown), for the size guard that refuses, when
        a spec is loaded, instances too large for the machine's memory.
    """

    name: str
    summary: str
    parse: Callable
    build: Callable
    fields: frozenset = field(default_factory=frozenset)
    identity: Callable = _whole
    states: Callable = _one_state_per_node


def register_family(family: Family) -> Family:
    """Make ``family`` available by name in specs (``[instances] family = "..."``)."""
    if not isinstance(family, Family):
        raise TypeError(f"register_family expects a Family, got {type(family).__name__}")
    _FAMILIES[family.name] = family
    return family


def _load_builtins() -> None:
    for name, module in _BUILTIN.items():
        if name not in _FAMILIES:
            import_module(module)


def get_family(name: str) -> Family:
    """The registered family ``name``; :class:`UnknownFamilyError` names the known ones."""
    if name not in _FAMILIES:
        _load_builtins()
    if name not in _FAMILIES:
        raise UnknownFamilyError(f"unknown family {name!r} (known: {', '.join(family_names())})")
    return _FAMILIES[name]


def family_names() -> list[str]:
    _load_builtins()
    return sorted(_FAMILIES)
