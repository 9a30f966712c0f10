"""The GCNN's time: its controller's rollouts (most of it, in the cost's refinement) and its training.

Prints, measured in one run on one thread:

* seconds to roll a trained-size GCNN (K = 5 taps, 32 features, N = 20, T = 50) out from
  ``--draws`` initial states with the controller's step (feature-major filter bank, tanh as a
  folded sigmoid) and with the node-major step it replaced (``(batch N, K) x (K, F)`` products
  and ``torch.tanh``), their largest difference in the inputs, and the ratio;
* seconds for the same draws through ``simulate``, which steps them in cache-sized blocks
  (``benchmarks/bench_rollout_blocks.py`` measures what the blocks are worth beside another worker);
* seconds per 750-step model of the trainer's GCNN stack (float32 and float64, 10 models),
  with the torch path and the fused (numba) engine, and their ratio.

    python benchmarks/bench_gcnn.py [--draws 16000]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from codesign import paper_instance
from codesign.evaluation import BLOCK_STATES, ROLLOUT_BOUND, simulate, step_loop
from codesign.learned import GCNNController
from codesign.learned.gcnn import ensemble_member, parse_job
from codesign.learned.gcnn_bptt import GCNNStack
from codesign.learned.trainer import train_stack


def node_major_step(c: GCNNController, x):
    """The step before 2026-11-26: powers stacked node-major, then torch.tanh."""
    powers = [x]
    for _ in range(c.H.shape[0] - 1):
        powers.append(powers[-1] @ c.S.T)
    z = np.stack(powers, axis=-1) @ c.H
    return torch.tanh(torch.from_numpy(z)).numpy() @ c.w


def rollout(inst, step, x0):
    x, total = x0.copy(), 0.0
    for _ in range(inst.horizon):
        u = step(x)
        total += float(np.sum(x * x) + np.sum(u * u))
        x = x @ inst.A.T + u @ inst.B.T
    return total


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--draws", type=int, default=16000)
    args = parser.parse_args()
    torch.set_num_threads(1)
    inst = paper_instance(3, n=20)
    rng = np.random.default_rng(0)
    c = GCNNController(inst.gso, rng.standard_normal((5, 32)) / 3, rng.standard_normal(32) / 6)
    x0 = rng.standard_normal((args.draws, inst.n))
    diff = np.abs(c.step(None, x0[:500])[0] - node_major_step(c, x0[:500])).max()
    times = {}
    for name, step in (("node-major + torch.tanh", lambda x: node_major_step(c, x)),
                       ("feature-major + folded sigmoid", lambda x: c.step(None, x)[0])):
        t = time.perf_counter()
        rollout(inst, step, x0)
        times[name] = time.perf_counter() - t
    print(f"GCNN rollout, {args.draws} draws x {inst.horizon} steps, N = {inst.n}, one thread:")
    for name, seconds in times.items():
        print(f"  {name:32s} {seconds:7.2f} s")
    old, new = times.values()
    print(f"  ratio {old / new:.2f}x; largest difference in u {diff:.1e}")
    seconds = {}
    for name, run in (("all at once", lambda: step_loop(inst, c, x0, inst.horizon, 0.0, None, ROLLOUT_BOUND, 0.0)),
                      ("blocks", lambda: simulate(inst, c, x0, control_variates=False))):
        t = time.perf_counter()
        run()
        seconds[name] = time.perf_counter() - t
    print(f"  simulate's step loop, all draws at once {seconds['all at once']:7.2f} s, in blocks of "
          f"{BLOCK_STATES // inst.n} draws {seconds['blocks']:7.2f} s: ratio "
          f"{seconds['all at once'] / seconds['blocks']:.2f}x")
    print("GCNN training (10 models stacked, one thread), seconds per 750-step model:")
    insts = [paper_instance(s, n=20, a_norm=1.05) for s in range(10)]
    for dtype in ("float32", "float64"):
        jobs = [parse_job(i, dict(dtype=dtype, ensemble=1, steps=150)) for i in insts]
        members = [ensemble_member(j, 0) for j in jobs]
        train_stack(GCNNStack, members[:1], jobs[0].settings.loop(inst.horizon), engine="fused")  # compile
        seconds = {}
        for engine in ("torch", "fused"):
            t = time.perf_counter()
            train_stack(GCNNStack, members, jobs[0].settings.loop(inst.horizon), engine=engine)
            seconds[engine] = (time.perf_counter() - t) / len(members) * 5
        print(f"  {dtype}  torch {seconds['torch']:6.2f} s   fused {seconds['fused']:6.2f} s   "
              f"ratio {seconds['torch'] / seconds['fused']:.2f}x")


if __name__ == "__main__":
    main()
