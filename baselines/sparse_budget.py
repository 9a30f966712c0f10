"""Sparse static gains at exact link budgets: gradient support pursuit with hard thresholding.

The ℓ1 paths (:mod:`baselines.sparse_admm`, :mod:`baselines.sparse_delayed`) visit
whatever link counts their γ grid happens to produce. This method answers the other
question, "the best static gain with at most L links", for every L on a grid, so
that a linear design sits at exactly the link counts another method used.

For each budget L (largest first) the pattern is searched by gradient support
pursuit (GraSP: Bahmani, Raj & Boufounos, JMLR 2013; used for sparse wide-area
control by Lian, Chakrabortty, Wu & Duel-Hallen, 2018), with the exact benchmark
cost ``J(K) / trace(P)`` as the objective and whole node links as the atoms:

1. start from the best of two patterns, each polished on the exact cost: the L
   largest links of the dense gain (LQR's for the instantaneous information model,
   the polished dense delayed gain for the delayed one) and the L largest links of
   the previous, larger budget's design;
2. merge the pattern with the 2L links whose gradient blocks are largest, polish on
   the union, keep its L largest links, polish on them; repeat while the pattern
   changes and the cost falls (at most ``rounds`` times);
3. keep the best polished pattern seen (stabilizing first, then cost).

Every pattern includes each node's own block (local feedback needs no link), links
are counted between nodes and only from nodes that have an actuator. Polishing is
the same L-BFGS on the exact cost as the other sparse methods (:func:`polish_gain`,
:func:`baselines.sparse_delayed.polish_delayed`) inside the same stabilizing search
(:mod:`baselines.stabilizing`: where the minimum from a start does not stabilize, it
goes on from the decentralized gain and its own starts), so the result at L is never
worse than truncating the dense gain to L links and polishing. At budget 0 the start
is the best diagonal gain. The search is a heuristic:
the best pattern with L links is a combinatorial problem (see ``best_pattern``).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Annotated, Literal

import numpy as np

from codesign.design import Design, Timer
from codesign.evaluation import spectral_radius, static_gain_cost_and_grad
from codesign.methods import AtLeast, NotEmpty, method
from codesign.status import USABLE

from ._sparse import DecentralizedCache, as_path_point, gain_design, polished_gain
from .sparse_admm import MAX_STATES as ADMM_MAX_STATES
from .sparse_admm import MAX_STATES_REASON as ADMM_MAX_STATES_REASON
from .sparse_admm import sparse_admm
from .sparse_delayed import Nodes as DelayedNodes
from .sparse_delayed import delayed_gain_cost_and_grad, stabilizing_delayed
from .sparse_delayed import delayed_gain_design as delayed_design
from .stabilizing import is_stable

__all__ = ["sparse_budget", "budget_grid", "admissible_links"]

INFO_MODELS = ("instantaneous", "delayed")


def budget_grid(instance) -> list[int]:
    """The default budgets: 0, then 10 counts log-spaced up to every admissible link (largest first)."""
    most = int(admissible_links(instance).sum())
    return sorted({int(round(x)) for x in np.geomspace(1, max(most, 1), 10)} | {0, most}, reverse=True)


def admissible_links(instance) -> np.ndarray:
    """(N, N) node links a gain can have: off the diagonal, from nodes that have an input."""
    actuated = np.zeros(instance.nodes, dtype=bool)
    actuated[instance.input_nodes] = True
    return actuated[:, None] & ~np.eye(instance.nodes, dtype=bool)


def check_budgets(budgets, most: int) -> list[int]:
    """The distinct link budgets, largest first; each an integer between 0 and ``most`` (the admissible links)."""
    checked = set()
    for count in budgets:
        if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or not 0 <= count <= most:
            raise ValueError(f"links must be integers between 0 and {most} (the admissible links), got {count!r}")
        checked.add(int(count))
    return sorted(checked, reverse=True)


def _largest(sizes, admissible, count: int) -> np.ndarray:
    """The ``count`` admissible node links of largest size (ties by position), as an (N, N) mask."""
    flat = np.flatnonzero(admissible)
    order = flat[np.argsort(-sizes.ravel()[flat], kind="stable")[:count]]
    mask = np.zeros(admissible.shape, dtype=bool)
    mask.ravel()[order] = True
    return mask


class _Instantaneous:
    """``u = K x``: the gain, its polish on a node pattern, its gradient's link sizes, its design."""

    def __init__(self, instance):
        self.instance = instance
        self.decentral = DecentralizedCache(instance)

    def local_start(self):
        """The best diagonal gain (LQR's gain where none is found), no links."""
        start = self.decentral.get().controller
        return start.K if start is not None else self.instance.K_lqr

    def dense(self):
        return self.instance.K_lqr

    def path(self):
        """Gains of the ℓ1 ADMM path (:func:`baselines.sparse_admm`), a start for every budget."""
        return [d.controller.K for d in sparse_admm(self.instance) if d.status in USABLE]

    def grad_sizes(self, K):
        return self.instance.block_norms(static_gain_cost_and_grad(self.instance, K)[1])

    def entries(self, links):
        return self.instance.expand_blocks(links | np.eye(self.instance.nodes, dtype=bool))

    def sizes(self, K):
        return self.instance.block_norms(K)

    def polish(self, K, links):
        """Polish on ``links`` (and the own blocks): the stabilizing search from ``K``, then its fallbacks."""
        gain, extras = polished_gain(self.instance, K, self.entries(links), decentral=self.decentral)
        cost, grad = static_gain_cost_and_grad(self.instance, gain)
        stable = is_stable(spectral_radius(self.instance.A + self.instance.B @ gain), self.instance)
        return gain, cost, stable, self.instance.block_norms(grad), extras

    def design(self, K, params, extras):
        return gain_design(self.instance, "sparse_budget", params, K, seconds=0.0, extras=extras, polished=True)


