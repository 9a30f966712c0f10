"""Controllers as the common simulator sees them.

A controller is any object with

``reset(batch) -> state``
    the internal state for ``batch`` parallel trajectories (None if memoryless);
``step(state, x) -> (u, state)``
    ``x`` and ``u`` of shape ``(batch, n)``: the input applied at this time step;
``kind`` and ``arrays()``
    a registered name and the numpy arrays that rebuild it with
    :func:`controller_from_arrays` (how the result store saves controllers,
    without pickles).

Linear controllers may also offer ``closed_loop_responses(instance)`` for exact
costs, and any controller ``rollout(instance, x0, steps) -> (costs, peaks)``: each
draw's summed stage and terminal cost (not divided by trace P) and each step's
largest ``|x|``, computed in one pass, or None where it does not apply.
:func:`~codesign.evaluation.simulate` takes it for noiseless rollouts that stay
bounded, and the step loop otherwise (the GRNN's: 2-5x faster,
``benchmarks/bench_grnn_rollout.py``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

__all__ = [
    "StaticGain",
    "ZeroInput",
    "register_controller",
    "controller_from_arrays",
]

_CONTROLLER_KINDS: dict[str, Callable[[dict], object]] = {}


def register_controller(kind: str):
    """Class decorator: make ``kind`` loadable by :func:`controller_from_arrays`.

    The class needs a ``from_arrays(arrays: dict)`` classmethod.
    """

    def decorate(cls):
        _CONTROLLER_KINDS[kind] = cls.from_arrays
        cls.kind = kind
        return cls

    return decorate


def controller_from_arrays(kind: str, arrays: dict):
    """Rebuild a stored controller from its kind and arrays."""
    try:
        factory = _CONTROLLER_KINDS[kind]
    except KeyError:
        raise ValueError(
            f"unknown controller kind {kind!r}; known: {sorted(_CONTROLLER_KINDS)}"
        ) from None
    return factory(arrays)


@register_controller("static_gain")
@dataclass(frozen=True, eq=False)
class StaticGain:
    """Memoryless linear state feedback ``u(t) = K x(t)`` (sign included in K)."""

    K: np.ndarray

    def __post_init__(self):
        K = np.array(self.K, dtype=float)
        K.setflags(write=False)
        object.__setattr__(self, "K", K)

    def reset(self, batch: int):
        return None

    def step(self, state, x):
        return x @ self.K.T, None

    def arrays(self) -> dict:
        return {"K": self.K}

    @classmethod
    def from_arrays(cls, arrays: dict) -> "StaticGain":
        return cls(arrays["K"])

    @property
    def support(self) -> np.ndarray:
        return self.K != 0

    def closed_loop(self, instance) -> np.ndarray:
        """``A + B K``."""
        return instance.A + instance.B @ self.K


@register_controller("zero")
@dataclass(frozen=True, eq=False)
class ZeroInput:
    """``u = 0``: the autonomous (open-loop) system, with n states and m inputs (m = n by default)."""

    n: int
    m: int | None = None

    @property
    def inputs(self) -> int:
        return self.n if self.m is None else self.m

    def reset(self, batch: int):
        return None

    def step(self, state, x):
        return np.zeros((x.shape[0], self.inputs)), None

    def arrays(self) -> dict:
        return {"n": np.array(self.n)} if self.m is None else {"n": np.array(self.n), "m": np.array(self.m)}

    @classmethod
    def from_arrays(cls, arrays: dict) -> "ZeroInput":
        return cls(int(arrays["n"]), int(arrays["m"]) if "m" in arrays else None)

    @property
    def K(self) -> np.ndarray:
        return np.zeros((self.inputs, self.n))
