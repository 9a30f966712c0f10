"""The step loop in cache-sized blocks of draws, against 2000 draws at once, alone and beside a worker.

``simulate`` steps a controller without a compiled rollout (the GCNN, a GRNN on node blocks, a
user's controller) through blocks of 4000 states (200 draws at N = 20, 40 at N = 100). Until
2026-11-27 it stepped all its draws at once, and the refinement handed it 2000 at a time: a
GCNN's activations (32 features x draws x nodes) then leave a core's cache. On two cores that
matters most beside the other worker, which ``compare run`` always has. Prints, measured in
one run:

* a GCNN's rollout (K = 5 taps, 32 features, N = 20, T = 50), draws per second, in 2000-draw
  batches and in blocks: alone, and beside a second process training GRNN-Sparse β-path runs
  (the ``tradeoff`` preset's other work);
* that neighbour's seconds per batch of runs: alone, beside the 2000-draw rollouts and beside
  the blocked ones;
* the rollout at N = 100 (blocks of 40 draws), alone and beside the neighbour.

    python benchmarks/bench_rollout_blocks.py [--seconds 12]
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import time

import numpy as np
import torch

from codesign import paper_instance
from codesign.evaluation import ROLLOUT_BOUND, simulate, step_loop
from codesign.learned import GCNNController
from codesign.learned.grnn import grnn_batch

_OLD_BATCH = 2000


def gcnn(n: int):
    inst = paper_instance(3, n=n)
    rng = np.random.default_rng(0)
    controller = GCNNController(inst.gso, rng.standard_normal((5, 32)) / 3, rng.standard_normal(32) / 6)
    return inst, controller, rng.standard_normal((8000, n))


def rollout_costs(inst, controller, x0, blocked: bool) -> np.ndarray:
    if blocked:
        return simulate(inst, controller, x0, control_variates=False).costs * inst.trace_P
    return np.concatenate([step_loop(inst, controller, x0[i:i + _OLD_BATCH], inst.horizon, 0.0, None,
                                     ROLLOUT_BOUND, 0.0)[0] for i in range(0, x0.shape[0], _OLD_BATCH)])


def draws_per_second(n: int, blocked: bool, stop=None, seconds: float = 0.0) -> float:
    """Roll the same 8000 draws out until ``stop`` is set (or for ``seconds``)."""
    torch.set_num_threads(1)
    inst, controller, x0 = gcnn(n)
    draws, start = 0, time.perf_counter()
    while not (stop.is_set() if stop is not None else time.perf_counter() - start > seconds):
        rollout_costs(inst, controller, x0, blocked)
        draws += x0.shape[0]
    return draws / (time.perf_counter() - start)


def _rollouts_beside(blocked, stop, ready, result):
    ready.set()
    result.put(draws_per_second(20, blocked, stop=stop))


def beta_path_batch() -> float:
    """Seconds for six GRNN-Sparse β-path runs (the tradeoff preset's settings), one stack."""
    settings = dict(variant="sparse", steps=150, ensemble=3, refine_ensemble=3, lr=0.03, l1_lr=0.03,
                    dtype="float32", curve_every=50, seed=0)
    jobs = [(paper_instance(seed, a_norm=1.1), dict(settings, beta=beta)) for seed in (0, 1) for beta in (0.01, 0.25, 6.3)]
    start = time.perf_counter()
    grnn_batch(jobs)
    return time.perf_counter() - start


def _training_beside(stop, ready, result):
    torch.set_num_threads(1)
    beta_path_batch()
    ready.set()
    while not stop.is_set():
        beta_path_batch()
    result.put(None)


def beside(target, args):
    """Start ``target`` in a second process; return (its stop event, its result queue, the process)."""
    stop, ready, result = mp.Event(), mp.Event(), mp.Queue()
    process = mp.Process(target=target, args=(*args, stop, ready, result))
    process.start()
    ready.wait()
    return stop, result, process


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=12.0, help="seconds per rollout measurement")
    args = parser.parse_args()
    torch.set_num_threads(1)
    names = {False: f"{_OLD_BATCH} draws at once", True: "cache-sized blocks"}

    inst, controller, x0 = gcnn(20)
    difference = np.max(np.abs(rollout_costs(inst, controller, x0, True) / rollout_costs(inst, controller, x0, False) - 1))
    beta_path_batch()  # compile
    print("GRNN-Sparse beta-path batch (6 runs), the neighbour:")
    neighbour = {"alone": beta_path_batch()}
    print(f"  alone {neighbour['alone']:7.2f} s")
    rates = {}
    for blocked in (False, True):
        stop, result, process = beside(_rollouts_beside, (blocked,))
        neighbour[blocked] = min(beta_path_batch(), beta_path_batch())
        stop.set()
        beside_rate = result.get()
        process.join()
        print(f"  beside a GCNN rolled out in {names[blocked]:20s} {neighbour[blocked]:7.2f} s")
        rates[blocked] = (draws_per_second(20, blocked, seconds=args.seconds), beside_rate)
    print(f"  ratio {neighbour[False] / neighbour[True]:.2f}x (beside 2000 at once / beside blocks)")

    print("\nGCNN rollout, N = 20, T = 50, draws per second (its own process beside the neighbour):")
    for blocked in (False, True):
        stop, result, process = beside(_training_beside, ())
        beside_rate = draws_per_second(20, blocked, seconds=args.seconds)
        stop.set()
        result.get()
        process.join()
        print(f"  {names[blocked]:20s} alone {rates[blocked][0]:8.0f}   beside GRNN training {beside_rate:8.0f}"
              f"   (while the neighbour was timed: {rates[blocked][1]:8.0f})")
        rates[blocked] = (rates[blocked][0], beside_rate)
    print(f"  ratio blocks / 2000 at once: alone {rates[True][0] / rates[False][0]:.2f}x, "
          f"beside {rates[True][1] / rates[False][1]:.2f}x; largest relative difference in the costs {difference:.1e}")

    print("\nGCNN rollout, N = 100, draws per second:")
    big = {blocked: [draws_per_second(100, blocked, seconds=args.seconds)] for blocked in (False, True)}
    stop, result, process = beside(_training_beside, ())
    for blocked in (False, True):
        big[blocked].append(draws_per_second(100, blocked, seconds=args.seconds))
    stop.set()
    result.get()
    process.join()
    for blocked in (False, True):
        print(f"  {names[blocked]:20s} alone {big[blocked][0]:8.0f}   beside GRNN training {big[blocked][1]:8.0f}")
    print(f"  ratio blocks / 2000 at once: alone {big[True][0] / big[False][0]:.2f}x, "
          f"beside {big[True][1] / big[False][1]:.2f}x")


if __name__ == "__main__":
    main()
