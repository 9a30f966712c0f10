"""Design methods: one object per method, registered by a decorator in the method's own module.

A method is a function ``f(instance, *, **hyperparameters) -> Design | list[Design]``
with keyword-only hyperparameters (their defaults and annotations are the method's
one table of settings). The :func:`method` decorator wraps it in a frozen
:class:`Method` and registers it by name::

    from codesign.methods import method
    from codesign.scoring import score

    @method("trunc10", label="Truncated LQR (10 links)")
    def trunc10(instance, *, links: int = 10):
        ...
        return score(instance, StaticGain(K))

The decorated function is returned unchanged, so it stays an ordinary function
for notebooks. Calling the :class:`Method` checks the instance and the
hyperparameters, runs the function and stamps the method's name into every returned
:class:`Design` (a method never types its own name). This follows benchopt's one-file
solvers and pymanopt's split between an optimizer and its frozen result.

A hyperparameter's bounds are declared in its annotation, with ``typing.Annotated``
(plain Python calls and type checkers still see the plain type), so that a spec is
refused before any work::

    def f(instance, *, steps: Annotated[int, AtLeast(1)] = 750,
          beta: Annotated[float, AtLeast(0)] | None = None,
          gammas: list[Annotated[float, Above(0)]] | None = None,
          dtype: Literal["float64", "float32"] = "float64"): ...

The constraints are :class:`AtLeast`, :class:`Above`, :class:`AtMost`,
:class:`Below` (numbers; each also refuses NaN and infinities), :class:`NotEmpty`
(lists) and :class:`Matches` (strings of a pattern); a ``Literal`` gives the
choices.
"""

from __future__ import annotations

import inspect
import math
import operator
import re
import types
import typing
from dataclasses import dataclass, field, replace
from typing import Any, Callable

from .design import Design
from .instances import check_instance
from .status import FAILED

__all__ = [
    "Method",
    "Hyperparameter",
    "AtLeast",
    "Above",
    "AtMost",
    "Below",
    "NotEmpty",
    "Matches",
    "method",
    "register",
    "get_method",
    "registered_methods",
    "UnknownMethodError",
    "PRODUCTS",
]

#: What a method may declare that its designs carry, so a report can give it a section:
#: ``training_curve`` (``extras["curve"] = {"step": [...], "cost": [...]}``) and
#: ``topology_path`` (designs along ``path_param`` whose controllers expose ``support``).
PRODUCTS = ("training_curve", "topology_path")


class UnknownMethodError(KeyError):
    """A method name that is not registered."""

    def __str__(self):
        return str(self.args[0])


# -- value constraints, carried in a hyperparameter's Annotated annotation -------------
def _finite(value) -> bool:
    # An int too large for a float is still a finite number.
    return isinstance(value, int) or math.isfinite(value)


@dataclass(frozen=True)
class _Compared:
    """A finite number in a fixed relation to ``bound``; the subclasses name the relation."""

    bound: float
    _symbol = ""
    _holds = staticmethod(lambda value, bound: False)

    def allows(self, value) -> bool:
        return _finite(value) and self._holds(value, self.bound)

    def __str__(self) -> str:
        return f"{self._symbol} {self.bound:g}"


class AtLeast(_Compared):
    """A number ``>= bound`` (and finite)."""

    _symbol, _holds = ">=", staticmethod(operator.ge)


class Above(_Compared):
    """A number ``> bound`` (and finite)."""

    _symbol, _holds = ">", staticmethod(operator.gt)


class AtMost(_Compared):
    """A number ``<= bound`` (and finite)."""

    _symbol, _holds = "<=", staticmethod(operator.le)


class Below(_Compared):
    """A number ``< bound`` (and finite)."""

    _symbol, _holds = "<", staticmethod(operator.lt)


@dataclass(frozen=True)
class NotEmpty:
    """A list with at least one item."""

    def allows(self, value) -> bool:
        return len(value) > 0

    def __str__(self) -> str:
        return "non-empty"


@dataclass(frozen=True)
class Matches:
    """A string that matches ``pattern`` in full; ``text`` says which strings those are, for messages."""

    pattern: str
    text: str

    def allows(self, value) -> bool:
        return re.fullmatch(self.pattern, value) is not None

    def __str__(self) -> str:
        return self.text


_LOWER = (AtLeast, Above)
_UPPER = (AtMost, Below)


