"""Centralized LQR, the autonomous system, and the best decentralized static gain."""

from __future__ import annotations

from typing import Literal

import numpy as np

from codesign.controllers import StaticGain, ZeroInput
from codesign.design import Design, Timer, count_links
from codesign.evaluation import spectral_radius, static_gain_cost
from codesign.instances import check_instance
from codesign.methods import method
from codesign.status import DIVERGED, FAILED, INACCURATE, OPTIMAL

from .polish import GRAD_RTOL
from .stabilizing import EXHAUSTIVE_STATES, is_stable, stabilizing_gain, unstable_note

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
    radius = spectral_radius(instance.A + instance.B @ K)
    if not is_stable(radius, instance):  # the DARE gain stabilizes a stabilizable plant; a numerical one may not
        return Design.failure("lqr", {}, DIVERGED,
                              f"the LQR gain does not stabilize: {unstable_note(radius, instance=instance)}",
                              info_model="instantaneous", seconds=timer.seconds, links=links,
                              self_loops=self_loops, extras={"spectral_radius": radius})
    return Design(
        method="lqr",
        params={},
        controller=StaticGain(K),
        cost=static_gain_cost(instance, K),
        links=links,
        self_loops=self_loops,
        info_model="instantaneous",
        seconds=timer.seconds,
        extras={"spectral_radius": radius},
    )


@method("autonomous", label="Autonomous (u = 0)", node_blocks=True)
def autonomous(instance) -> Design:
    """No control, ``u = 0``: the open-loop cost, with zero links.

    The reference "no control" cost, so it is reported wherever it is finite, an unstable
    plant included (the finite-horizon cost of an unstable open loop is a number). Where
    the open loop grows too fast for the cost to be represented (``a_norm = 1e6``, say),
    the design is ``diverged``.
    """
    check_instance(instance, "autonomous")
    radius = instance.open_loop_radius
    extras = {"spectral_radius": radius}
    with np.errstate(over="ignore", invalid="ignore"):
        cost = static_gain_cost(instance, np.zeros((instance.m, instance.n)))
    if not np.isfinite(cost):
        status = DIVERGED if not is_stable(radius, instance) else FAILED
        return Design.failure("autonomous", {}, status,
                              f"the open-loop cost is {cost} (open-loop spectral radius {radius:.6g})",
                              extras=extras)
    return Design(
        method="autonomous",
        params={},
        controller=ZeroInput(instance.n, instance.m),
        cost=cost,
        links=0,
        self_loops=0,
        info_model="none",
        extras=extras,
    )


@method("decentralized", label="Decentralized (diagonal K)", node_blocks=True)
def decentralized(instance, *, start: Literal["lqr_diagonal", "zero"] = "lqr_diagonal") -> Design:
    """Best diagonal static gain ``u_i = k_i x_i`` found for the benchmark cost (zero links).

    Minimizes the exact normalized finite-horizon cost over the diagonal of K
    (L-BFGS, exact gradient); where nodes have several states or inputs, over the
    block-diagonal gains that map each node's states to its own inputs. The cost is
    not convex and is finite for unstable gains too, so L-BFGS runs from several starts
    (:mod:`baselines.stabilizing`): every one up to
    :data:`~baselines.stabilizing.EXHAUSTIVE_STATES` states, keeping the lowest-cost
    stabilizing minimum; above, until the first that stabilizes. A design whose gain
    does not stabilize (none of the starts found one) is ``diverged``.

    Parameters
    ----------
    instance : Instance
    start : {"lqr_diagonal", "zero"}
        The first start: the diagonal of the LQR gain, or zero. The search's other
        starts follow; the first start's minimum is kept unless another is lower.
    """
    check_instance(instance, "decentralized")
    if start not in ("lqr_diagonal", "zero"):
        raise ValueError(f"start must be 'lqr_diagonal' or 'zero', got {start!r}")
    params = {"start": start}
    mask = instance.block_mask()
    K0 = np.where(mask, instance.K_lqr, 0.0) if start == "lqr_diagonal" else np.zeros(mask.shape)
    with Timer() as timer:
        found = stabilizing_gain(instance, mask, [(start, K0)], exhaustive=instance.n <= EXHAUSTIVE_STATES)
    result = found.result
    links, self_loops = count_links(instance.node_support(result.K))
    extras = {"spectral_radius": found.radius, "grad_norm": result.grad_norm, "iterations": result.iterations,
              "search_start": found.start, "search_starts": found.tried}
    if not found.stable:
        return Design.failure("decentralized", params, DIVERGED,
                              f"no stabilizing diagonal gain found from {found.tried} starts (the least unstable, "
                              f"from {found.start}: {unstable_note(found.radius, instance=instance)})",
                              info_model="none", seconds=timer.seconds, extras=extras)
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
