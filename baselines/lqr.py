"""Centralized LQR, the autonomous system, and the best decentralized static gain."""

from __future__ import annotations

from typing import Literal

import numpy as np

from codesign.controllers import StaticGain, ZeroInput
from codesign.design import Design, count_links
from codesign.evaluation import spectral_radius, static_gain_cost
from codesign.instances import check_instance
from codesign.methods import method
from codesign.status import FAILED, INACCURATE, OPTIMAL

from ._common import Timer
from .polish import GRAD_RTOL, polish_gain

__all__ = ["lqr", "autonomous", "decentralized"]


@method("lqr", label="LQR (centralized)", node_blocks=True)
def lqr(instance) -> Design:
    """Centralized LQR ``u = K x``, ``K = -(R + B'PB)^{-1} B'PA``.

    It needs every state at every node with no delay: N(N-1) instantaneous links
    between the N nodes. Its normalized cost is 1 by construction of the terminal cost P.
    """
    check_instance(instance, "lqr")
    with Timer() as timer:
        K = np.array(instance.K_lqr)
    links, self_loops = count_links(instance.node_support(K))
    return Design(
        method="lqr",
        params={},
        controller=StaticGain(K),
        cost=static_gain_cost(instance, K),
        links=links,
        self_loops=self_loops,
        info_model="instantaneous",
        seconds=timer.seconds,
        extras={"spectral_radius": spectral_radius(instance.A + instance.B @ K)},
    )


@method("autonomous", label="Autonomous (u = 0)", node_blocks=True)
def autonomous(instance) -> Design:
    """No control, ``u = 0``: the open-loop cost, with zero links."""
    check_instance(instance, "autonomous")
    return Design(
        method="autonomous",
        params={},
        controller=ZeroInput(instance.n, instance.m),
        cost=static_gain_cost(instance, np.zeros((instance.m, instance.n))),
        links=0,
        self_loops=0,
        info_model="none",
        extras={"spectral_radius": instance.open_loop_radius},
    )


@method("decentralized", label="Decentralized (diagonal K)", node_blocks=True)
def decentralized(instance, *, start: Literal["lqr_diagonal", "zero"] = "lqr_diagonal") -> Design:
    """Best diagonal static gain ``u_i = k_i x_i`` for the benchmark cost (zero links).

    Minimizes the exact normalized finite-horizon cost over the diagonal of K
    (L-BFGS, exact gradient); where nodes have several states or inputs, over the
    block-diagonal gains that map each node's states to its own inputs.

    Parameters
    ----------
    instance : Instance
    start : {"lqr_diagonal", "zero"}
        Where L-BFGS starts: the diagonal of the LQR gain, or zero.
    """
    check_instance(instance, "decentralized")
    if start not in ("lqr_diagonal", "zero"):
        raise ValueError(f"start must be 'lqr_diagonal' or 'zero', got {start!r}")
    params = {"start": start}
    mask = instance.block_mask()
    K0 = np.where(mask, instance.K_lqr, 0.0) if start == "lqr_diagonal" else np.zeros(mask.shape)
    with Timer() as timer:
        result = polish_gain(instance, K0, mask)
    radius = spectral_radius(instance.A + instance.B @ result.K)
    links, self_loops = count_links(instance.node_support(result.K))
    extras = {"spectral_radius": radius, "grad_norm": result.grad_norm, "iterations": result.iterations}
    if not np.isfinite(result.cost):
        return Design.failure("decentralized", params, FAILED, f"optimizer diverged: {result.message}",
                              info_model="none", seconds=timer.seconds, extras=extras)
    status, message = OPTIMAL, ""
    if not result.grad_norm < GRAD_RTOL * result.cost:
        status = INACCURATE
        message = (f"L-BFGS stopped at gradient norm {result.grad_norm:.3g} (> {GRAD_RTOL:g} x cost): "
                   f"{result.message}")
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
