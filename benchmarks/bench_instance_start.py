"""A fresh process's first paper instance: the basis rotation by scipy.stats.ortho_group against numpy's QR.

Every process that builds an instance (``compare run``, each of its workers, each test
process) rotates the degenerate eigenspaces of the graph's Laplacian by a Haar-random
orthogonal matrix. ``scipy.stats.ortho_group`` needs ``import scipy.stats``, which
loads all of scipy's distributions; :func:`codesign.instances.haar_orthogonal` draws
the same matrix (same algorithm, same stream) with numpy alone. Prints, measured in
one run: the median over ``--repeats`` fresh processes of the seconds from the start
of the build to the instance (the imports the build itself triggers included), each
way, their ratio, and whether the two instances are the same to the last bit.

    python benchmarks/bench_instance_start.py [--repeats 5]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys

CHILD = """
import hashlib
import time
import codesign.instances as instances
if {scipy}:
    def rotation(dim, rng):
        import scipy.stats
        return scipy.stats.ortho_group.rvs(dim, random_state=rng)
    instances.haar_orthogonal = rotation
t = time.perf_counter()
inst = instances.paper_instance(0, n=20)
seconds = time.perf_counter() - t
print(seconds, hashlib.sha256(inst.A.tobytes() + inst.B.tobytes()).hexdigest())
"""


def first_instance(scipy: bool) -> tuple[float, str]:
    out = subprocess.run([sys.executable, "-c", CHILD.format(scipy=scipy)], capture_output=True, text=True,
                         check=True, env={**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
                                          "MKL_NUM_THREADS": "1"}).stdout.split()
    return float(out[0]), out[1]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    seconds = {True: [], False: []}
    digests = {}
    for _ in range(args.repeats):
        for scipy in (True, False):
            s, digest = first_instance(scipy)
            seconds[scipy].append(s)
            digests[scipy] = digest
    old, new = statistics.median(seconds[True]), statistics.median(seconds[False])
    print(f"first paper instance (N = 20) in a fresh process, median of {args.repeats}:")
    print(f"  scipy.stats.ortho_group       {old:6.3f} s")
    print(f"  numpy QR (haar_orthogonal)    {new:6.3f} s")
    print(f"  ratio {old / new:.1f}x; same A to the last bit: {digests[True] == digests[False]}")


if __name__ == "__main__":
    main()