class _Delayed:
    """``u(t) = K_l x(t) + K_d x(t - 1)`` (:mod:`baselines.sparse_delayed`): links are K_d's node blocks."""

    def __init__(self, instance):
        self.instance = instance
        self.nodes = DelayedNodes(instance)
        self.decentral = DecentralizedCache(instance)

    def local_start(self):
        """The best diagonal gain (stabilizing where one exists, else LQR's diagonal) with no links."""
        start = self.decentral.get().controller
        local = self.nodes.local_matrix(self.nodes.local(start.K if start is not None else self.instance.K_lqr))
        return local, np.zeros_like(local)

    def dense(self):
        local, zero = self.local_start()
        return stabilizing_delayed(self.instance, local, zero, self.nodes.off, decentral=self.decentral).gain

    def path(self):
        """Gains of the delayed ℓ1 path (:func:`baselines.sparse_delayed`), a start for every budget."""
        from .sparse_delayed import sparse_delayed

        return [(d.controller.K_local, d.controller.K_delayed) for d in sparse_delayed(self.instance)
                if d.status in USABLE]

    def sizes(self, gain):
        return self.nodes.norms(gain[1])

    def grad_sizes(self, gain):
        return self.nodes.norms(delayed_gain_cost_and_grad(self.instance, gain[0], gain[1])[2])

    def polish(self, gain, links):
        """Polish on ``links`` (and the local part): the stabilizing search from ``gain``, then its fallbacks."""
        free = self.instance.expand_blocks(links) & self.nodes.off
        found = stabilizing_delayed(self.instance, gain[0], gain[1], free, decentral=self.decentral)
        (local, K_delayed), result = found.gain, found.result
        _, _, grad = delayed_gain_cost_and_grad(self.instance, local, K_delayed)
        extras = {"polish_iterations": result.iterations, "polish_message": result.message}
        if found.tried > 1:
            extras.update(polish_start=found.start, polish_starts=found.tried)
        return (local, K_delayed), result.cost, found.stable, self.nodes.norms(grad), extras

    def design(self, gain, params, extras):
        free = self.nodes.pattern(gain[1])
        return delayed_design(self.instance, params, self.nodes.local(gain[0]), gain[1], extras=extras, free=free)


def gain_model(instance, info_model: str):
    """The static gain of ``info_model`` on ``instance``, as the budget searches use it."""
    if info_model not in INFO_MODELS:
        raise ValueError(f"info_model must be one of {INFO_MODELS}, got {info_model!r}")
    return _Instantaneous(instance) if info_model == "instantaneous" else _Delayed(instance)


def _start(model, admissible, budget: int, gain):
    """A start's pattern with ``budget`` links: its largest links, or all of them and the links of largest gradient."""
    sizes = model.sizes(gain)
    links = (sizes > 0) & admissible
    if links.sum() >= budget:
        return _largest(sizes, links, budget)
    return links | _largest(model.grad_sizes(gain), admissible & ~links, budget - int(links.sum()))


