"""What the fused engine's non-public numba pipeline (array arguments marked noalias) is worth.

codesign/learned/fused.py compiles its kernels with a subclass of numba's
non-public ``CompilerBase`` that marks every array argument noalias. This
measures, in one run, seconds per fused loss-and-gradient pass of a GRNN stack
(paper size: N = 20, T = 50, batch 20, h = 5, M = 16 models, one thread) with
that pipeline and with numba's default one, each in a fresh process with its own
on-disk kernel cache, and prints the ratio. The project keeps the non-public
pipeline, and pins numba to the versions it was tested with, only while this
ratio exceeds 1.10 (docs/performance.md).

    python benchmarks/bench_fused_noalias.py [--repeats 200] [--dtype float64]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile

CHILD = r"""
import sys, time
import numpy as np
import torch
torch.set_num_threads(1)
from codesign.learned import fused
if sys.argv[1] == "default":
    fused.PIPELINE = None
from codesign import paper_instance
dtype, repeats, M = np.dtype(sys.argv[2]).type, int(sys.argv[3]), 16
insts = [paper_instance(s, n=20) for s in range(M)]
stack = lambda xs: np.ascontiguousarray(np.stack(xs), dtype=dtype)
rng = np.random.default_rng(0)
S = stack([i.gso for i in insts]); mask = np.stack([i.comm_adj != 0 for i in insts])
F, W, G = (np.ascontiguousarray(rng.random(shape), dtype=dtype) for shape in ((M, 5), (M, 5, 5), (M, 5)))
engine = fused.FusedStack(stack([i.A for i in insts]), stack([i.B for i in insts]), stack([i.Q for i in insts]),
                          stack([i.R for i in insts]), stack([i.P for i in insts]), S, mask, hidden=5, horizon=50,
                          batch=20, dtype=dtype, squash=True)
x0 = np.ascontiguousarray(rng.standard_normal((M, 20, 20)), dtype=dtype)
engine.loss_and_grad(S, F, W, G, x0)  # compile
best = float("inf")
for _ in range(5):
    t = time.perf_counter()
    for _ in range(repeats // 5):
        engine.loss_and_grad(S, F, W, G, x0)
    best = min(best, (time.perf_counter() - t) / (repeats // 5))
print(best)
"""


def run(pipeline: str, dtype: str, repeats: int) -> float:
    with tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache, "OMP_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1"}
        out = subprocess.run([sys.executable, "-c", CHILD, pipeline, dtype, str(repeats)], env=env,
                             capture_output=True, text=True, check=True)
    return float(out.stdout.strip().splitlines()[-1])


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=200)
    parser.add_argument("--dtype", default="float64", choices=("float64", "float32"))
    args = parser.parse_args()
    noalias = run("noalias", args.dtype, args.repeats)
    default = run("default", args.dtype, args.repeats)
    print(f"fused loss-and-gradient pass, 16 GRNNs at N = 20, {args.dtype}, one thread (best of 5 rounds):")
    print(f"  numba default pipeline   {default * 1e3:8.2f} ms")
    print(f"  noalias pipeline         {noalias * 1e3:8.2f} ms")
    print(f"  ratio default / noalias  {default / noalias:8.3f}")


if __name__ == "__main__":
    main()
