"""A GRNN batch at hundreds of nodes in one process against a 2-worker dask cluster that spreads it.

Above ``codesign.cluster.SPREAD_ABOVE`` states a GRNN batch run as a task of a dask cluster trains
each fused-engine model as a task of its own and scores each design as another. Prints, measured
in one run: the wall seconds of ``grnn_batch`` on ``--instances`` paper instances of ``--n`` nodes
(ensemble 2, ``--steps`` steps, float32) in this process and as one task of a local 2-worker
cluster (single-threaded worker processes), the ratio, and whether the designs agree to the last
bit. On 2 cores the ideal ratio is 2.

    python benchmarks/bench_cluster_spread.py [--n 500] [--steps 60] [--instances 1]
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def batch(n: int, steps: int, instances: int):
    from codesign import paper_instance
    from codesign.learned.grnn import grnn_batch

    jobs = [(paper_instance(seed, n=n, a_norm=1.05), dict(seed=0, steps=steps, ensemble=2, dtype="float32"))
            for seed in range(instances)]
    start = time.perf_counter()
    designs = grnn_batch(jobs)
    return time.perf_counter() - start, designs


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=500)
    parser.add_argument("--steps", type=int, default=60)
    parser.add_argument("--instances", type=int, default=1)
    args = parser.parse_args()
    from distributed import Client, LocalCluster

    from compare.run.execution import limit_threads

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        with Client(cluster) as client:
            client.run(limit_threads)
            client.submit(batch, 30, 2, 1, pure=False).result()  # warm: imports, compiled kernels
            spread, remote = client.submit(batch, args.n, args.steps, args.instances, pure=False).result()
    limit_threads()
    batch(30, 2, 1)
    alone, local = batch(args.n, args.steps, args.instances)
    same = all(a.cost == b.cost and all(np.array_equal(a.controller.arrays()[k], b.controller.arrays()[k])
                                        for k in "SFWG") for a, b in zip(local, remote))
    print(f"grnn_batch, {args.instances} instance(s) x ensemble 2, N = {args.n}, {args.steps} steps, float32")
    print(f"  one process        {alone:7.1f} s")
    print(f"  2-worker cluster   {spread:7.1f} s   ratio {alone / spread:.2f}x   same designs: {same}")


if __name__ == "__main__":
    main()
