"""Centralized LQR, the autonomous system, and the best decentralized static gain."""

from __future__ import annotations

import numpy as np

from codesign.controllers import StaticGain, ZeroInput
from codesign.design import Design, count_links
from codesign.evaluation import spectral_radius, static_gain_cost
from codesign.methods import method

from ._common import Timer
from .polish import polish_gain

__all__ = ["lqr", "autonomous", "decentralized"]


@method("lqr", label="LQR (centralized)")
def lqr(instance) -> Design:
    """Centralized LQR ``u = K x``, ``K = -(R + B'PB)^{-1} B'PA``.

    It needs every state at every node with no delay: N(N-1) instantaneous links.
    Its normalized cost is 1 by construction of the terminal cost P.
    """
    with Timer() as timer:
        K = np.array(instance.K_lqr)
    n = instance.n
    return Design(
        method="lqr",
        params={},
        controller=StaticGain(K),
        cost=static_gain_cost(instance, K),
        links=n * (n - 1),
        self_loops=n,
        info_model="instantaneous",
        seconds=timer.seconds,
        extras={"spectral_radius": spectral_radius(instance.A + instance.B @ K)},
    )


@method("autonomous", label="Autonomous (u = 0)")
def autonomous(instance) -> Design:
    """No control, ``u = 0``: the open-loop cost, with zero links."""
    return Design(
        method="autonomous",
        params={},
        controller=ZeroInput(instance.n),
        cost=static_gain_cost(instance, np.zeros((instance.n, instance.n))),
        links=0,
        self_loops=0,
        info_model="none",
        extras={"spectral_radius": instance.open_loop_radius},
    )


@method("decentralized", label="Decentralized (diagonal K)")
def decentralized(instance, *, start: str = "lqr_diagonal") -> Design:
    """Best diagonal static gain ``u_i = k_i x_i`` for the benchmark cost (zero links).

    Minimizes the exact normalized finite-horizon cost over the diagonal of K
    (L-BFGS, exact gradient).

    Parameters
    ----------
    instance : Instance
    start : {"lqr_diagonal", "zero"}
        Where L-BFGS starts: the diagonal of the LQR gain, or zero.
    """
    if start not in ("lqr_diagonal", "zero"):
        raise ValueError(f"start must be 'lqr_diagonal' or 'zero', got {start!r}")
    params = {"start": start}
    n = instance.n
    K0 = np.diag(np.diag(instance.K_lqr)) if start == "lqr_diagonal" else np.zeros((n, n))
    with Timer() as timer:
        result = polish_gain(instance, K0, np.eye(n, dtype=bool))
    radius = spectral_radius(instance.A + instance.B @ result.K)
    links, self_loops = count_links(result.K)
    extras = {"spectral_radius": radius, "grad_norm": result.grad_norm, "iterations": result.iterations}
    if not np.isfinite(result.cost):
        return Design.failure("decentralized", params, "failed", f"optimizer diverged: {result.message}",
                              info_model="none", seconds=timer.seconds, extras=extras)
    status, message = "optimal", ""
    if not result.success:
        status, message = "inaccurate", f"L-BFGS stopped early: {result.message}"
    return Design(
        method="decentralized",
        params=params,
        controller=StaticGain(result.K),
        cost=result.cost,
        links=links,
        self_loops=self_loops,
        info_model="none",
        status=status,
        message=message,
        seconds=timer.seconds,
        extras=extras,
    )
