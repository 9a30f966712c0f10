"""Seconds per 750-step GRNN training, one model alone against many trained together.

Trains M GRNN models of the paper's size (N = 20, T = 50, batch 20, h = 5,
validation curve every 10 steps on 100 draws) for a fixed number of steps with
:func:`codesign.training.train_stack`, for M = 1 and M = 64 (or ``--models``),
and prints the seconds per 750-step model of each and their ratio, measured in
this one run. The paper's own code takes 20-28 s per model on a 2-core machine.

    python benchmarks/bench_grnn.py                 # float64 and float32, 2 processes x 1 thread
    python benchmarks/bench_grnn.py --procs 1 --threads 2 --dtype float32 --steps 30

M = 1 runs in one process; the M-model run splits the models over ``--procs``
single-threaded processes (one stack each, as the runner's workers do), which
uses 2 cores better than 2 torch threads on one stack of tiny matrix products.
"""

from __future__ import annotations

import argparse
import multiprocessing
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


def _train_share(args):
    M, offset, count, steps, dtype, threads, barrier = args
    torch.set_num_threads(threads)
    instances = [paper_instance(seed) for seed in range(8)]
    specs = make_specs(M, instances)[offset:offset + count]
    train_stack(specs[:2], steps=2, dtype=dtype)  # warm-up (allocator, BLAS)
    if barrier is not None:
        barrier.wait()
    start = time.perf_counter()
    train_stack(specs, steps=steps, dtype=dtype, curve_every=10)
    return start, time.perf_counter()


def seconds_per_model(M: int, steps: int, dtype: str, threads: int, procs: int) -> float:
    """Wall seconds per 750-step model; with procs > 1 the M models are split over that many
    single-stack processes running at once (how the runner uses several cores)."""
    if procs == 1 or M < procs:
        start, end = _train_share((M, 0, M, steps, dtype, threads, None))
        return (end - start) / M * (750 / steps)
    ctx = multiprocessing.get_context("spawn")
    with ctx.Manager() as manager:
        barrier = manager.Barrier(procs)
        shares = [M // procs + (i < M % procs) for i in range(procs)]
        offsets = [sum(shares[:i]) for i in range(procs)]
        with ctx.Pool(procs) as pool:
            spans = pool.map(_train_share, [(M, o, c, steps, dtype, threads, barrier)
                                            for o, c in zip(offsets, shares)])
    wall = max(end for _, end in spans) - min(start for start, _ in spans)
    return wall / M * (750 / steps)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--models", type=int, default=64, help="stack size M of the batched run (default 64)")
    parser.add_argument("--steps", type=int, default=50, help="training steps timed (extrapolated to 750)")
    parser.add_argument("--dtype", choices=("float64", "float32", "both"), default="both")
    parser.add_argument("--threads", type=int, default=1, help="torch intra-op threads per process (default 1)")
    parser.add_argument("--procs", type=int, default=2,
                        help="processes sharing the M models, one stack each (default 2: one per core)")
    args = parser.parse_args(argv)
    dtypes = ("float64", "float32") if args.dtype == "both" else (args.dtype,)
    print(f"GRNN training, N=20 T=50 batch=20 h=5, {args.steps} steps timed (curve every 10 on 100 draws), "
          f"{args.procs} process(es) x {args.threads} torch thread(s)")
    print(f"{'dtype':8} {'M':>4} {'s / 750-step model':>20}")
    for dtype in dtypes:
        single = seconds_per_model(1, args.steps, dtype, args.threads, 1)
        print(f"{dtype:8} {1:>4} {single:>20.3f}")
        many = seconds_per_model(args.models, args.steps, dtype, args.threads, args.procs)
        print(f"{dtype:8} {args.models:>4} {many:>20.3f}")
        print(f"{dtype:8} ratio M=1 / M={args.models}: {single / many:.1f}x")


if __name__ == "__main__":
    main()
