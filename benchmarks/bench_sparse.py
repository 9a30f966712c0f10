"""Seconds per γ of the sparse static-gain paths (ℓ1 ADMM and ℓ1 SDP), in one run.

Targets: a 10-γ path on an N = 20 paper instance in under 5 s (ADMM) and under 10 s
(SDP) on 2 cores (issue 4); the SDP at N = 50 in at most 5 s per γ and its 10-γ path
at N = 100 in under 10 minutes (issue 15). The SDP runs with its default solver (SCS)
on the whole path at every N, and beside it, in the same run, with Clarabel (the
interior-point reference the toolkit used before): its whole path at N = 20, the
``--clarabel-gammas`` at N = 50 (40-60 s per γ), not at all above its size guard (64
states; over 20 minutes per γ at 100). Where both solved a γ the script says whether the patterns agree.
Run from the repository root::

    OMP_NUM_THREADS=1 python benchmarks/bench_sparse.py              # N = 20, 50, 100 (~9 min)
    OMP_NUM_THREADS=1 python benchmarks/bench_sparse.py --sizes 20   # just N = 20
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
from baselines._sparse import pattern_of  # noqa: E402
from baselines.sparse_sdp import SDP_MAX_STATES  # noqa: E402
from codesign.instances import paper_instance  # noqa: E402
from codesign.status import OPTIMAL  # noqa: E402

TARGETS = {"sparse_admm": 5.0, "sparse_sdp": 10.0}  # seconds for 10 γ at N = 20
SDP_PER_GAMMA_N50 = 5.0  # seconds per γ at N = 50
SDP_PATH_N100 = 600.0  # seconds for the 10-γ path at N = 100


def run(method, instance, **kwargs):
    start = time.perf_counter()
    designs = method(instance, **kwargs)
    total = time.perf_counter() - start
    return designs, total


def describe(name, n, a_norm, designs, total):
    ok = [d for d in designs if d.status == OPTIMAL]
    # The γ = inf end is the decentralized gain, computed once: count the finite γ.
    gammas = sum(np.isfinite(d.params["gamma"]) for d in designs)
    per_gamma = total / gammas
    polish = sum(d.extras.get("polish_iterations", 0) for d in designs)
    solve = [d.extras["solve_time"] for d in designs if "solve_time" in d.extras]
    links = [d.links for d in ok]
    line = (f"{name:21s} N={n:<3d} a={a_norm:<6g} {gammas:2d} gammas + inf  total {total:7.2f} s  "
            f"{per_gamma:6.2f} s/gamma  links {max(links, default=0)}..{min(links, default=0)}  "
            f"cost {min((d.cost for d in ok), default=np.nan):.4f}..{max((d.cost for d in ok), default=np.nan):.4f}  "
            f"{len(ok)}/{len(designs)} optimal  polish iters {polish}")
    if solve:
        line += f"  solver {np.median(solve):.2f} s/solve (median), {max(solve):.2f} max"
    base = name.split()[0]
    if n == 20 and gammas == 10:
        line += f"  [target < {TARGETS[base]:g} s: {'met' if total < TARGETS[base] else 'MISSED'}, x{total / TARGETS[base]:.2f}]"
    if name == "sparse_sdp (scs)" and n == 50:
        line += f"  [target <= {SDP_PER_GAMMA_N50:g} s/gamma: {'met' if per_gamma <= SDP_PER_GAMMA_N50 else 'MISSED'}]"
    if name == "sparse_sdp (scs)" and n == 100 and gammas == 10:
        line += f"  [target < {SDP_PATH_N100:g} s: {'met' if total < SDP_PATH_N100 else 'MISSED'}]"
    print(line, flush=True)
    for d in designs:
        if d.status != OPTIMAL:
            print(f"    gamma {d.params['gamma']:.3g}: {d.status} after {d.extras.get('iterations', '?')} iterations "
                  f"({d.extras.get('solve_time', float('nan')):.1f} s): {d.message}", flush=True)
    return per_gamma


def compare_patterns(fast, reference):
    """How many γ give the same pattern with both solvers, and the largest cost gap."""
    by_gamma = {d.params["gamma"]: d for d in fast if d.controller is not None}
    same, gap, count = 0, 0.0, 0
    for r in reference:
        f = by_gamma.get(r.params["gamma"])
        if f is None or r.controller is None or not np.isfinite(r.params["gamma"]):
            continue
        count += 1
        if np.array_equal(pattern_of(np.asarray(f.controller.K)), pattern_of(np.asarray(r.controller.K))):
            same += 1
            gap = max(gap, abs(f.cost - r.cost) / r.cost)
    return f"same pattern at {same} of {count} gammas (largest relative cost gap there {gap:.1e})"


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", type=int, nargs="+", default=[20, 50, 100])
    parser.add_argument("--a-norms", type=float, nargs="+", default=[0.995, 1.05])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--clarabel-gammas", type=float, nargs="+", default=[1e-3, 3e-2],
                        help="Clarabel's weights (normalized units) for N > 20 (default: two)")
    args = parser.parse_args(argv)
    print(f"cores available: {len(os.sched_getaffinity(0))}, OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS')}, "
          f"load average {os.getloadavg()[0]:.2f}")
    for n in args.sizes:
        for a_norm in args.a_norms:
            instance = paper_instance(args.seed, n=n, a_norm=a_norm)
            designs, total = run(sparse_admm, instance)
            describe("sparse_admm", n, a_norm, designs, total)
            scs, total = run(sparse_sdp, instance, max_states=instance.n)  # whatever size is asked
            scs_per_gamma = describe("sparse_sdp (scs)", n, a_norm, scs, total)
            if instance.n <= SDP_MAX_STATES["clarabel"]:
                kwargs = {"solver": "clarabel"} if n <= 20 else {"solver": "clarabel", "gammas": args.clarabel_gammas}
                if n > 20:  # SCS on the same weights, for a like-for-like seconds per γ
                    same_gammas, scs_total = run(sparse_sdp, instance, gammas=args.clarabel_gammas)
                    scs_per_gamma = describe("sparse_sdp (scs)", n, a_norm, same_gammas, scs_total)
                    scs = scs + same_gammas
                reference, total = run(sparse_sdp, instance, **kwargs)
                clarabel_per_gamma = describe("sparse_sdp (clarabel)", n, a_norm, reference, total)
                print(f"    clarabel / scs seconds per gamma: x{clarabel_per_gamma / scs_per_gamma:.1f}; "
                      f"{compare_patterns(scs, reference)}", flush=True)
            else:
                print(f"    clarabel not run at {instance.n} states: over 20 minutes per gamma (size guard)", flush=True)
            if n > 50:
                break  # one a_norm: the N = 100 path alone takes minutes


if __name__ == "__main__":
    main()
