"""Precision and time of the simulated cost of learned controllers, before and after control variates.

Trains every GRNN variant (given, dense, fixed, sparse at one β) and the GCNN
with their default settings on 5 paper instances per ‖A‖ ∈ {0.995, 1.05}, then
scores each trained controller two ways, in this one run:

- before: what the harness did up to version 0.1 — the method's own 1000-draw
  rollout plus the harness's second 1000-draw rollout, each reporting the
  sample mean (timed with that version's rollout loop, kept below);
- after: the harness's rollout (:func:`codesign.evaluation.simulate_to_precision`):
  the default validation set (2000 draws) with the cross-fitted quadratic control
  variates, refined on importance-sampled draws (doubling the count, up to 128,000) while the relative
  standard error exceeds 0.1 %.

It prints per method the median and largest relative standard error of the
reported cost (target ≤ 0.1 %), the most draws used, and the evaluation seconds per design
(median before and after, their ratio, and the largest after).

    python benchmarks/bench_evaluation.py             # 5 instances per ‖A‖, about 7 minutes on 2 cores
    python benchmarks/bench_evaluation.py --instances 2
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from baselines import gcnn_batch
from codesign import grnn_batch, paper_instance, validation_set
from codesign.evaluation import VALIDATION_SIZE, simulate_to_precision
from codesign.status import OPTIMAL


def rollout_before(instance, controller, x):
    """The 0.1 rollout loop: three-operand einsums for the stage costs, sample mean."""
    A_T, B_T = instance.A.T, instance.B.T
    costs = np.zeros(x.shape[0])
    state = controller.reset(x.shape[0])
    for _ in range(instance.horizon):
        u, state = controller.step(state, x)
        costs += np.einsum("bi,ij,bj->b", x, instance.Q, x) + np.einsum("bi,ij,bj->b", u, instance.R, u)
        x = x @ A_T + u @ B_T
        float(np.max(np.abs(x)))  # the boundedness check of every step
    costs += np.einsum("bi,ij,bj->b", x, instance.P, x)
    costs /= instance.trace_P
    return costs.mean(), costs.std(ddof=1) / np.sqrt(costs.size)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--instances", type=int, default=5, help="instances per ‖A‖")
    parser.add_argument("--beta", type=float, default=0.1, help="β of the GRNN-Sparse designs")
    args = parser.parse_args()
    instances = [paper_instance(seed, a_norm=a) for a in (0.995, 1.05) for seed in range(args.instances)]
    jobs = {
        "grnn (given)": [(i, {"variant": "given"}) for i in instances],
        "grnn_dense": [(i, {"variant": "dense"}) for i in instances],
        "grnn_fixed": [(i, {"variant": "fixed"}) for i in instances],
        f"grnn_sparse (β={args.beta:g})": [(i, {"variant": "sparse", "beta": args.beta}) for i in instances],
    }
    print(f"validation set: {VALIDATION_SIZE} draws after, 2 x 1000 before; "
          f"{args.instances} instances per ‖A‖ in {{0.995, 1.05}}\n")
    header = (f"{'method':26s} {'‖A‖':>6s} {'rel. stderr before':>19s} {'after: median':>14s} {'max':>8s}"
              f" {'draws max':>9s} {'s/design before':>16s} {'after':>7s} {'ratio':>6s} {'after max':>9s}")
    print(header)
    print("-" * len(header))
    worst = 0.0
    for name in [*jobs, "gcnn"]:
        start = time.perf_counter()
        if name == "gcnn":
            designs = gcnn_batch([(i, {}) for i in instances])
        else:
            designs = grnn_batch(jobs[name])
        train_seconds = time.perf_counter() - start
        for a_norm in (0.995, 1.05):
            before_rel, after_rel, before_s, after_s, draws = [], [], [], [], []
            for instance, design in zip(instances, designs):
                if instance.spec["a_norm"] != a_norm or design.status != OPTIMAL:
                    continue
                x = validation_set(instance, 1000)
                tick = time.perf_counter()
                mean, stderr = rollout_before(instance, design.controller, x)
                rollout_before(instance, design.controller, x)
                before_s.append(time.perf_counter() - tick)
                tick = time.perf_counter()
                rollout = simulate_to_precision(instance, design.controller)
                after_s.append(time.perf_counter() - tick)
                draws.append(rollout.costs.size)
                before_rel.append(stderr / mean)
                after_rel.append(rollout.stderr / rollout.cost)
            worst = max(worst, max(after_rel))
            print(f"{name:26s} {a_norm:6.3f} {np.median(before_rel):18.3%} {np.median(after_rel):14.4%}"
                  f" {max(after_rel):8.4%} {max(draws):9d} {np.median(before_s):16.3f} {np.median(after_s):7.3f}"
                  f" {np.median(after_s) / np.median(before_s):6.2f} {max(after_s):9.2f}")
        print(f"{'':26s} (trained {len(designs)} designs in {train_seconds:.0f} s)")
    print(f"\nlargest relative standard error after: {worst:.4%} (target 0.1 %)")


if __name__ == "__main__":
    main()
