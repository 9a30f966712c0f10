"""A learned controller's rollout in a notebook: torch's thread pool at its default size against one thread.

The harness's workers run single-threaded; a notebook does not. A rollout alternates numpy
(OpenBLAS) products with the controller's torch calls on small arrays, and with both thread pools
at their default sizes their threads spin-wait on each other's cores. ``codesign.evaluation``
therefore holds torch at one thread for the length of a rollout. Prints, measured in one run of a
process with the default thread pools (run it without OMP_NUM_THREADS and friends), the seconds of
a 2000-draw rollout (``simulate``) of a GRNN and a GCNN at N = 20 and 100 with torch's pool left at
its default size (the code before 2026-11-26) and held at one thread, and their ratio, median of
``--repeats``.

    python benchmarks/bench_rollout_threads.py [--repeats 5]
"""

from __future__ import annotations

import argparse
import contextlib
import statistics
import time

import torch

from codesign import evaluation, paper_instance
from codesign.learned import gcnn, grnn


def seconds(run, repeats: int) -> float:
    run()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        run()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    print(f"torch's default pool: {torch.get_num_threads()} threads")
    print(f"{'controller':10s} {'N':>4s} {'default pool':>13s} {'one thread':>11s} {'ratio':>7s}")
    held = evaluation.one_torch_thread
    for n in (20, 100):
        inst = paper_instance(1, n=n, a_norm=1.05)
        x0 = evaluation.validation_set(inst, 2000)
        for name, design in (("GRNN", grnn(inst, seed=0, steps=5)), ("GCNN", gcnn(inst, seed=0, steps=2))):
            def run():
                evaluation.simulate(inst, design.controller, x0)

            evaluation.one_torch_thread = contextlib.nullcontext
            try:
                before = seconds(run, args.repeats)
            finally:
                evaluation.one_torch_thread = held
            after = seconds(run, args.repeats)
            print(f"{name:10s} {n:4d} {before:11.3f} s {after:9.3f} s {before / after:6.1f}x", flush=True)


if __name__ == "__main__":
    main()
