"""Scoring a GRNN and a GCNN at hundreds to a thousand nodes: structured rollouts against dense ones, in one run.

On paper instances (``connect = "bridge"``, seed 0) at each N, a GRNN controller with
S on the given communication graph (about 7 links per node), and a GCNN on the same
graph, are scored the way the harness scores a learned design: a 2000-draw
validation rollout, the local cost form (2N rows, the pilot's tilt) and, for the
GRNN, the spectral radius of its linearized closed loop.
Each is timed twice: on the structured path (S, A, B multiplied on their supports,
ARPACK on the sparse linearization; what runs above 200 states) and on the dense path
(forced by raising the threshold; what ran before). The costs must agree to rounding.

Part 2 (``--train``): seconds per Adam step of the fused engine on GRNN-Sparse's l1
stage, on every pair of nodes against on ``l1_hops`` = 3, at each N. Single-threaded
BLAS and torch. Run from the repository root::

    python benchmarks/bench_grnn_scale.py                  # N = 300, 500, 1000 (~8 min)
    python benchmarks/bench_grnn_scale.py --sizes 500 --train
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import importlib  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402
import torch  # noqa: E402

from codesign import evaluation  # noqa: E402
from codesign.instances import paper_instance  # noqa: E402

grnn_module = importlib.import_module("codesign.learned.grnn")


gcnn_module = importlib.import_module("codesign.learned.gcnn")


def _grnn(inst):
    rng = np.random.default_rng(0)
    S = np.where(inst.comm_adj != 0, 0.3 * rng.random(inst.comm_adj.shape), 0.0) + 0.2 * np.eye(inst.n)
    return grnn_module.GRNNController(S, 0.5 * rng.random(5), 0.3 * rng.random((5, 5)), -0.3 * rng.random(5))


def _gcnn(inst):
    rng = np.random.default_rng(0)
    return gcnn_module.GCNNController(inst.gso, rng.uniform(-0.5, 0.5, (5, 32)), rng.uniform(-0.3, 0.3, 32))


def _score(inst, controller):
    times, x0 = {}, evaluation.validation_set(inst)
    start = time.perf_counter()
    rollout = evaluation.simulate(inst, controller, x0)
    times["rollout"] = time.perf_counter() - start
    start = time.perf_counter()
    evaluation.local_cost_form(inst, controller)
    times["form"] = time.perf_counter() - start
    radius = float("nan")
    start = time.perf_counter()
    if hasattr(controller, "linearized_closed_loop"):
        radius = evaluation.spectral_radius(controller.linearized_closed_loop(
            inst, sparse=inst.n > grnn_module.STRUCTURED_ABOVE))
    times["radius"] = time.perf_counter() - start
    return times, rollout.plain_cost, radius


def _dense_path():
    """Raise every structured-path threshold (returns a function that restores them)."""
    modules = (evaluation, grnn_module, gcnn_module)
    saved = [m.STRUCTURED_ABOVE for m in modules]
    for m in modules:
        m.STRUCTURED_ABOVE = 10**9

    def restore():
        for m, value in zip(modules, saved):
            m.STRUCTURED_ABOVE = value
    return restore


def scoring(sizes):
    print("Scoring one learned design (seconds, one thread): structured path / dense path = ratio")
    print(f"{'model':>5} {'N':>5} | {'2000-draw rollout':>26} | {'local cost form':>26} | {'spectral radius':>26} "
          f"| cost agreement")
    for n in sizes:
        inst = paper_instance(0, n=n, connect="bridge")
        for name, build in (("GRNN", _grnn), ("GCNN", _gcnn)):
            fast, cost, radius = _score(inst, build(inst))
            restore = _dense_path()
            try:
                slow, dense_cost, dense_radius = _score(inst, build(inst))
            finally:
                restore()
            keys = ("rollout", "form", "radius") if name == "GRNN" else ("rollout", "form")
            cells = [f"{fast[k]:7.2f} / {slow[k]:7.2f} = {slow[k] / fast[k]:5.1f}x" for k in keys]
            agreement = f"{abs(cost - dense_cost) / dense_cost:.1e}"
            if name == "GRNN":
                agreement += f" (radius {abs(radius - dense_radius):.1e})"
            else:
                cells.append(f"{'':>26}")
            print(f"{name:>5} {n:>5} | " + " | ".join(cells) + f" | {agreement}", flush=True)


def training(sizes, steps: int = 6):
    from codesign.learned.trainer import train_jobs

    print(f"\nGRNN-Sparse's l1 stage, fused engine: seconds per Adam step of one model ({steps} steps after a warm-up)")
    print(f"{'N':>5} | {'all N^2 pairs':>14} | {'l1_hops = 3':>12} | ratio")
    for n in sizes:
        inst = paper_instance(0, n=n, connect="bridge")
        per_step = {}
        for hops in (None, 3):
            def run(k):
                job = grnn_module._parse(inst, {"variant": "sparse", "beta": 1.0, "l1_hops": hops, "steps": k,
                                                "ensemble": 1, "curve_every": 0})
                start = time.perf_counter()
                train_jobs([grnn_module._training(job, grnn_module._first_stage_specs(job))], stack_size=1)
                return time.perf_counter() - start
            run(1)  # compiles the kernel for this shape
            per_step[hops] = (run(steps + 1) - run(1)) / steps
        print(f"{n:>5} | {per_step[None]:14.3f} | {per_step[3]:12.3f} | {per_step[None] / per_step[3]:5.1f}x",
              flush=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", type=int, nargs="+", default=[300, 500, 1000])
    parser.add_argument("--train", action="store_true", help="also time the l1 stage's training steps")
    args = parser.parse_args()
    torch.set_num_threads(1)
    scoring([n for n in args.sizes if n > 0])
    if args.train:
        training(args.sizes)


if __name__ == "__main__":
    main()
