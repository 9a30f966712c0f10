"""Truncated LQR: keep the largest entries of the LQR gain, then polish.

The naive sparse design that the ℓ1 methods must beat: for a target number of
off-diagonal links, keep the diagonal and that many largest |K_ij| of the
centralized LQR gain, and re-optimize the kept entries on the exact benchmark
cost.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Annotated

import numpy as np

from codesign.design import Design, Timer
from codesign.methods import AtLeast, NotEmpty, method

from ._sparse import DecentralizedCache, design_on_pattern

__all__ = ["truncated_lqr", "truncation_mask"]


def truncation_mask(K, links: int, instance=None) -> np.ndarray:
    """The diagonal plus the ``links`` largest off-diagonal |K_ij| (ties broken by position).

    With an ``instance`` whose nodes hold several states or inputs, entries are node
    blocks: each node's own block plus the ``links`` off-diagonal blocks of largest
    Frobenius norm.
    """
    K = np.asarray(K, dtype=float)
    blocks = instance is not None and not instance.scalar_nodes
    size = instance.block_norms(K) if blocks else np.abs(K)
    n = size.shape[0]
    off = ~np.eye(n, dtype=bool)
    if not 0 <= links <= int(off.sum()):
        raise ValueError(f"links must be between 0 and {int(off.sum())}, got {links}")
    order = np.argsort(-size[off], kind="stable")[:links]
    kept = np.zeros(int(off.sum()), dtype=bool)
    kept[order] = True
    mask = np.eye(n, dtype=bool)
    mask[off] = kept
    return instance.expand_blocks(mask) if blocks else mask


@method("truncated_lqr", label="Truncated LQR K", node_blocks=True)
def truncated_lqr(instance, *, links: Annotated[list[Annotated[int, AtLeast(0)]], NotEmpty()] | None = None,
                  polish: bool = True) -> list[Design]:
    """Sparse static gains by truncating the LQR gain to ``links`` off-diagonal entries, then polishing.

    Parameters
    ----------
    instance : Instance
    links : list of int, optional
        Off-diagonal link counts; by default 10 counts log-spaced from N(N-1) down,
        and 0 (the decentralized gain).
    polish : bool
        Re-optimize the kept entries on the exact benchmark cost.

    Returns
    -------
    list of Design
        One per link count (``params = {"links": count}``), information model
        ``instantaneous``. The polish is the stabilizing search
        (:mod:`baselines.stabilizing`) from the truncated gain; a pattern on which it
        finds no stabilizing gain is recorded as ``diverged``.
    """
    n = instance.nodes
    most = n * (n - 1)
    if links is None:
        links = sorted({int(round(x)) for x in np.geomspace(1, most, 10)} | {0}, reverse=True)
    counts = []
    for count in links:
        if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or not 0 <= count <= most:
            raise ValueError(f"links must be integers between 0 and {most}, got {count!r}")
        counts.append(int(count))
    decentral = DecentralizedCache(instance)
    designs = []
    for count in counts:
        params = {"links": count}
        with Timer() as timer:
            K = np.where(truncation_mask(instance.K_lqr, count, instance), instance.K_lqr, 0.0)
            design = design_on_pattern(instance, "truncated_lqr", params, K, extras={"solver": "truncation"},
                                       polish=polish, decentral=decentral)
        designs.append(replace(design, seconds=float(timer.seconds)))
    return designs
