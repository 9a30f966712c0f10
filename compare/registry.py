"""The method registry: every design method the harness can run, by name.

A method is a function ``f(instance, *, **hyperparameters)`` returning a
:class:`codesign.Design` or a list of them (a path, e.g. one per regularization
weight). Adding a method is one module plus one :func:`register` line below.
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass
from typing import Callable

import baselines
import codesign

__all__ = ["Method", "register", "get_method", "methods", "UnknownMethodError"]


class UnknownMethodError(KeyError):
    def __str__(self):
        return str(self.args[0])


@dataclass(frozen=True)
class Method:
    """A registered method: its name, function, one-line summary and legend label.

    ``batch``, when given, designs many (instance, hyperparameters) pairs in one
    call (``batch(pairs) -> list of Design or list of Design``, one entry per
    pair, in order); the runner then hands it up to ``batch_size`` runs at once,
    so that e.g. many GRNNs train together as one batched program.
    """

    name: str
    func: Callable
    summary: str
    label: str
    batch: Callable | None = None
    batch_size: int = 64

    @property
    def hyperparameters(self) -> dict[str, inspect.Parameter]:
        """Keyword-only hyperparameters and their defaults."""
        sig = inspect.signature(self.func)
        return {p.name: p for p in sig.parameters.values() if p.kind is inspect.Parameter.KEYWORD_ONLY}

    def check_params(self, params: dict, where: str = "params") -> None:
        """Raise ValueError naming the key for an unknown or mistyped hyperparameter."""
        accepted = self.hyperparameters
        for key, value in params.items():
            if key not in accepted:
                known = ", ".join(accepted) or "none"
                raise ValueError(
                    f"{where}.{key}: unknown hyperparameter for method {self.name!r} (accepts: {known})"
                )
            default = accepted[key].default
            if default is inspect.Parameter.empty or default is None:
                continue
            if not _same_kind(default, value):
                raise ValueError(
                    f"{where}.{key}: expected {type(default).__name__} like the default {default!r}, "
                    f"got {type(value).__name__} {value!r}"
                )

    def __call__(self, instance, **params):
        return _as_list(self.func(instance, **params))

    def run_batch(self, pairs) -> list[list]:
        """Designs for many (instance, params) pairs: one batched call if the method has one."""
        if self.batch is None:
            return [self(instance, **params) for instance, params in pairs]
        results = self.batch(list(pairs))
        if len(results) != len(pairs):
            raise RuntimeError(f"{self.name}: batch returned {len(results)} results for {len(pairs)} runs")
        return [_as_list(r) for r in results]


def _as_list(result) -> list:
    return list(result) if isinstance(result, (list, tuple)) else [result]


def _same_kind(default, value) -> bool:
    if isinstance(default, bool) or isinstance(value, bool):
        return isinstance(default, bool) and isinstance(value, bool)
    if isinstance(default, int):
        return isinstance(value, int)
    if isinstance(default, float):
        return isinstance(value, (int, float))
    if isinstance(default, str):
        return isinstance(value, str)
    if isinstance(default, (list, tuple)):
        return isinstance(value, (list, tuple))
    return True


_REGISTRY: dict[str, Method] = {}


def register(
    name: str,
    func: Callable,
    *,
    label: str | None = None,
    summary: str | None = None,
    batch: Callable | None = None,
    batch_size: int = 64,
) -> Method:
    """Register ``func`` under ``name`` (the name used in specs and the CLI).

    ``batch`` optionally designs many (instance, params) pairs in one call; see :class:`Method`.
    """
    doc = inspect.getdoc(func) or ""
    method = Method(name, func, summary or (doc.splitlines()[0] if doc else ""), label or name, batch, batch_size)
    _REGISTRY[name] = method
    return method


def get_method(name: str) -> Method:
    try:
        return _REGISTRY[name]
    except KeyError:
        raise UnknownMethodError(
            f"unknown method {name!r}; registered methods: {', '.join(sorted(_REGISTRY))}"
        ) from None


def methods() -> dict[str, Method]:
    """All registered methods by name."""
    return dict(_REGISTRY)


register("lqr", baselines.lqr, label="LQR (centralized)")
register("autonomous", baselines.autonomous, label="Autonomous (u = 0)")
register("decentralized", baselines.decentralized, label="Decentralized (diagonal K)")
register("sls", baselines.sls, label="SLS (delay constraints)")
register("sls_topologies", baselines.sls_topologies, label="SLS (topology family)")
register("sparse_admm", baselines.sparse_admm, label="Sparse K (l1 ADMM)")
register("sparse_sdp", baselines.sparse_sdp, label="Sparse K (l1 SDP)")
register("truncated_lqr", baselines.truncated_lqr, label="Truncated LQR K")
for _name, _variant, _label in (("grnn", "given", "GRNN"), ("grnn_dense", "dense", "GRNN-Dense"),
                                 ("grnn_fixed", "fixed", "GRNN-Fixed"), ("grnn_sparse", "sparse", "GRNN-Sparse")):
    _func = codesign.grnn_method(_variant)
    register(_name, _func, label=_label, batch=_func.batch, batch_size=25)
register("gcnn", baselines.gcnn, label="GCNN", batch=baselines.gcnn.batch, batch_size=25)
