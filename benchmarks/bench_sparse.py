"""Seconds per γ of the sparse static-gain paths (ℓ1 ADMM and ℓ1 SDP), in one run.

Targets (issue 4): a 10-γ path on an N = 20 paper instance in under 5 s (ADMM)
and under 10 s (SDP) on 2 cores. Run from the repository root::

    OMP_NUM_THREADS=1 python benchmarks/bench_sparse.py            # N = 20 and N = 50
    OMP_NUM_THREADS=1 python benchmarks/bench_sparse.py --sizes 20  # just N = 20

At N = 50 the SDP's 2N x 2N LMI makes one solve take most of a minute, so the
SDP runs there on ``--sdp-gammas-large`` weights only (seconds per γ is the
figure of merit); ``--full`` runs its whole default path.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from baselines import sparse_admm, sparse_sdp  # noqa: E402
from codesign.instances import paper_instance  # noqa: E402

TARGETS = {"sparse_admm": 5.0, "sparse_sdp": 10.0}  # seconds for 10 γ at N = 20


def run(method, instance, **kwargs):
    start = time.perf_counter()
    designs = method(instance, **kwargs)
    total = time.perf_counter() - start
    return designs, total


def describe(name, n, a_norm, designs, total):
    ok = [d for d in designs if d.status == "optimal"]
    # The γ = inf end is the decentralized gain, computed once: count the finite γ.
    gammas = sum(np.isfinite(d.params["gamma"]) for d in designs)
    per_gamma = total / gammas
    polish = sum(d.extras.get("polish_iterations", 0) for d in designs)
    solve = [d.extras["solve_time"] for d in designs if "solve_time" in d.extras]
    links = [d.links for d in ok]
    line = (f"{name:12s} N={n:<3d} a={a_norm:<6g} {gammas:2d} gammas + inf  total {total:7.2f} s  "
            f"{per_gamma:6.2f} s/gamma  links {max(links, default=0)}..{min(links, default=0)}  "
            f"cost {min(d.cost for d in ok):.4f}..{max(d.cost for d in ok):.4f}  "
            f"{len(ok)}/{len(designs)} optimal  polish iters {polish}")
    if solve:
        line += f"  solver {np.median(solve):.2f} s/solve (median)"
    if n == 20 and gammas == 10:
        line += f"  [target < {TARGETS[name]:g} s: {'met' if total < TARGETS[name] else 'MISSED'}, x{total / TARGETS[name]:.2f}]"
    print(line, flush=True)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", type=int, nargs="+", default=[20, 50])
    parser.add_argument("--a-norms", type=float, nargs="+", default=[0.995, 1.05])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--sdp-gammas-large", type=float, nargs="+", default=[1e-3, 3e-2],
                        help="SDP weights (normalized units) for N > 20 (default: two)")
    parser.add_argument("--full", action="store_true", help="full default SDP path at every N")
    args = parser.parse_args(argv)
    print(f"cores available: {len(os.sched_getaffinity(0))}, OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS')}, "
          f"load average {os.getloadavg()[0]:.2f}")
    for n in args.sizes:
        for a_norm in args.a_norms:
            instance = paper_instance(args.seed, n=n, a_norm=a_norm)
            designs, total = run(sparse_admm, instance)
            describe("sparse_admm", n, a_norm, designs, total)
            if n <= 20 or args.full:
                designs, total = run(sparse_sdp, instance)
            else:
                designs, total = run(sparse_sdp, instance, gammas=args.sdp_gammas_large)
            describe("sparse_sdp", n, a_norm, designs, total)
            if n > 20 and not args.full:
                break  # one a_norm is enough for the large SDP's seconds per γ


if __name__ == "__main__":
    main()
