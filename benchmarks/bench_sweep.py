"""Wall time of a fixed small sweep with 1 and 2 local workers, and the projected full sweep.

The small sweep is the ``tradeoff`` preset cut to ``--seeds`` instances per a_norm
(every method, every β); the runs are independent, so the full preset (30 seeds)
should take about ``30 / seeds`` times the small sweep's wall time with the same
workers. The projection is pessimistic for the batched GRNN methods, which train
up to 25 models per task at full scale but fewer here.

    python benchmarks/bench_sweep.py             # 1 seed per a_norm, 1 and 2 workers
    python benchmarks/bench_sweep.py --seeds 2 --workers 2
"""

from __future__ import annotations

import argparse
import tempfile
import time
from dataclasses import replace
from pathlib import Path

from codesign.status import OPTIMAL
from compare import Store, load_spec, run_experiment


def small_sweep(seeds: int):
    spec = load_spec("tradeoff")
    return replace(spec, name=f"tradeoff-{seeds}-seeds", instances=replace(spec.instances, seeds=tuple(range(seeds))))


def timed(spec, workers: int) -> float:
    with tempfile.TemporaryDirectory() as folder, Store(Path(folder) / "bench.sqlite") as store:
        start = time.perf_counter()
        summary = run_experiment(spec, store, workers=workers, progress=False)
        seconds = time.perf_counter() - start
    bad = {k: v for k, v in summary.statuses.items() if k != OPTIMAL}
    print(f"  {workers} worker(s): {seconds:7.1f} s for {summary.computed} runs"
          + (f" (non-optimal designs: {bad})" if bad else ""))
    return seconds


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=1, help="instances per a_norm in the small sweep")
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2], help="worker counts to time")
    args = parser.parse_args()
    spec = small_sweep(args.seeds)
    full = len(load_spec("tradeoff").runs())
    print(f"small sweep: tradeoff preset with {args.seeds} instance(s) per a_norm, {len(spec.runs())} runs "
          f"(the full preset has {full})")
    times = {w: timed(spec, w) for w in args.workers}
    if 1 in times and 2 in times:
        print(f"speed-up with 2 workers: {times[1] / times[2]:.2f}x")
    scale = 30 / args.seeds
    for workers, seconds in times.items():
        print(f"projected full tradeoff preset with {workers} worker(s): {seconds * scale / 60:.1f} min")


if __name__ == "__main__":
    main()
