"""Seconds per 2000-draw GRNN rollout: the compiled pass against simulate's step loop.

A learned design's simulated cost is 2000 validation draws rolled out over the
horizon, a 250-draw pilot, a 100-draw 500-step boundedness check, and where the
pilot asks for it up to 126,000 importance-sampled draws more
(docs/evaluation.md). :meth:`GRNNController.rollout` runs each batch as one
compiled pass (:mod:`codesign.learned.grnn_rollout`); the step loop is the same
controller without it. Both on one thread, best of ``--repeats``, for GRNNs on
the paper's instances with S complete, on the plant graph, and with ``k`` links
per node (a GRNN-Sparse design), printing the ratio and the largest relative
difference of the draws' costs.

    python benchmarks/bench_grnn_rollout.py
    python benchmarks/bench_grnn_rollout.py --sizes 20 50 100 --draws 2000
"""

from __future__ import annotations

import argparse
import os
import time

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):  # one thread, as the harness's workers
    os.environ.setdefault(_name, "1")

import numpy as np

from codesign import GRNNController, paper_instance, simulate, validation_set


class StepByStep:
    """The controller without ``rollout``: simulate advances it one step at a time."""

    def __init__(self, controller):
        self.controller = controller

    def reset(self, batch):
        return self.controller.reset(batch)

    def step(self, state, x):
        return self.controller.step(state, x)


def best_seconds(fn, repeats: int) -> float:
    fn()  # warm-up (compiles the kernel on first use)
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="*", default=[20, 100])
    parser.add_argument("--draws", type=int, default=2000)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    print(f"{'N':>4} {'S':>14} {'step loop s':>12} {'compiled s':>11} {'ratio':>6} {'max rel diff':>13}")
    for n in args.sizes:
        inst = paper_instance(0, n=n, a_norm=1.05)
        x = validation_set(inst, args.draws)
        h = 5
        F, W, G = 0.4 * rng.standard_normal(h), 0.4 * rng.standard_normal((h, h)), -0.4 * rng.random(h)
        dense = inst.gso + 0.01
        plant = inst.gso * (inst.comm_adj != 0)
        sparse = plant.copy()
        np.put_along_axis(sparse, np.argsort(-np.abs(sparse), axis=1)[:, 2:], 0.0, axis=1)
        for name, S in (("complete", dense), ("plant graph", plant), ("2 per node", sparse)):
            c = GRNNController(S, F, W, G)
            def rollout(controller, inst=inst, x=x):
                return simulate(inst, controller, x, control_variates=False).costs

            loop = best_seconds(lambda c=c: rollout(StepByStep(c)), args.repeats)
            fast = best_seconds(lambda c=c: rollout(c), args.repeats)
            a, b = rollout(c), rollout(StepByStep(c))
            print(f"{n:>4} {name:>14} {loop:>12.4f} {fast:>11.4f} {loop / fast:>5.2f}x "
                  f"{np.max(np.abs(a - b) / np.abs(b)):>13.1e}")


if __name__ == "__main__":
    main()
