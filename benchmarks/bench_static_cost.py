"""Seconds of a static gain's exact cost and masked gradient, dense formulas against the structured path, in one run.

The polishing methods (decentralized: L-BFGS on the diagonal of K; truncated LQR and
the other sparse methods: L-BFGS on a sparse pattern; :func:`baselines.polish_gain`)
evaluate :func:`codesign.static_gain_cost_and_grad` once per L-BFGS step, and every
static design is scored by :func:`codesign.static_gain_cost`. The dense formulas do
seven n x n products per time step; above ``STRUCTURED_ABOVE`` states the structured
path multiplies with the closed loop ``A + BK`` as a sparse matrix (renumbered to a
band) and computes the gradient on the mask's entries only.

On one paper instance per size (seed 0, ``connect="bridge"``, horizon 50), single-threaded,
for two gains with their masks:

- ``diagonal``: the diagonal of the LQR gain (the decentralized design's start);
- ``pattern``: the LQR gain truncated to its 10 largest entries per row plus the diagonal
  (a truncated-LQR-like pattern).

Each line gives the seconds of one cost + masked gradient by the dense formulas and by the
structured path (the threshold moved either way, so n = 200 shows both too), the ratio, the
relative difference of the cost and of the masked gradient (largest entry difference over
the largest entry), then the same for the cost alone. Last, one :func:`baselines.polish_gain`
of the diagonal at the largest size: seconds, evaluations, seconds per evaluation.
Run from the repository root::

    python benchmarks/bench_static_cost.py                    # n = 200, 500, 1000 (~2 min)
    python benchmarks/bench_static_cost.py --sizes 200 500 --polish-n 500
"""

from __future__ import annotations

import os

# Single-threaded BLAS: the variables must be set before numpy loads its BLAS.
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from unittest import mock  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402
from threadpoolctl import threadpool_limits  # noqa: E402

from baselines import polish as polish_module  # noqa: E402
from codesign import evaluation  # noqa: E402
from codesign.instances import paper_instance  # noqa: E402

PATTERN_PER_ROW = 10


def timed(function, *args, **kwargs):
    start = time.perf_counter()
    out = function(*args, **kwargs)
    return out, time.perf_counter() - start


def path(structured: bool):
    """The dense formulas or the structured path at any n (the threshold moved out of the way)."""
    return mock.patch.object(evaluation, "STRUCTURED_ABOVE", -1 if structured else sys.maxsize)


def gains(instance):
    """(label, gain, mask): the LQR gain's diagonal, and the LQR gain truncated to a local pattern."""
    K = np.array(instance.K_lqr)
    diagonal = np.eye(instance.n, dtype=bool)
    largest = np.argsort(-np.abs(K), axis=1)[:, :PATTERN_PER_ROW]
    pattern = diagonal.copy()
    np.put_along_axis(pattern, largest, True, axis=1)
    return [("diagonal", K * diagonal, diagonal), ("pattern", np.where(pattern, K, 0.0), pattern)]


def relative(x, reference) -> float:
    return float(np.max(np.abs(x - reference)) / np.max(np.abs(reference)))


def compare(instance, label, K, mask):
    with path(structured=False):
        (dense_cost, dense_grad), dense_s = timed(evaluation.static_gain_cost_and_grad, instance, K, mask=mask)
        dense_only, dense_only_s = timed(evaluation.static_gain_cost, instance, K)
    with path(structured=True):
        (cost, grad), seconds = timed(evaluation.static_gain_cost_and_grad, instance, K, mask=mask)
        only, only_s = timed(evaluation.static_gain_cost, instance, K)
        loop = evaluation._ClosedLoop(instance, K)
    closed_loop = "dense" if isinstance(loop.acl, np.ndarray) else f"CSR {loop.acl.nnz / instance.n:.0f}/row"
    print(f"{label:9s} {instance.n:5d} {mask.sum() / instance.n:6.1f} {closed_loop:>12s} "
          f"{dense_s:8.2f} {seconds:8.2f} {dense_s / seconds:6.1f} "
          f"{abs(cost - dense_cost) / dense_cost:8.1e} {relative(grad[mask], dense_grad[mask]):8.1e} "
          f"{dense_only_s:8.2f} {only_s:8.2f} {dense_only_s / only_s:6.1f} {abs(only - dense_only) / dense_only:8.1e}",
          flush=True)


def polish_run(instance):
    """One polish_gain of the LQR diagonal on the diagonal: seconds and evaluations."""
    label, K, mask = gains(instance)[0]
    count = [0]
    evaluate = polish_module.static_gain_cost_and_grad

    def counted(*args, **kwargs):
        count[0] += 1
        return evaluate(*args, **kwargs)

    with mock.patch.object(polish_module, "static_gain_cost_and_grad", counted):
        result, seconds = timed(polish_module.polish_gain, instance, K, mask)
    print(f"polish_gain on the {label}, n = {instance.n}: {seconds:.1f} s, {count[0]} evaluations "
          f"({seconds / count[0]:.2f} s each), {result.iterations} iterations, cost {result.cost:.8f}, "
          f"masked gradient norm {result.grad_norm:.1e}: {result.message}", flush=True)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", type=int, nargs="+", default=[200, 500, 1000])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--polish-n", type=int, default=None,
                        help="size of the timed polish (default: the largest size; 0 skips it)")
    args = parser.parse_args(argv)
    limits = threadpool_limits(limits=1)  # also caps a BLAS that ignored the variables
    print(f"cores available: {len(os.sched_getaffinity(0))}, BLAS threads 1, "
          f"load average {os.getloadavg()[0]:.2f}; STRUCTURED_ABOVE = {evaluation.STRUCTURED_ABOVE}, "
          f"SPARSE_DENSITY = {evaluation.SPARSE_DENSITY}")
    print(f"{'':9s} {'':5s} {'mask':>6s} {'':>12s} {'cost + masked gradient':^33s} {'':8s} {'':8s} "
          f"{'cost only':^33s}")
    print(f"{'gain':9s} {'n':>5s} {'/row':>6s} {'closed loop':>12s} {'dense s':>8s} {'struct s':>8s} {'ratio':>6s} "
          f"{'cost rel':>8s} {'grad rel':>8s} {'dense s':>8s} {'struct s':>8s} {'ratio':>6s} {'cost rel':>8s}")
    instances = {}
    polish_n = max(args.sizes) if args.polish_n is None else args.polish_n
    for n in args.sizes:
        instance = paper_instance(args.seed, n=n, connect="bridge")
        if n == polish_n:
            instances[n] = instance
        for label, K, mask in gains(instance):
            compare(instance, label, K, mask)
    if polish_n:
        polish_run(instances.get(polish_n) or paper_instance(args.seed, n=polish_n, connect="bridge"))
    del limits


if __name__ == "__main__":
    main()
