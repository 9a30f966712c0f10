"""Divergence of the GRNN and GRNN-Sparse on unstable plants: random initialization against a stable start.

Issue #50, item 4. On the ``random_network`` family (second-order unstable nodes,
open-loop spectral radius 1.83-1.87 at N = 20; both of the systems report's placements
gave only ``diverged`` tanh GRNN and GRNN-Sparse designs) and on the paper family at
||A||_2 = 1.2 (spectral radius 1.2), each instance is run three ways:

- ``random``: the paper's random initialization and shared readout (the default);
- ``random, per-node``: the random initialization with ``readout="per_node"``;
- ``diagonal``: ``init="diagonal"``, ``readout="per_node"``: the best diagonal static
  gain embedded as the first parameters (codesign/learned/warm.py).

Printed per family, variant and arm: designs ``diverged`` (status), warm starts kept
(training ended above the start, or diverged), ensemble members that diverged in
training, and the median cost of the usable designs. The training settings are the
systems report's (float32; GRNN with one model; GRNN-Sparse 150 steps, 3 + 3 models,
learning rates 0.03) with the GRNN's steps cut to ``--steps`` (default 300) to fit a
few minutes of CPU. One batch per (family, arm), as a report's runner trains them.

Usage::

    python benchmarks/bench_stable_start.py                  # 4 instances per family
    python benchmarks/bench_stable_start.py --instances 6 --families random_network
    python benchmarks/bench_stable_start.py --families paper_1.4 paper_1.6 --arms random diagonal
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from codesign import paper_instance
from baselines import grnn_batch
from codesign.status import DIVERGED, USABLE
from compare.run.families.random_network import random_network_instance

FAMILIES = ("random_network", "paper_1.2")
#: GRNN-Sparse's l1 weight: the middle of the systems report's grid (random network), and of the trade-off
#: report's grid at ||A|| = 1.2 (paper, every ||A||).
BETA = {"random_network": 0.3, "paper": 3.981071705534973}


def _family(name: str):
    """``random_network`` (N = 20) or ``paper_<a_norm>`` (N = 20, ||A||_2 = a_norm): seed -> instance."""
    if name == "random_network":
        return lambda seed: random_network_instance(20, seed=seed)
    a_norm = float(name.removeprefix("paper_"))
    return lambda seed: paper_instance(seed, a_norm=a_norm)
ARMS = {
    "random": {},
    "random, per-node": {"readout": "per_node"},
    "diagonal": {"readout": "per_node", "init": "diagonal"},
}


def _jobs(instances, family: str, arm: dict, steps: int) -> list:
    grnn = dict(variant="given", dtype="float32", ensemble=1, steps=steps, **arm)
    sparse = dict(variant="sparse", beta=BETA[family.split("_")[0]], steps=150, ensemble=3, refine_ensemble=3, lr=0.03,
                  l1_lr=0.03, dtype="float32", **arm)
    return [(inst, grnn) for inst in instances] + [(inst, sparse) for inst in instances]


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--instances", type=int, default=4)
    parser.add_argument("--steps", type=int, default=300, help="GRNN (given graph) training steps")
    parser.add_argument("--families", nargs="+", default=list(FAMILIES),
                        help="random_network, paper_<a_norm> (e.g. paper_1.2 paper_1.5)")
    parser.add_argument("--arms", nargs="+", default=list(ARMS), choices=list(ARMS))
    args = parser.parse_args(argv)
    for family in args.families:
        instances = [_family(family)(seed) for seed in range(args.instances)]
        radii = [inst.open_loop_radius for inst in instances]
        print(f"{family}: {len(instances)} instances (seeds 0-{len(instances) - 1}), open-loop spectral radius "
              f"{min(radii):.3f}-{max(radii):.3f}; GRNN {args.steps} steps, GRNN-Sparse 150 steps "
              f"(beta {BETA[family.split('_')[0]]:.4g})", flush=True)
        for name in args.arms:
            arm = ARMS[name]
            t0 = time.perf_counter()
            designs = grnn_batch(_jobs(instances, family, arm, args.steps))
            seconds = time.perf_counter() - t0
            for variant, part in (("GRNN", designs[:len(instances)]), ("GRNN-Sparse", designs[len(instances):])):
                diverged = sum(d.status == DIVERGED for d in part)
                kept = sum(bool(d.extras.get("kept_start")) for d in part)
                members = sum(int(d.extras.get("diverged_members", 0)) for d in part)
                costs = [d.cost for d in part if d.status in USABLE]
                median = f"{np.median(costs):.4g}" if costs else "-"
                print(f"  {variant:12s} {name:17s} diverged {diverged}/{len(part)}  kept start {kept}  "
                      f"members diverged {members}  median cost {median}", flush=True)
            print(f"    ({seconds:.0f} s)", flush=True)


if __name__ == "__main__":
    main()
