"""Solve times of SLS with delay constraints on paper instances.

Each line is one cold solve in this process (matrix building, cvxpy compilation,
Clarabel setup and solve, realization and exact scoring), on the plant graph at
one hop per step. N = 20 and 50 use the full finite-horizon QP (T = 50); N = 100
uses the FIR variant (F = 15) by default, ``--full`` also runs its T = 50 QP
(50-75 s and 4.5 GB of memory on 2 cores).

Run: ``OMP_NUM_THREADS=1 python benchmarks/bench_sls.py [--full]``
"""

from __future__ import annotations

import argparse
import time

from baselines import sls
from codesign import paper_instance, simulate


def timed(instance, **kwargs):
    start = time.perf_counter()
    design = sls(instance, **kwargs)
    return design, time.perf_counter() - start


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--full", action="store_true", help="also solve the N = 100, T = 50 QP")
    args = parser.parse_args()

    cases = [(20, {}), (20, {"fir": 15}), (50, {}), (100, {"fir": 15})]
    if args.full:
        cases.append((100, {}))
    print(f"{'N':>4} {'variant':<14} {'status':<10} {'cost':>8} {'links':>6} {'vars':>8} "
          f"{'clarabel s':>10} {'total s':>8}")
    for n, kwargs in cases:
        instance = paper_instance(0, n=n)
        design, seconds = timed(instance, **kwargs)
        variant = f"FIR F={kwargs['fir']}" if "fir" in kwargs else f"T={instance.horizon}"
        print(f"{n:>4} {variant:<14} {design.status:<10} {design.cost:>8.4f} {design.links:>6} "
              f"{design.extras.get('variables', 0):>8} {design.extras.get('solve_seconds', float('nan')):>10.2f} "
              f"{seconds:>8.2f}", flush=True)
        if n == 20 and not kwargs:
            n20 = seconds

    instance = paper_instance(0)
    given, given_seconds = timed(instance, graph="given")
    print(f"\nN = 20 given graph at speed 1: {given.status} in {given_seconds:.2f} s: {given.message}")
    fir, _ = timed(instance, fir=15)
    rollout = simulate(instance, fir.controller, steps=500, noise_std=0.5, seed=0)
    print(f"N = 20 FIR realization, 500 noisy steps (sigma 0.5): bounded={rollout.bounded}, "
          f"max |x_i| = {rollout.max_state:.2f}")
    print(f"\nN = 20, T = 50 cold solve: {n20:.2f} s (target < 2 s)")


if __name__ == "__main__":
    main()
