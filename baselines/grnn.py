"""The GRNN methods as the harness runs them: the trainer of :mod:`codesign.learned.grnn` with
its warm starts' static designs.

A warm start (``init = "diagonal" | "delayed" | "auto"``) embeds a static design of this
layer (the decentralized gain, the delayed l1 path's gain, the delayed gain polished on the
given graph) into the GRNN's first parameters. :class:`StartCache` computes those designs,
each once per instance in a batch, and :func:`grnn_batch` hands it to the trainer; the
trainer itself (``codesign``) imports nothing of this layer. The four registered methods
(``grnn``, ``grnn_dense``, ``grnn_fixed``, ``grnn_sparse``) are this module's, so that their
fingerprints cover the sources of their starts as well as the training.
"""

from __future__ import annotations

import functools

import numpy as np

from codesign.design import Design, count_links
from codesign.learned.grnn import check_settings
from codesign.learned.grnn import grnn as _trained_grnn
from codesign.learned.grnn import grnn_batch as _trained_batch
from codesign.learned.warm import StartSources, usable_source
from codesign.methods import method
from codesign.status import DIVERGED, OPTIMAL, is_stable

from ._sparse import DecentralizedCache
from .lqr import decentralized
from .sparse_delayed import DelayedStaticGain, delayed_gain_cost, sparse_delayed, stabilizing_delayed

__all__ = ["grnn", "grnn_batch", "StartCache", "MAX_STATES", "DENSE_L1_MAX_STATES"]


class StartCache(StartSources):
    """The source designs of a batch's warm starts, each computed once per instance (and γ)."""

    def __init__(self):
        self._designs: dict = {}

    def _get(self, instance, key, compute):
        full = (id(instance), key)
        if full not in self._designs:
            self._designs[full] = (instance, compute())  # the instance kept alive: its id stays its own
        return self._designs[full][1]

    def diagonal(self, instance):
        return self._get(instance, "diagonal", lambda: decentralized(instance))

    def delayed_path(self, instance, gamma: float | None):
        gamma = float(gamma or 0.0)
        if gamma == 0.0:
            return self._get(instance, ("delayed", 0.0),
                             lambda: sparse_delayed(instance, gammas=[0.0], diagonal_end=False)[0])
        dense_end, design = self._get(instance, ("delayed", gamma), lambda: tuple(
            sparse_delayed(instance, gammas=[0.0, gamma], diagonal_end=False)))
        self._designs.setdefault((id(instance), ("delayed", 0.0)), (instance, dense_end))  # the same first point
        return design

    def delayed_given(self, instance):
        return self._get(instance, ("delayed", "given"), lambda: _polished_on_graph(instance, self.diagonal(instance)))


def _polished_on_graph(instance, diagonal):
    """The delayed gain polished on the given graph's links from the diagonal gain (None without one)."""
    if not usable_source(diagonal):
        return None
    cache = DecentralizedCache(instance)
    cache._design = diagonal
    free = instance.expand_blocks(instance.comm_adj != 0) & ~instance.block_mask()
    found = stabilizing_delayed(instance, diagonal.controller.K, np.zeros((instance.m, instance.n)), free,
                                decentral=cache)
    local, K_delayed = found.gain
    nodes = {} if instance.scalar_nodes else dict(state_nodes=instance.state_nodes, input_nodes=instance.input_nodes)
    gain = DelayedStaticGain(local, K_delayed, **nodes)
    links, self_loops = count_links(instance.node_support(K_delayed + local))
    extras = {"spectral_radius": float(found.radius)}
    if not is_stable(found.radius):
        return Design.failure("sparse_delayed", {"graph": "given"}, DIVERGED, "no stabilizing delayed gain on the "
                              "given graph", info_model="delayed", extras=extras)
    return Design(method="sparse_delayed", params={"graph": "given"}, controller=gain,
                  cost=float(delayed_gain_cost(instance, local, K_delayed)), links=links, self_loops=self_loops,
                  info_model="delayed", status=OPTIMAL, cost_kind="exact", extras=extras)


def grnn_batch(jobs, *, stack_size: int = 128) -> list[Design]:
    """:func:`codesign.learned.grnn.grnn_batch` with the warm starts' sources (one :class:`StartCache`)."""
    return _trained_batch(jobs, stack_size=stack_size, sources=StartCache())


