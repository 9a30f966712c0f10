"""Seconds per 750-step GRNN training, one model alone against many trained together.

Trains M GRNN models of the paper's size (N = 20, T = 50, batch 20, h = 5,
validation curve every 10 steps on 100 draws) for a fixed number of steps with
:func:`codesign.training.train_stack`, for M = 1 and M = 64 (or ``--models``),
and prints the seconds per 750-step model of each and their ratio, measured in
this one run. The paper's own code takes 20-28 s per model on a 2-core machine.

    python benchmarks/bench_grnn.py                 # float64 and float32, 2 threads
    python benchmarks/bench_grnn.py --threads 1 --dtype float32 --steps 30
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from codesign import paper_instance
from codesign.grnn import _selection_set
from codesign.training import ModelSpec, init_fwg, train_stack


def make_specs(M: int, instances) -> list[ModelSpec]:
    specs = []
    for m in range(M):
        inst = instances[m % len(instances)]
        F, W, G = init_fwg(np.random.default_rng([m, 1]), 5)
        specs.append(ModelSpec(
            A=inst.A, B=inst.B, Q=inst.Q, R=inst.R, P=inst.P, trace_P=inst.trace_P,
            S0=inst.gso, mask=inst.comm_adj != 0, F0=F, W0=W, G0=G, data_seed=[m, 0],
            curve_x0=_selection_set(inst, 100), lr=0.02,
        ))
    return specs


def seconds_per_model(M: int, steps: int, dtype: str, instances) -> float:
    specs = make_specs(M, instances)
    train_stack(specs[: min(M, 4)], steps=2, dtype=dtype)  # warm-up (allocator, BLAS)
    start = time.perf_counter()
    train_stack(specs, steps=steps, dtype=dtype, curve_every=10)
    return (time.perf_counter() - start) / M * (750 / steps)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--models", type=int, default=64, help="stack size M of the batched run (default 64)")
    parser.add_argument("--steps", type=int, default=50, help="training steps timed (extrapolated to 750)")
    parser.add_argument("--dtype", choices=("float64", "float32", "both"), default="both")
    parser.add_argument("--threads", type=int, default=2, help="torch intra-op threads (default 2)")
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)
    instances = [paper_instance(seed) for seed in range(8)]
    dtypes = ("float64", "float32") if args.dtype == "both" else (args.dtype,)
    print(f"GRNN training, N=20 T=50 batch=20 h=5, {args.steps} steps timed, {args.threads} torch thread(s)")
    print(f"{'dtype':8} {'M':>4} {'s / 750-step model':>20}")
    for dtype in dtypes:
        single = seconds_per_model(1, args.steps, dtype, instances)
        print(f"{dtype:8} {1:>4} {single:>20.3f}")
        many = seconds_per_model(args.models, args.steps, dtype, instances)
        print(f"{dtype:8} {args.models:>4} {many:>20.3f}")
        print(f"{dtype:8} ratio M=1 / M={args.models}: {single / many:.1f}x")


if __name__ == "__main__":
    main()
