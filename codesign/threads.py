"""Torch held at one thread where numpy and torch alternate on small arrays.

Two pools serve this code in a plain Python process (a notebook): numpy's OpenBLAS
and torch's OpenMP, each sized to the machine. Where a loop alternates between them
on arrays too small to share out, as a rollout of a learned controller does at every
step, the threads of the idle pool spin-wait on the cores the busy one needs, and the
loop slows down by up to an order of magnitude (measured on 2 cores:
``benchmarks/bench_rollout_threads.py``). The harness's workers run every pool at one
thread already (``compare.run.execution``); :func:`one_torch_thread` gives a notebook the
same speed and gives the pool back after. Elementwise results do not depend on the
pool size.
"""

from __future__ import annotations

import sys
from contextlib import contextmanager

__all__ = ["one_torch_thread"]


@contextmanager
def one_torch_thread():
    """Torch's intra-op pool at one thread for the duration, if torch is loaded.

    For rollouts: numpy products of the plant with a controller's torch calls (the
    GRNN's tanh, the GCNN's layers) at every step. On 2 cores a GRNN's 2000-draw
    rollout at N = 20 took 0.71 s with both pools at two threads, 0.068 s with torch at
    one (N = 100: 1.03 s and 0.48 s; the GCNN 0.40 and 0.12 s at N = 20).
    """
    torch = sys.modules.get("torch")
    before = torch.get_num_threads() if torch is not None else 1
    if before == 1:
        yield
        return
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(before)