def grnn(instance, **kwargs) -> Design:
    return grnn_batch([(instance, kwargs)])[0]


# The trainer's signature, bounds and docstring (what the registry, `compare methods` and help() read).
functools.update_wrapper(grnn, _trained_grnn)
grnn.__module__ = __name__


#: Settings of the co-design (l1 stage, threshold, refinement) that only ``sparse`` uses.
_SPARSE_ONLY = ("beta", "l1_lr", "threshold", "refine_ensemble", "l1_hops")


class _VariantBatch:
    """``grnn_batch`` for one variant: trains a runner's batch of runs in shared stacks."""

    def __init__(self, variant: str):
        self.variant = variant

    def __call__(self, pairs):
        return grnn_batch([(inst, {**params, "variant": self.variant}) for inst, params in pairs])


#: Variants are refused at once above these many states. Above STRUCTURED_ABOVE states training
#: multiplies S, A and B on their supports (the fused engine) and so do the rollouts that score
#: a design, so a time step costs O(N degree h batch): at 1000 states one GRNN design on the
#: given graph took 270 s with the default settings (one thread, docs/performance.md). A dense S
#: stays O(N^2): the ``dense`` variant, and the l1 stage of ``sparse`` without ``l1_hops``.
MAX_STATES = {"given": 1000, "fixed": 1000, "sparse": 1000, "dense": 500}
#: The most states of GRNN-Sparse's l1 stage on all N^2 pairs (``l1_hops`` None).
DENSE_L1_MAX_STATES = 500
_DENSE_S_REASON = ("S is a dense N x N matrix: one design takes 416 s at 500 states with the default settings, "
                   "about 20 minutes of training at 1000, where an Adam step of one model takes 0.74 s "
                   "(its products grow like N^2)")
_MEASURED = "the largest size it has been measured at (docs/performance.md, 'A thousand nodes')"
_MAX_STATES_REASONS = {"sparse": _MEASURED, "dense": _DENSE_S_REASON, "given": _MEASURED, "fixed": _MEASURED}


def _blocks_limit(instance, params: dict):
    """Nodes with several states or inputs: the torch engine's and the rollouts' dense products."""
    if not getattr(instance, "scalar_nodes", True):
        return DENSE_L1_MAX_STATES, "on nodes with several states or inputs its products with S, A and B are dense"
    return None


def _sparse_limit(instance, params: dict):
    """GRNN-Sparse's tighter size limits: its l1 stage on all N^2 pairs (``l1_hops`` not set), node blocks."""
    if params.get("l1_hops") is None:
        return DENSE_L1_MAX_STATES, f"its l1 stage trains all N^2 pairs; {_DENSE_S_REASON}: set l1_hops " \
                                    f"(e.g. 3) to train on a few hops of the communication graph"
    return _blocks_limit(instance, params)


# One function, four methods: the variant is bound, and the co-design's own settings
# are hidden from the other variants so that a spec setting them is an error naming the key.
for _name, _variant, _label, _summary in (
    ("grnn", "given", "GRNN", "GRNN with S trained on the given communication graph (one step delay per hop)."),
    ("grnn_dense", "dense", "GRNN-Dense", "GRNN with all N^2 entries of S trained (a centralized, delayed controller)."),
    ("grnn_fixed", "fixed", "GRNN-Fixed", "GRNN with S frozen at the normalized adjacency; only F, W, G train."),
    ("grnn_sparse", "sparse", "GRNN-Sparse",
     "GRNN co-design: l1 stage on a dense S, threshold, refinement on the found support."),
):
    method(_name, label=_label, summary=_summary, bind={"variant": _variant},
           exclude=() if _variant == "sparse" else _SPARSE_ONLY, batch=_VariantBatch(_variant), batch_size=25,
           node_blocks=True,
           max_states=MAX_STATES[_variant], max_states_reason=_MAX_STATES_REASONS[_variant],
           size_limit=_sparse_limit if _variant == "sparse" else _blocks_limit,
           produces=("training_curve", "topology_path") if _variant == "sparse" else ("training_curve",),
           path_param="beta" if _variant == "sparse" else None,
           check=functools.partial(check_settings, variant=_variant))(grnn)
