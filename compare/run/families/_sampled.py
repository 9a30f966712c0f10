"""What the families sampled from continuous-time models share (mass_spring, random_network)."""

from __future__ import annotations

import numpy as np

from ..parsing import SpecError, list_of, typed

#: Entries of the discretized A and B below this fraction of their largest are set to zero:
#: the matrix exponential couples every pair of states, mostly by rounding-level amounts.
CUTOFF = 1e-9


def zoh(Ac, Bc, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Zero-order-hold discretization (:func:`scipy.signal.cont2discrete`), entries below :data:`CUTOFF` dropped."""
    from scipy.signal import cont2discrete

    n, m = np.shape(Bc)
    A, B, *_ = cont2discrete((Ac, Bc, np.eye(n), np.zeros((n, m))), dt, method="zoh")
    return (np.where(np.abs(A) >= CUTOFF * np.abs(A).max(), A, 0.0),
            np.where(np.abs(B) >= CUTOFF * np.abs(B).max(), B, 0.0))


def parse_sampling(table: dict, *, noun: str, dt: float) -> tuple[tuple, float, int]:
    """The keys every sampled family has: sizes ``n`` (>= 2 ``noun``), sampling time ``dt`` and ``horizon``."""
    sizes = list_of("instances.n", table.get("n", [20]), int)
    if any(n < 2 for n in sizes):
        raise SpecError(f"instances.n: at least 2 {noun}, got {list(sizes)}")
    dt = typed("instances.dt", table.get("dt", dt), float)
    horizon = typed("instances.horizon", table.get("horizon", 50), int)
    if not dt > 0:
        raise SpecError(f"instances.dt: must be positive, got {dt}")
    if horizon < 1:
        raise SpecError(f"instances.horizon: must be >= 1, got {horizon}")
    return sizes, dt, horizon