def _pursue(model, admissible, budget: int, starts, rounds: int):
    """GraSP from the best of ``starts`` (gains): the best polished pattern seen, and the rounds that improved on it."""
    def polished(gain, links):
        new, cost, stable, grad_sizes, extras = model.polish(gain, links)
        return {"gain": new, "links": links, "cost": cost, "stable": stable, "grad": grad_sizes, "extras": extras}

    def better(a, b):
        return (not a["stable"], a["cost"]) < (not b["stable"], b["cost"])

    best, seen = None, []
    for gain in starts:
        links = _start(model, admissible, budget, gain)
        if any(np.array_equal(links, other) for other in seen):
            continue
        seen.append(links)
        candidate = polished(gain, links)
        if best is None or better(candidate, best):
            best = candidate
    current, used = best, 0
    for _ in range(rounds if 0 < budget < admissible.sum() else 0):
        grad = np.where(current["links"], 0.0, current["grad"])
        merged = current["links"] | _largest(grad, admissible, 2 * budget)
        wide = polished(current["gain"], merged)
        links = _largest(model.sizes(wide["gain"]), admissible, budget)
        if np.array_equal(links, current["links"]):
            break
        candidate = polished(wide["gain"], links)
        if not better(candidate, current):
            break
        current, used = candidate, used + 1
        if better(current, best):
            best = current
    return best, used


@method("sparse_budget", label="Sparse K at exact budgets (GraSP)", node_blocks=True, max_states=ADMM_MAX_STATES,
        max_states_reason=f"it starts from the l1 ADMM path: {ADMM_MAX_STATES_REASON}")
def sparse_budget(
    instance,
    *,
    links: Annotated[list[Annotated[int, AtLeast(0)]], NotEmpty()] | None = None,
    info_model: Literal[INFO_MODELS] = "instantaneous",
    rounds: Annotated[int, AtLeast(0)] = 5,
    seed: Annotated[int, AtLeast(0)] = 0,
) -> list[Design]:
    """The best static gain found with at most L links, for every budget L (gradient support pursuit).

    Parameters
    ----------
    instance : Instance
    links : list of int, optional
        Link budgets (node links, counted between nodes); by default 0, every admissible
        link, and 10 counts log-spaced between (:func:`budget_grid`). A budget above the
        admissible links (N (N - 1) with an actuator at every node) is refused.
    info_model : {"instantaneous", "delayed"}
        ``u = K x`` (every link delivers its state at once), or the delayed gain of
        :mod:`baselines.sparse_delayed` (own state now, a linked neighbour's one step late).
    rounds : int
        Support-pursuit rounds per budget after the start (0: the best of the two
        truncations, polished).
    seed : int
        Accepted for a uniform interface; the method draws no random numbers.

    Returns
    -------
    list of Design
        One per distinct budget, largest first: ``params = {"budget", "info_model", "rounds"}``,
        ``links <= budget``, exact cost; extras ``solver`` ("grasp"), ``pursuit_rounds``
        (rounds that moved to a better pattern), the polish's iterations and message. A gain
        that does not stabilize is recorded ``diverged``; budget 0 is the decentralized
        gain.
    """
    admissible = admissible_links(instance)
    checked = check_budgets(budget_grid(instance) if links is None else links, int(admissible.sum()))
    model = gain_model(instance, info_model)
    with Timer() as timer:
        dense, path = model.dense(), model.path()
    designs, previous = [], None
    for budget in checked:  # largest first: each warm-starts the next
        params = {"budget": budget, "info_model": info_model, "rounds": int(rounds)}
        with Timer() as step:
            diagonal = model.decentral.usable()
            if budget == 0 and info_model == "instantaneous" and diagonal is not None:
                design = as_path_point(diagonal, "sparse_budget", params, {"solver": "decentralized"})
            else:
                # The ℓ1 path's design with the most links within the budget (its pattern, extended by
                # gradient to the budget) makes the result at least as good as the path at its own counts.
                within = [g for g in path if (model.sizes(g) > 0)[admissible].sum() <= budget]
                starts = [dense] + ([previous] if previous is not None else []) + within[:1]
                if budget == 0:
                    # Every start has the same (empty) pattern and only the first is polished: make it the
                    # best local gain, so that this end is the decentralized gain, as documented.
                    starts = [model.local_start()]
                best, used = _pursue(model, admissible, budget, starts, int(rounds))
                design = model.design(best["gain"], params, {"solver": "grasp", "pursuit_rounds": used,
                                                             **best["extras"]})
                if design.status in USABLE:
                    previous = best["gain"]
        seconds = step.seconds + (timer.seconds if not designs else 0.0)  # the dense gain: the first budget's
        designs.append(replace(design, seconds=float(seconds)))
    return designs
