"""Seconds per refit per controller class, at N = 20 and N = 100, and what a stored design saves.

``refit`` fits the best controller of one class on a given graph (baselines/refit.py). For one
paper instance per size, the graph of the delayed l1 path's design nearest ``--links-per-node``
links per node is refit with each class (the GRNN with ``--steps`` training steps, one ensemble
member at N = 100), and each class's seconds are printed, with the seconds of the path that chose
the graph: a refit in the harness reuses that stored design instead of computing it again
(``compare run`` plans refits from the store), so the ratio is what reuse saves per refit.

Run: ``OMP_NUM_THREADS=1 python benchmarks/bench_refit.py [--sizes 20 100] [--steps 150]``
"""

from __future__ import annotations

import argparse
import time

from baselines import refit_design, sparse_delayed
from codesign import paper_instance
from codesign.graphs import design_graph


def timed(function, *args, **kwargs):
    start = time.perf_counter()
    value = function(*args, **kwargs)
    return value, time.perf_counter() - start


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[20, 100])
    parser.add_argument("--steps", type=int, default=150, help="the GRNN refit's training steps")
    parser.add_argument("--links-per-node", type=float, default=1.0)
    args = parser.parse_args()
    refit_design(paper_instance(0, n=4, degree=2), [[0, 1, 0, 0]] * 4, "sls")  # imports outside the timings
    print(f"{'N':>4} {'links':>5} {'class':>13} {'status':>10} {'cost':>9} {'seconds':>8} {'path s / refit s':>17}")
    for n in args.sizes:
        instance = paper_instance(0, n=n, a_norm=1.05)
        gammas = [0.0, 1e-3, 3e-3, 1e-2] if n > 50 else None
        path, path_seconds = timed(sparse_delayed, instance, gammas=gammas)
        usable = [d for d in path if d.ok and d.links > 0]
        source = min(usable, key=lambda d: abs(d.links - args.links_per_node * n))
        graph = design_graph(instance, source)
        settings = {"steps": args.steps, "ensemble": 3 if n <= 50 else 1, "dtype": "float32"}
        for name, kwargs in (("delayed", {}), ("instantaneous", {}), ("sls", {}),
                             ("grnn", dict(settings)), ("grnn", dict(settings, activation="identity"))):
            design, seconds = timed(refit_design, instance, graph, name, **kwargs)
            label = name if name != "grnn" else f"grnn {kwargs.get('activation', 'tanh')}"
            print(f"{n:>4} {source.links:>5} {label:>13} {design.status:>10} {design.cost:>9.5f} "
                  f"{seconds:>8.2f} {path_seconds / seconds:>17.1f}")
        print(f"{n:>4} the delayed l1 path that chose the graph: {path_seconds:.1f} s for {len(path)} designs")


if __name__ == "__main__":
    main()
