"""Localized SLS (``sls_local``) against the joint QP (``sls``), and its time against N, in one run.

Part 1, where both apply (paper instances, N = 20 and 50, FIR 10 on the plant graph):
the joint QP solved by Clarabel against the columns' exact KKT solves with the locality
at the graph's diameter (the same problem): seconds of each, their ratio and the
relative cost difference; then the localized designs at 2 and 3 hops and their cost.

Part 2, time against N (paper family, ``connect = "bridge"``, one instance per size, FIR
10, 3 hops): seconds to design (all columns), seconds to score, the largest column's
variables, how many columns needed the dense rank-revealing solve, and the seconds per
column, which stay about flat when the cost grows linearly in N. Issue 33's target:
localized SLS at N = 1000 in at most 10 minutes on 2 cores. Single-threaded BLAS. Run
from the repository root::

    python benchmarks/bench_sls_local.py                       # N up to 1000 (~5 min)
    python benchmarks/bench_sls_local.py --sizes 100 200       # a quick look
"""

from __future__ import annotations

import os

# Single-threaded BLAS: the variables must be set before numpy loads its BLAS.
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import importlib  # noqa: E402
import resource  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from threadpoolctl import threadpool_limits  # noqa: E402

from baselines import sls, sls_local  # noqa: E402
from codesign import hop_distances, paper_instance  # noqa: E402
from codesign.status import OPTIMAL  # noqa: E402
from baselines.sls import topology  # noqa: E402

TARGET_N1000 = 600.0  # seconds (issue 33, on 2 cores)
local_module = importlib.import_module("baselines.sls_local")


def timed(function, *args, **kwargs):
    start = time.perf_counter()
    out = function(*args, **kwargs)
    return out, time.perf_counter() - start


def counting_fallbacks():
    """Wrap the dense solve so that a run can say how many columns took it; returns the counter."""
    count = [0]
    original = local_module._min_weighted_norm

    def counted(*args):
        count[0] += 1
        return original(*args)

    local_module._min_weighted_norm = counted
    return count


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", type=int, nargs="+", default=[100, 200, 500, 1000])
    parser.add_argument("--fir", type=int, default=10)
    parser.add_argument("--locality", type=int, default=3)
    args = parser.parse_args(argv)
    limits = threadpool_limits(limits=1)  # also caps a BLAS that ignored the variables
    print(f"cores available: {os.cpu_count()}, BLAS threads 1, load average {os.getloadavg()[0]:.2f}")
    fallbacks = counting_fallbacks()

    print(f"\n1. joint QP (sls, Clarabel) against the columns (sls_local at the diameter), FIR {args.fir}, plant graph")
    print(f"{'N':>5s} {'sls s':>8s} {'local s':>8s} {'ratio':>6s} {'rel.diff':>9s} {'cost':>10s}   localized: hops cost")
    for n in (20, 50):
        instance = paper_instance(0, n=n)
        diameter = int(hop_distances(topology(instance, "plant")).max())
        joint, joint_s = timed(sls, instance, fir=args.fir)
        whole, whole_s = timed(sls_local, instance, locality=diameter, fir=args.fir)
        line = (f"{n:5d} {joint_s:8.2f} {whole_s:8.2f} {joint_s / whole_s:6.1f} "
                f"{abs(whole.cost - joint.cost) / joint.cost:9.1e} {joint.cost:10.6f}  ")
        for hops in (2, 3):
            design = sls_local(instance, locality=hops, fir=args.fir)
            line += f" {hops}: {design.cost:.6f}" if design.status == OPTIMAL else f" {hops}: {design.status}"
        print(line + f"   (diameter {diameter})", flush=True)

    print(f"\n2. sls_local against N: FIR {args.fir}, {args.locality} hops of the plant graph, paper family (bridged)")
    print(f"{'N':>5s} {'design s':>9s} {'score s':>8s} {'s/column':>9s} {'largest':>8s} {'dense':>6s} "
          f"{'status':>10s} {'cost':>10s} {'peak MB':>8s}")
    for n in args.sizes:
        instance = paper_instance(0, n=n, connect="bridge")
        fallbacks[0] = 0
        design, total = timed(sls_local, instance, locality=args.locality, fir=args.fir)
        score = total - design.seconds
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        cost = f"{design.cost:10.6f}" if design.status == OPTIMAL else f"{'-':>10s}"
        print(f"{n:5d} {design.seconds:9.1f} {score:8.1f} {design.seconds / n:9.3f} "
              f"{design.extras['largest_column']:8d} {fallbacks[0]:6d} {design.status:>10s} {cost} {peak:8.0f}",
              flush=True)
        if n == 1000:
            verdict = "met" if total <= TARGET_N1000 else "NOT met"
            print(f"    [target: localized SLS at N = 1000 in <= {TARGET_N1000:.0f} s on 2 cores: {verdict} "
                  f"on one thread, {total:.0f} s]")
    del limits


if __name__ == "__main__":
    main()