@dataclass(frozen=True)
class Hyperparameter:
    """One keyword-only hyperparameter: its name, default, annotation (bounds included) and one-line meaning."""

    name: str
    default: Any
    annotation: Any = Any
    doc: str = ""

    @property
    def type_name(self) -> str:
        return _type_name(self.annotation)

    def check(self, value, where: str) -> None:
        """Raise ValueError naming ``where`` when ``value`` does not fit the annotation's type or bounds."""
        problem = _problem(value, self.annotation)
        if problem is not None:
            suffix, message = problem
            raise ValueError(f"{where}{suffix}: {message}")


@dataclass(frozen=True)
class Method:
    """A registered design method.

    Attributes
    ----------
    name : str
        The name used in specs and on the CLI.
    design : callable
        ``design(instance, **params) -> Design | list[Design]``.
    label : str
        Legend label (a spec entry may override it).
    summary : str
        One line for ``compare methods``.
    hyperparameters : dict of str to Hyperparameter
        The one defaults table: every keyword the method accepts.
    batch : callable, optional
        ``batch(pairs) -> list`` designing many ``(instance, params)`` pairs in one
        call (one ``Design`` or list of them per pair, in order), so that e.g. many
        GRNNs train as one batched program.
    batch_size : int
        How many runs the runner hands ``batch`` at once.
    produces : tuple of str
        Entries of :data:`PRODUCTS` the designs carry (report sections).
    path_param : str, optional
        The hyperparameter a ``topology_path`` runs along (e.g. ``"beta"``).
    modules : tuple of str
        Modules whose source defines the method (for the code fingerprint).
    node_blocks : bool
        Whether the method handles nodes with several states or inputs
        (:attr:`codesign.Instance.scalar_nodes` False). A method that does not is
        never called on such an instance: its run records a ``failed`` design
        saying so.
    max_states : int, optional
        The most states the method is run on through the registry (a spec, the CLI):
        above it a run records, at once, a ``failed`` design giving
        ``max_states_reason`` instead of an attempt that would take hours. Calling the
        function itself runs it at any size.
    max_states_reason : str
        Why, with what was measured, e.g. ``"one γ takes 19 minutes at 500 states"``.
    size_limit : callable, optional
        ``size_limit(instance, params) -> (states, reason) or None``: a tighter
        limit for some settings or instances only (GRNN-Sparse's l1 stage on
        every pair of nodes, but not on a few hops; node blocks, whose products
        stay dense), enforced like ``max_states``.
    check : callable, optional
        ``check(params) -> None``: raises ValueError for hyperparameters that are each
        valid but not together (a setting that needs another's value, such as the
        GRNN's warm start and its per-node readout), given one run's hyperparameters
        (those left out take their defaults). :meth:`check_together` runs it: a spec is
        refused when it is loaded, for every grid point, and a call before any work.
    """

    name: str
    design: Callable
    label: str
    summary: str
    hyperparameters: dict = field(default_factory=dict)
    batch: Callable | None = None
    batch_size: int = 64
    produces: tuple = ()
    path_param: str | None = None
    modules: tuple = ()
    node_blocks: bool = False
    max_states: int | None = None
    max_states_reason: str = ""
    size_limit: Callable | None = None
    check: Callable | None = None

    def __post_init__(self):
        unknown = set(self.produces) - set(PRODUCTS)
        if unknown:
            raise ValueError(f"method {self.name!r}: unknown products {sorted(unknown)} (known: {', '.join(PRODUCTS)})")

    @property
    def defaults(self) -> dict:
        """Hyperparameter name -> default."""
        return {name: h.default for name, h in self.hyperparameters.items()}

    @classmethod
    def from_function(
        cls,
        func: Callable,
        *,
        name: str | None = None,
        label: str | None = None,
        summary: str | None = None,
        bind: dict | None = None,
        exclude: tuple = (),
        batch: Callable | None = None,
        batch_size: int = 64,
        produces: tuple = (),
        path_param: str | None = None,
        node_blocks: bool = False,
        max_states: int | None = None,
        max_states_reason: str = "",
        size_limit: Callable | None = None,
        check: Callable | None = None,
    ) -> "Method":
        """A method from a function's keyword-only parameters.

        ``bind`` fixes some keywords (e.g. a variant) and removes them from the
        hyperparameters, like ``exclude``. Raises TypeError when the function does
        not take an instance and keyword-only hyperparameters.
        """
        name = name or func.__name__
        bind = dict(bind or {})
        hyper = _hyperparameters(func, name, dropped=set(bind) | set(exclude))
        doc = inspect.getdoc(func) or ""
        design = func if not bind else _Bound(func, bind)
        modules = tuple(dict.fromkeys(m.__module__ for m in (func, batch) if m is not None))
        return cls(
            name=name,
            design=design,
            label=label or name,
            summary=summary or (doc.splitlines()[0] if doc else ""),
            hyperparameters=hyper,
            batch=batch,
            batch_size=batch_size,
            produces=tuple(produces),
            path_param=path_param,
            modules=modules,
            node_blocks=node_blocks,
            max_states=max_states,
            max_states_reason=max_states_reason,
            size_limit=size_limit,
            check=check,
        )

    def check_params(self, params: dict, where: str = "params") -> None:
        """Raise ValueError naming the key for an unknown hyperparameter, or one of the wrong type or out of bounds."""
        accepted = self.hyperparameters
        for key, value in params.items():
            if key not in accepted:
                known = ", ".join(accepted) or "none"
                raise ValueError(f"{where}.{key}: unknown hyperparameter for method {self.name!r} (accepts: {known})")
            accepted[key].check(value, f"{where}.{key}")

    def check_together(self, params: dict, where: str = "params") -> None:
        """Raise ValueError, prefixed by ``where``, for one run's hyperparameters that are each valid but not together.

        The method's own ``check`` (see :class:`Method`), on the hyperparameters of one run
        (a spec entry's ``params`` with one grid point); nothing for a method without one.
        """
        if self.check is None:
            return
        try:
            self.check(dict(params))
        except ValueError as exc:
            raise ValueError(f"{where}: {exc}") from None

    def _stamp(self, result, params: dict) -> list[Design]:
        designs = list(result) if isinstance(result, (list, tuple)) else [result]
        if not designs:
            # A run without a design would be stored with no status at all.
            raise RuntimeError(f"method {self.name!r} returned no design (an empty list); "
                               "a method returns a Design or a non-empty list of them")
        for d in designs:
            if not isinstance(d, Design):
                raise TypeError(f"method {self.name!r} returned {type(d).__name__}, not a Design (or a list of them)")
        # A design that names no params (e.g. from codesign.score) gets the run's.
        return [replace(d, method=self.name, params=d.params or dict(params)) for d in designs]

    def unsupported(self, instance, params: dict) -> list[Design] | None:
        """The recorded failure for an instance this method cannot handle, or None."""
        limits = [(self.max_states, self.max_states_reason, "")] if self.max_states is not None else []
        tighter = self.size_limit(instance, params) if self.size_limit is not None else None
        if tighter is not None:
            limits.append((*tighter, " here"))
        for most, reason, qualifier in limits:
            if instance.n > most:
                return [Design.failure(self.name, dict(params), FAILED,
                                       f"method {self.name!r} is not run on {instance.n} states (at most "
                                       f"{most}{qualifier}): {reason}", extras={"size_guard": True})]
        if self.node_blocks or getattr(instance, "scalar_nodes", True):
            return None
        return [Design.failure(self.name, dict(params), FAILED,
                               f"method {self.name!r} does not handle nodes with several states or inputs "
                               f"({instance.n} states and {instance.m} inputs on {instance.nodes} nodes)")]

    def __call__(self, instance, **params) -> list[Design]:
        """Designs for one instance (always a list), with the name stamped in."""
        check_instance(instance, f"method {self.name!r}")
        self.check_params(params)
        self.check_together(params)
        refused = self.unsupported(instance, params)
        if refused is not None:
            return refused
        return self._stamp(self.design(instance, **params), params)

    def run_batch(self, pairs) -> list[list[Design]]:
        """Designs for many (instance, params) pairs: one batched call if the method has one."""
        pairs = list(pairs)
        for instance, _ in pairs:
            check_instance(instance, f"method {self.name!r}")
        if self.batch is None or any(self.unsupported(instance, params) for instance, params in pairs):
            return [self(instance, **params) for instance, params in pairs]
        for _, params in pairs:
            self.check_params(params)
            self.check_together(params)
        results = self.batch(pairs)
        if len(results) != len(pairs):
            raise RuntimeError(f"{self.name}: batch returned {len(results)} results for {len(pairs)} runs")
        return [self._stamp(r, params) for r, (_, params) in zip(results, pairs)]


