"""The best sparsity pattern found by trying them all: a yardstick for the sparse heuristics on small systems.

For every budget L, every pattern of exactly L node links (up to the instance's
symmetries) is polished on the exact benchmark cost from several starts, and the
best is kept. More links never hurt a pattern's optimum, so the best with exactly L
links is the best with at most L. The polish is the same L-BFGS on the exact cost
as every sparse method's (:func:`baselines.polish_gain`, or
:func:`baselines.sparse_delayed.polish_delayed` for the delayed information
model), which is non-convex in the gain: the result is the best pattern *found*,
not a certificate. Each design records after how many starts its value stopped
changing (``starts_to_best``); where that is the last start, more starts may lower it.

Starts, for each pattern: the dense gain restricted to the pattern (LQR's, or the
polished dense delayed gain), the decentralized gain with the links at zero, and
``starts - 2`` random perturbations of the first (seeded). Each polish is the shared
stabilizing search (:mod:`baselines.stabilizing`) from that start: where its minimum
does not stabilize, the search goes on from the decentralized gain and its own starts,
so a pattern is unstable (``diverged``) only when none of them stabilizes.

Symmetries: on one-state-one-input instances, node permutations that map A, B, Q,
R and the given graph onto themselves (the chain's reversal, say) map a pattern to
one of equal cost; only one pattern per orbit is polished. Random instances have
none.

The number of patterns grows as the binomial coefficient of the admissible links:
the method refuses at once (before any polish) a request above ``max_patterns``
patterns, naming the largest budget that fits.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import replace
from typing import Annotated, Literal

import numpy as np

from codesign.design import Design, Timer
from codesign.methods import AtLeast, NotEmpty, method

from .sparse_budget import INFO_MODELS, admissible_links, check_budgets, gain_model

__all__ = ["best_pattern", "automorphisms"]


def automorphisms(instance) -> list[np.ndarray]:
    """Node permutations p (as index arrays) with A, B, Q, R and the given graph invariant; scalar nodes only.

    The identity first. On instances whose nodes hold several states or inputs only
    the identity is returned (no reduction).
    """
    N = instance.nodes
    identity = np.arange(N)
    if not instance.scalar_nodes or N > 8:
        return [identity]
    mats = [instance.A, instance.B, instance.Q, instance.R, np.asarray(instance.comm_adj, dtype=float)]
    found = [identity]
    for perm in itertools.permutations(range(N)):
        p = np.array(perm)
        if np.array_equal(p, identity):
            continue
        if all(np.allclose(M[np.ix_(p, p)], M, rtol=0, atol=1e-12 * max(1.0, np.abs(M).max())) for M in mats):
            found.append(p)
    return found


def _orbit_representatives(patterns, perms, admissible):
    """One pattern (a tuple of admissible-link indices) per orbit of the permutations."""
    cells = np.flatnonzero(admissible)
    position = {c: i for i, c in enumerate(cells)}
    N = admissible.shape[0]
    maps = []
    for p in perms[1:]:
        maps.append(np.array([position[p[c // N] * N + p[c % N]] for c in cells]))
    kept = []
    for pattern in patterns:
        key = tuple(sorted(pattern))
        if all(tuple(sorted(m[list(pattern)])) >= key for m in maps):
            kept.append(pattern)
    return kept


def _fitting_budgets(most: int, max_patterns: int) -> list[int]:
    """Every budget whose patterns fit within ``max_patterns`` in all, those with fewest patterns first."""
    chosen, total = [], 0
    for L in sorted(range(most + 1), key=lambda L: (math.comb(most, L), L)):
        total += math.comb(most, L)
        if total > max_patterns:
            break
        chosen.append(L)
    return chosen


def _random_start(gain, rng, model):
    """``gain`` with its links perturbed by half its largest link block (at least 1e-3), seeded by ``rng``."""
    scale = 0.5 * max(float(np.max(model.sizes(gain))), 1e-3)
    if isinstance(gain, tuple):
        return gain[0], gain[1] + scale * rng.standard_normal(gain[1].shape)
    return gain + scale * rng.standard_normal(gain.shape)


@method("best_pattern", label="Best pattern found (exhaustive)", node_blocks=True)
def best_pattern(
    instance,
    *,
    links: Annotated[list[Annotated[int, AtLeast(0)]], NotEmpty()] | None = None,
    info_model: Literal[INFO_MODELS] = "instantaneous",
    starts: Annotated[int, AtLeast(1)] = 3,
    max_patterns: Annotated[int, AtLeast(1)] = 20000,
    seed: Annotated[int, AtLeast(0)] = 0,
) -> list[Design]:
    """The best polished gain over every pattern of each budget's number of links (small systems).

    Parameters
    ----------
    instance : Instance
    links : list of int, optional
        Budgets (node links); by default every budget whose patterns fit within
        ``max_patterns`` together, those with the fewest patterns first (every budget
        from 0 to all admissible links at N <= 4: 4096 patterns; at N = 8, 0-2 and 54-56).
    info_model : {"instantaneous", "delayed"}
        As in ``sparse_budget``: ``u = K x``, or own state now and linked states one step late.
    starts : int
        Polishes per pattern: the dense gain on the pattern, the decentralized gain,
        then random perturbations of the first.
    max_patterns : int
        Refuse, at once, a request that would polish more patterns than this.
    seed : int
        Seeds the random starts.

    Returns
    -------
    list of Design
        One per distinct budget, largest first: ``params = {"budget", "info_model", "starts"}``;
        extras ``patterns`` (polished, after symmetry), ``symmetries`` (automorphisms
        used), ``starts_to_best`` (the first start count at which the budget's best
        value was reached), ``certificate`` False.
    """
    admissible = admissible_links(instance)
    most = int(admissible.sum())
    checked = check_budgets(_fitting_budgets(most, max_patterns) if links is None else links, most)
    total = sum(math.comb(most, L) for L in checked)
    if total > max_patterns:
        raise ValueError(f"best_pattern: budgets {checked} on {most} admissible links take {total} patterns, more "
                         f"than max_patterns = {max_patterns} (budget L alone takes C({most}, L)); ask for fewer "
                         f"budgets or raise max_patterns")
    model = gain_model(instance, info_model)
    rng = np.random.default_rng([int(seed), 0xB357])
    perms = automorphisms(instance)
    cells = np.flatnonzero(admissible)
    with Timer() as timer:
        dense, decentral = model.dense(), model.local_start()
    designs = []
    for budget in checked:
        with Timer() as step:
            patterns = _orbit_representatives(itertools.combinations(range(cells.size), budget), perms, admissible)
            best_by_start = [None] * starts  # (key, result) of the best over patterns using starts 0..k
            best = None
            for pattern in patterns:
                mask = np.zeros(admissible.shape, dtype=bool)
                mask.ravel()[cells[list(pattern)]] = True
                initial = [dense, decentral] + [_random_start(dense, rng, model) for _ in range(starts - 2)]
                running = None
                for k, gain in enumerate(initial[:starts]):
                    new, cost, stable, _, extras = model.polish(gain, mask)
                    result = {"gain": new, "cost": cost, "stable": stable, "extras": extras}
                    key = (not stable, cost)
                    if running is None or key < running[0]:
                        running = (key, result)
                    if best_by_start[k] is None or running[0] < best_by_start[k][0]:
                        best_by_start[k] = running
                if best is None or running[0] < best[0]:
                    best = running
            final = best[0]
            reached = next(k + 1 for k, entry in enumerate(best_by_start)
                           if entry[0][0] == final[0] and entry[0][1] <= final[1] * (1 + 1e-9))
            params = {"budget": budget, "info_model": info_model, "starts": int(starts)}
            extras = {"solver": "exhaustive", "patterns": len(patterns), "symmetries": len(perms),
                      "starts_to_best": reached, "certificate": False, **best[1]["extras"]}
            design = model.design(best[1]["gain"], params, extras)
        seconds = step.seconds + (timer.seconds if not designs else 0.0)
        designs.append(replace(design, seconds=float(seconds)))
    return designs
