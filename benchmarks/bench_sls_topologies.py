"""SLS on the topology family: every graph solved, against one solve per distinct graph.

``sls_topologies`` runs SLS on the given graph, the plant graph, its 2- and 3-hop
closures and the complete graph. Where closures coincide (on the paper's family at
N = 20 the 2-hop closure is usually complete already: 145 of the ``tradeoff``
preset's 150 instances have 3 distinct graphs among the 5) the QP is the same and is
now solved once. Prints, for ``--instances`` paper instances per a_norm and in one
run, the seconds of one ``sls`` call per graph (the code before 2026-11-26) and of
``sls_topologies``, their ratio, and whether the designs are equal to the last bit.

Run: ``OMP_NUM_THREADS=1 python benchmarks/bench_sls_topologies.py [--instances 3]``
"""

from __future__ import annotations

import argparse
import math
import time

from baselines import sls, sls_topologies
from baselines.sls import TOPOLOGY_FAMILY
from codesign import paper_instance


def same(a, b) -> bool:
    costs = a.cost == b.cost or (math.isnan(a.cost) and math.isnan(b.cost))
    return costs and (a.status, a.links, a.params) == (b.status, b.links, b.params)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--instances", type=int, default=3, help="paper instances per a_norm (N = 20)")
    args = parser.parse_args()
    sls(paper_instance(0), graph="plant")  # imports and first-call setup outside the timings
    print(f"{'a_norm':>7} {'seed':>4} {'graphs':>6} {'each graph':>10} {'family':>7} {'ratio':>6}  equal")
    totals = [0.0, 0.0]
    for a_norm in (0.995, 1.05, 1.2):
        for seed in range(args.instances):
            instance = paper_instance(seed, a_norm=a_norm)
            start = time.perf_counter()
            alone = [sls(instance, graph=name) for name in TOPOLOGY_FAMILY]
            each = time.perf_counter() - start
            start = time.perf_counter()
            family = sls_topologies(instance)
            once = time.perf_counter() - start
            totals[0] += each
            totals[1] += once
            solved = sum("same_graph_as" not in d.extras for d in family)
            equal = all(same(a, b) for a, b in zip(alone, family))
            print(f"{a_norm:>7} {seed:>4} {solved:>3} of {len(family)} {each:>8.2f} s {once:>5.2f} s "
                  f"{each / once:>5.2f}x  {equal}")
    print(f"total: {totals[0]:.1f} s each graph, {totals[1]:.1f} s family ({totals[0] / totals[1]:.2f}x)")


if __name__ == "__main__":
    main()