class _Bound:
    """``func`` with some keywords fixed; picklable, unlike a closure."""

    def __init__(self, func, bound):
        self.func, self.bound = func, bound
        self.__module__ = func.__module__

    def __call__(self, instance, **params):
        return self.func(instance, **params, **self.bound)


def _hyperparameters(func: Callable, name: str, dropped: set) -> dict:
    try:
        sig = inspect.signature(func)
    except (TypeError, ValueError):
        raise TypeError(f"method {name!r}: {func!r} is not a function with a signature") from None
    params = list(sig.parameters.values())
    positional = [p for p in params if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)]
    if len(positional) != 1 or positional[0].default is not inspect.Parameter.empty:
        raise TypeError(
            f"method {name!r}: the function must take exactly one positional argument, the instance, "
            f"then keyword-only hyperparameters (def f(instance, *, ...)); got {name}{sig}"
        )
    try:
        hints = typing.get_type_hints(func, include_extras=True)  # keep Annotated bounds
    except Exception:  # an annotation that does not resolve is treated as unchecked
        hints = {}
    docs = _param_docs(inspect.getdoc(func) or "")
    out = {}
    for p in params:
        if p.kind is not p.KEYWORD_ONLY or p.name in dropped:
            continue
        if p.default is inspect.Parameter.empty:
            raise TypeError(f"method {name!r}: hyperparameter {p.name!r} needs a default value")
        annotation = hints.get(p.name, Any)
        if annotation is Any and p.default is not None:
            annotation = _kind_of(p.default)
        out[p.name] = Hyperparameter(p.name, p.default, annotation, docs.get(p.name, ""))
    return out


