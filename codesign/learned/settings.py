"""Settings of the learned methods: one frozen type per method, the single place for defaults and bounds.

A settings type is a frozen dataclass whose fields carry their bounds in their
annotations (``Annotated[int, AtLeast(1)]``, as a method's keyword arguments
do). Constructing one checks every field (ValueError naming the field), and
:func:`takes_settings` gives a method function the settings' fields as its
keyword-only parameters, so the registry's hyperparameters, ``compare methods``
and ``help()`` all read the one table::

    @dataclass(frozen=True)
    class MySettings(TrainingSettings):
        lr: Annotated[float, Above(0)] = 0.01

    @takes_settings(MySettings)
    def my_method(instance, *, seed: Annotated[int, AtLeast(0)] = 0, **settings):
        s = MySettings(**settings)
        ...
"""

from __future__ import annotations

import dataclasses
import inspect
import typing
from dataclasses import dataclass
from typing import Annotated, Literal

from ..methods import AtLeast, Hyperparameter
from .trainer import DTYPES

__all__ = ["TrainingSettings", "takes_settings", "SEED"]

#: A learned method's ``seed`` keyword (not a training setting: it is not part of a stack's key).
SEED = Hyperparameter("seed", 0, Annotated[int, AtLeast(0)])


@dataclass(frozen=True)
class TrainingSettings:
    """What every learned method's training has: loop length, ensemble, curve, precision, stability check.

    Attributes
    ----------
    steps : int
        Adam updates.
    batch : int
        Draws x(0) ~ N(0, I) per update.
    ensemble : int
        Models trained per run; the one with the lowest cost on the selection set is kept.
    curve_every : int
        Record the selection-set cost every this many updates (0: only at the end).
    curve_size : int
        Draws of the selection set (training curve and ensemble selection), apart from the validation set.
    dtype : {"float64", "float32"}
        Training precision.
    stability_steps : int
        Length of the boundedness check rollout (0 skips it).
    stability_size : int
        How many draws of the validation set the boundedness check starts from.
    """

    steps: Annotated[int, AtLeast(1)] = 750
    batch: Annotated[int, AtLeast(1)] = 20
    ensemble: Annotated[int, AtLeast(1)] = 2
    curve_every: Annotated[int, AtLeast(0)] = 10
    curve_size: Annotated[int, AtLeast(2)] = 100
    dtype: Literal[DTYPES] = "float64"
    stability_steps: Annotated[int, AtLeast(0)] = 500
    stability_size: Annotated[int, AtLeast(1)] = 100

    def __post_init__(self):
        for name, hyper in self.hyperparameters().items():
            hyper.check(getattr(self, name), name)

    @classmethod
    def hyperparameters(cls) -> dict:
        """Field name -> :class:`~codesign.methods.Hyperparameter` (default and annotation, bounds included)."""
        hints = typing.get_type_hints(cls, include_extras=True)
        return {f.name: Hyperparameter(f.name, f.default, hints[f.name]) for f in dataclasses.fields(cls)}

    @classmethod
    def parse(cls, kwargs: dict, method: str):
        """The settings named in ``kwargs``; ValueError naming unknown keys (and listing the known) or a bad value."""
        known = sorted(f.name for f in dataclasses.fields(cls))
        unknown = set(kwargs) - set(known)
        if unknown:
            raise ValueError(f"unknown {method} settings: {sorted(unknown)}; known: {known}")
        return cls(**kwargs)

    def changed(self) -> dict:
        """The fields that differ from their defaults, by name (what a design's params record)."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)
                if getattr(self, f.name) != f.default}


def takes_settings(settings_type):
    """Decorator: ``f(instance, *, <own keywords>, **settings)`` gets ``settings_type``'s fields as keywords.

    The function's signature and annotations then list its own keyword-only
    parameters followed by every field of the settings type with its default and
    bounds, and its docstring's ``Parameters`` the fields' ``Attributes`` entries
    from the settings types' docstrings: what :func:`codesign.methods.method`,
    ``compare methods`` and ``help()`` read.
    """
    def decorate(func):
        func.__doc__ = _with_parameters(inspect.getdoc(func) or "", _field_docs(settings_type))
        sig = inspect.signature(func)
        own = [p for p in sig.parameters.values() if p.kind is not p.VAR_KEYWORD]
        hints = typing.get_type_hints(settings_type, include_extras=True)
        fields = [inspect.Parameter(f.name, inspect.Parameter.KEYWORD_ONLY, default=f.default,
                                    annotation=hints[f.name]) for f in dataclasses.fields(settings_type)]
        func.__signature__ = sig.replace(parameters=own + fields)
        func.__annotations__ = {**typing.get_type_hints(func, include_extras=True),
                                **{f.name: hints[f.name] for f in dataclasses.fields(settings_type)}}
        func.settings_type = settings_type
        return func
    return decorate


def _section(doc: str, title: str) -> list[str]:
    """The lines of a numpydoc section (after its underline), up to the next section."""
    lines = doc.splitlines()
    for i, line in enumerate(lines[:-1]):
        if line.strip() == title and set(lines[i + 1].strip()) == {"-"}:
            out = []
            for nxt, rest in zip(lines[i + 2:], lines[i + 3:] + [""]):
                if nxt.strip() and set(rest.strip()) == {"-"} and not nxt.startswith(" "):
                    break
                out.append(nxt)
            return out
    return []


def _field_docs(settings_type) -> list[str]:
    """The ``Attributes`` entries of the settings type and its bases, bases first."""
    lines = []
    for cls in reversed(settings_type.__mro__):
        if dataclasses.is_dataclass(cls) and "__doc__" in vars(cls):
            lines += [line for line in _section(inspect.getdoc(cls) or "", "Attributes") if line.strip()]
    return lines


def _with_parameters(doc: str, entries: list[str]) -> str:
    """``doc`` with ``entries`` appended to its ``Parameters`` section."""
    lines = doc.splitlines()
    own = _section(doc, "Parameters")
    if not own and not any(line.strip() == "Parameters" for line in lines):
        return "\n".join(lines + ["", "Parameters", "----------"] + entries) + "\n"
    start = next(i for i, line in enumerate(lines) if line.strip() == "Parameters") + 2
    end = start + len(own)
    while end > start and not lines[end - 1].strip():
        end -= 1
    return "\n".join(lines[:end] + entries + lines[end:]).rstrip() + "\n"
