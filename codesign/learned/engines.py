"""Which engine trains a stack of GRNNs or GCNNs: torch's batched products or the fused numba pass.

One rule for both learned controllers: :mod:`codesign.learned.grnn_bptt` and
:mod:`codesign.learned.gcnn` (which dispatch) and :mod:`codesign.learned.fused` (which
lays out a stack's supports) read it, so it lives here, apart from all three:
importing it loads neither torch nor numba.
"""

from __future__ import annotations

import numpy as np

__all__ = ["ENGINES", "FUSED_DENSE_S", "FUSED_DENSE_NODES", "s_supports", "fused_unsupported", "resolve_engine"]

#: How a stack's loss and gradient are computed: one torch call per product and time step
#: (any node layout), or one compiled pass per model (:mod:`codesign.learned.fused`, numba; one state
#: and one input per node); "auto" takes "fused" where it applies and is faster (resolve_engine).
ENGINES = ("torch", "fused", "auto")


#: The fused engine multiplies by S dense where its support is more than this full, and only
#: up to this many nodes (its loops over nodes unroll); beyond, a full S makes it slower than
#: torch's batched products (docs/performance.md), so "auto" leaves such stacks to torch.
FUSED_DENSE_S, FUSED_DENSE_NODES = 0.5, 32


def s_supports(S0: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Where each model's S can be nonzero, (M, N, N): its mask, or the nonzeros of S0 if S is frozen."""
    trainable = mask.any(axis=(1, 2))
    return np.where(trainable[:, None, None], mask, S0 != 0)


def fused_unsupported(*, states_per_node: int = 1, inputs_per_node: int = 1, readout: str = "shared",
                      unit_weights: bool = True) -> str | None:
    """What keeps a model off the fused kernels, as the end of a sentence; None where they apply.

    Both kernels (the GRNN's and the GCNN's) take one state and one input per node
    and read one readout for every node; the GCNN's also takes Q = R = I
    (``unit_weights``), which the GRNN's does not need.
    """
    if not states_per_node == inputs_per_node == 1:
        return (f"needs one state and one input per node, this model has {states_per_node} and "
                f"{inputs_per_node}")
    if readout != "shared":
        return f"supports readout 'shared' only, got readout {readout!r}"
    if not unit_weights:
        return "needs Q = R = I"
    return None


def resolve_engine(engine: str, *, unsupported: str | None = None, nodes: int = 0,
                   support_density: float = 0.0) -> str:
    """The engine that runs, for both learned controllers: ``engine`` itself, or for "auto" the faster one.

    ``unsupported`` is :func:`fused_unsupported`'s answer for the model. "auto"
    takes "fused" wherever it applies, unless the model has more than
    ``FUSED_DENSE_NODES`` nodes and products with S more than ``FUSED_DENSE_S``
    full (``support_density``: the GRNN's largest fraction of nonzeros in S's
    support; the GCNN's kernel multiplies by S dense, 1.0). "fused" where it does
    not apply is an error that says why.
    """
    if engine not in ENGINES:
        raise ValueError(f"engine must be one of {ENGINES}, got {engine!r}")
    if engine == "fused" and unsupported is not None:
        raise ValueError(f"engine 'fused' {unsupported}; use engine 'torch' or 'auto'")
    if engine == "auto":
        dense_and_large = nodes > FUSED_DENSE_NODES and support_density > FUSED_DENSE_S
        return "fused" if unsupported is None and not dense_and_large else "torch"
    return engine