def _kind_of(default):
    """The annotation implied by an unannotated default."""
    if isinstance(default, bool):
        return bool
    if isinstance(default, int):
        return int
    if isinstance(default, float):
        return float
    if isinstance(default, str):
        return str
    if isinstance(default, (list, tuple)):
        return list
    return Any


def _unwrap(hint) -> tuple[Any, tuple]:
    """``Annotated[T, *constraints]`` as ``(T, constraints)``; any other hint as ``(hint, ())``."""
    if typing.get_origin(hint) is typing.Annotated:
        inner, *metadata = typing.get_args(hint)
        return inner, tuple(c for c in metadata if hasattr(c, "allows"))
    return hint, ()


def _fits(value, hint) -> bool:
    """Whether ``value`` has the type ``hint`` names (bounds are :func:`_problem`'s)."""
    hint, _ = _unwrap(hint)
    if hint is Any or hint is inspect.Parameter.empty:
        return True
    origin = typing.get_origin(hint)
    if origin in (typing.Union, types.UnionType):
        return any(_fits(value, arg) for arg in typing.get_args(hint))
    if hint is None or hint is type(None):
        return value is None
    if origin is typing.Literal:
        return value in typing.get_args(hint)
    if hint is bool:
        return isinstance(value, bool)
    if hint is int:
        return isinstance(value, int) and not isinstance(value, bool)
    if hint is float:
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    if origin in (list, tuple) or hint in (list, tuple):
        if not isinstance(value, (list, tuple)):
            return False
        args = typing.get_args(hint)
        return not args or all(_fits(v, args[0]) for v in value)
    if origin is dict or hint is dict:
        return isinstance(value, dict)
    if isinstance(hint, type):
        return isinstance(value, hint)
    return True


def _problem(value, hint) -> tuple[str, str] | None:
    """Why ``value`` does not fit ``hint``: (key suffix such as ``"[0]"``, message), or None when it fits."""
    if not _fits(value, hint):
        return "", f"expected {_type_name(hint)}, got {type(value).__name__} {value!r}"
    hint, constraints = _unwrap(hint)
    origin = typing.get_origin(hint)
    if origin in (typing.Union, types.UnionType):
        # Of the members whose type fits, report the first one's bound.
        problems = [_problem(value, arg) for arg in typing.get_args(hint) if _fits(value, arg)]
        return None if None in problems else problems[0]
    if origin in (list, tuple) and typing.get_args(hint):
        for i, item in enumerate(value):
            problem = _problem(item, typing.get_args(hint)[0])
            if problem is not None:
                return f"[{i}]{problem[0]}", problem[1]
    if all(c.allows(value) for c in constraints):
        return None
    return "", f"must be {_requirement(hint, constraints)}, got {value!r}"


#: What a value of a constrained type is called in "must be ..." messages.
_NOUNS = {int: "an integer", float: "a finite number", str: "a string", list: "a list"}


def _requirement(hint, constraints) -> str:
    """``an integer >= 1``, ``a finite number in (0, 1]``, ``a non-empty list``, or a :class:`Matches` text."""
    for c in constraints:
        if isinstance(c, Matches):
            return c.text
    if any(isinstance(c, NotEmpty) for c in constraints):
        return "a non-empty list"
    noun = _NOUNS.get(typing.get_origin(hint) or hint, _type_name(hint))
    bounds = _bounds_text(constraints)
    return f"{noun} {bounds}" if bounds else noun


