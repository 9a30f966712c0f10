"""One draw of the paper family's graph: the kNN neighbours on the sorted line against the dense sort.

``paper_instance`` redraws positions until the 6-nearest-neighbour graph is connected and gives up
after ``MAX_REDRAWS`` draws. Prints, measured in one run, per ``--n``: the milliseconds of one draw's
neighbour sets and connectivity test by the dense O(n^2 log n) sort (what every draw cost before) and
by the sorted-line window (what a draw costs now), their ratio, whether the sets agree, and the
seconds ``MAX_REDRAWS`` draws take each way.

    python benchmarks/bench_redraw.py [--n 500 1500 3000] [--draws 20]
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def dense_draw(positions, degree):
    from scipy.sparse.csgraph import connected_components

    from codesign.instances import knn_graph

    nearest = np.argsort(np.abs(positions[:, None] - positions[None, :]), axis=1, kind="stable")[:, :degree]
    comm = knn_graph(positions, degree, nearest)
    return nearest, connected_components(comm, directed=False, return_labels=False) == 1


def window_draw(positions, degree):
    from codesign.instances import is_connected, knn_neighbours

    nearest = knn_neighbours(positions, degree)
    return nearest, is_connected(nearest)


def per_draw(draw, draws_of_positions, degree):
    start = time.perf_counter()
    results = [draw(p, degree) for p in draws_of_positions]
    return (time.perf_counter() - start) / len(draws_of_positions), results


def main():
    from codesign.instances import MAX_REDRAWS

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, nargs="+", default=[500, 1500, 3000])
    parser.add_argument("--draws", type=int, default=20)
    parser.add_argument("--degree", type=int, default=6)
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    print(f"{'n':>6} {'dense ms':>9} {'window ms':>10} {'ratio':>7} {'agree':>6} "
          f"{'dense s / limit':>16} {'window s / limit':>17}")
    for n in args.n:
        positions = [rng.uniform(0.0, 1.0, n) for _ in range(args.draws)]
        dense, dense_out = per_draw(dense_draw, positions, args.degree)
        window, window_out = per_draw(window_draw, positions, args.degree)
        agree = all(np.array_equal(np.sort(a[0], axis=1), np.sort(b[0], axis=1)) and a[1] == b[1]
                    for a, b in zip(dense_out, window_out))
        print(f"{n:>6} {1e3 * dense:>9.2f} {1e3 * window:>10.3f} {dense / window:>7.0f} {str(agree):>6} "
              f"{MAX_REDRAWS * dense:>16.1f} {MAX_REDRAWS * window:>17.2f}")


if __name__ == "__main__":
    main()
