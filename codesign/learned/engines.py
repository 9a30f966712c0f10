"""Which engine trains a stack of GRNNs: torch's batched products or the fused numba pass.

Both :mod:`codesign.learned.grnn_bptt` (which dispatches) and :mod:`codesign.learned.fused` (which
lays out a stack's supports) read these rules, so they live here, apart from both:
importing them loads neither torch nor numba.
"""

from __future__ import annotations

import numpy as np

__all__ = ["ENGINES", "FUSED_DENSE_S", "FUSED_DENSE_NODES", "s_supports", "resolve_engine"]

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


def resolve_engine(engine: str, states_per_node: int = 1, inputs_per_node: int = 1,
                   nodes: int = 0, support_density: float = 0.0, *, readout: str = "shared") -> str:
    """The engine that runs: ``engine`` itself, or for "auto" the faster one that applies.

    "auto" takes "fused" with one state and one input per node and the shared
    readout, unless the stack has more than ``FUSED_DENSE_NODES`` nodes and an S
    support (``support_density``, its largest fraction of nonzeros) more than
    ``FUSED_DENSE_S`` full. A per-node readout (``readout="per_node"``) trains on
    "torch" only: the fused kernels read one G for every node.
    """
    if engine not in ENGINES:
        raise ValueError(f"engine must be one of {ENGINES}, got {engine!r}")
    scalar = states_per_node == inputs_per_node == 1
    if engine == "fused" and not scalar:
        raise ValueError(f"engine 'fused' needs one state and one input per node, this stack has "
                         f"{states_per_node} and {inputs_per_node}; use engine 'torch' or 'auto'")
    if engine == "fused" and readout != "shared":
        raise ValueError(f"engine 'fused' supports readout 'shared' only, got readout {readout!r}; "
                         f"use engine 'torch' or 'auto'")
    if engine == "auto":
        dense_and_large = nodes > FUSED_DENSE_NODES and support_density > FUSED_DENSE_S
        return "fused" if scalar and readout == "shared" and not dense_and_large else "torch"
    return engine