def _bounds_text(constraints) -> str:
    """``>= 1``, ``> 0``, or an interval ``in [0, 1)`` when a lower and an upper bound are both given."""
    lower = [c for c in constraints if isinstance(c, _LOWER)]
    upper = [c for c in constraints if isinstance(c, _UPPER)]
    if len(lower) == len(upper) == 1:
        low, high = lower[0], upper[0]
        return (f"in {'[' if isinstance(low, AtLeast) else '('}{low.bound:g}, "
                f"{high.bound:g}{']' if isinstance(high, AtMost) else ')'}")
    return " and ".join(str(c) for c in lower + upper)


def _type_name(hint) -> str:
    hint, constraints = _unwrap(hint)
    if hint is Any or hint is inspect.Parameter.empty:
        return "any"
    if hint is None or hint is type(None):
        return "None"
    origin = typing.get_origin(hint)
    if origin in (typing.Union, types.UnionType):
        return " or ".join(_type_name(a) for a in typing.get_args(hint))
    if origin is typing.Literal:
        return " or ".join(repr(a) for a in typing.get_args(hint))
    if origin in (list, tuple) or hint in (list, tuple):
        args = typing.get_args(hint)
        name = f"list of {_type_name(args[0])}" if args else "list"
        return f"non-empty {name}" if any(isinstance(c, NotEmpty) for c in constraints) else name
    name = getattr(hint, "__name__", str(hint))
    matches = [c.text for c in constraints if isinstance(c, Matches)]
    if matches:
        return f"{name} ({matches[0]})"
    bounds = _bounds_text(constraints)
    return f"{name} {bounds}" if bounds else name


def _param_docs(doc: str) -> dict:
    """First sentence of each parameter's description in a numpydoc ``Parameters`` section."""
    out, lines = {}, doc.splitlines()
    try:
        start = next(i for i, line in enumerate(lines) if line.strip() == "Parameters") + 2
    except StopIteration:
        return out
    names, text = [], []

    def flush():
        sentence = " ".join(text).split(". ")[0].strip().rstrip(".")
        for n in names:
            out.setdefault(n, sentence)

    for line in lines[start:]:
        if line.strip() in ("Returns", "Raises", "Notes", "Examples", "See Also") or line.startswith("---"):
            break
        if line and not line.startswith(" "):
            flush()
            names = [n.strip() for n in line.split(":")[0].split(",")]
            text = []
        elif line.strip():
            text.append(line.strip())
    flush()
    return out


_REGISTRY: dict[str, Method] = {}


def register(m: Method, *, replace_existing: bool = False) -> Method:
    """Register a :class:`Method` under its name; a second method of the same name is an error."""
    old = _REGISTRY.get(m.name)
    if old is not None and not replace_existing and old.modules != m.modules:
        raise ValueError(f"method {m.name!r} is already registered (from {', '.join(old.modules)})")
    _REGISTRY[m.name] = m
    return m


def method(
    name: str | None = None,
    *,
    label: str | None = None,
    summary: str | None = None,
    bind: dict | None = None,
    exclude: tuple = (),
    batch: Callable | None = None,
    batch_size: int = 64,
    produces: tuple = (),
    path_param: str | None = None,
    node_blocks: bool = False,
    max_states: int | None = None,
    max_states_reason: str = "",
    size_limit: Callable | None = None,
    check: Callable | None = None,
):
    """Decorator: register ``f(instance, *, ...)`` as a design method and return it unchanged.

    Parameters
    ----------
    name : str, optional
        Name in specs and on the CLI (default: the function's name).
    label : str, optional
        Legend label (default: the name).
    summary : str, optional
        One line for ``compare methods`` (default: the docstring's first line).
    bind, exclude
        Keywords fixed to a value (``bind``) or hidden (``exclude``); neither is a
        hyperparameter. Lets one function serve several methods.
    batch, batch_size, produces, path_param, node_blocks, max_states, max_states_reason, size_limit, check
        See :class:`Method`.
    """

    def decorate(func):
        register(Method.from_function(func, name=name, label=label, summary=summary, bind=bind, exclude=exclude,
                                      batch=batch, batch_size=batch_size, produces=produces,
                                      path_param=path_param, node_blocks=node_blocks,
                                      max_states=max_states, max_states_reason=max_states_reason,
                                      size_limit=size_limit, check=check))
        return func

    return decorate


def get_method(name: str) -> Method:
    """The registered method called ``name``."""
    try:
        return _REGISTRY[name]
    except KeyError:
        raise UnknownMethodError(
            f"unknown method {name!r}; registered methods: {', '.join(sorted(_REGISTRY))} "
            "(or 'module:function' / 'file.py:function' for your own)"
        ) from None


def registered_methods() -> dict[str, Method]:
    """Every registered method by name."""
    return dict(_REGISTRY)
