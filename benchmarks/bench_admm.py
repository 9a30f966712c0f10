"""The ℓ1 ADMM path (``sparse_admm``) after issue 60, against the code before it, in one run.

Part 1, the issue's case: ``paper_instance(1, n=6, a_norm=1.05)`` at γ = 3, 10 and 100 (one
path, as the issue ran it). Before, each γ ran 2,000 or more ADMM iterations (163-209 s on
a loaded 2-core machine) and ended ``diverged``; the target is all three in at most 60 s, each
a usable design, the diagonal gain's cost where the pattern is diagonal, and γ = 3 within 1 %
of the proximal Newton path's 1.363193. ``--with-before`` also runs the code before on them
(about 10 minutes).

Part 2, the default path (10 γ, polished) on paper instances, N = 20 by default: seconds
(wall and this process's CPU, the least of ``--repeats`` runs) of the code before and after,
run in turn on the same instance, their ratio, the evaluations of J(K) (the K-steps' work: a
count the machine's load does not move), ADMM iterations, and whether every design
(links, cost to 1e-6 relative) is the same; then the ratio over all instances of a size. The
target is a ratio of at most 1 (no slower). ``--sizes 100`` runs N = 100: about 25 minutes
for seed 0 with ``--repeats 1``, 20 of them the code before at ‖A‖ = 1.2 (2026-12-07, a
loaded 2-core machine: before 748 s CPU, after 75 s, the same designs).

The code before is read from git (``--before``, the commit the change started from) and
loaded beside the current one. Single-threaded BLAS. Run from the repository root::

    python benchmarks/bench_admm.py                                   # parts 1 and 2 at N = 20 (~4 min)
    python benchmarks/bench_admm.py --skip-issue --sizes 100 --seeds 0 --repeats 1   # N = 100 (~25 min)
"""

from __future__ import annotations

import os

# Single-threaded BLAS: the variables must be set before numpy loads its BLAS.
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import importlib.util  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from baselines import decentralized, sparse_admm  # noqa: E402
from codesign import paper_instance  # noqa: E402
from codesign.status import USABLE  # noqa: E402

BEFORE = "568bcb3"          # the commit issue 60 was filed against
ISSUE_GAMMAS = (3.0, 10.0, 100.0)
ISSUE_TARGET = 60.0         # seconds for the three γ
NEWTON_GAMMA_3 = 1.363193   # sparse_newton at γ = 3 (1 link)


def load_before(rev: str):
    """``baselines/sparse_admm.py`` as of ``rev``, loaded beside the current one (its method renamed)."""
    source = subprocess.run(["git", "show", f"{rev}:baselines/sparse_admm.py"], cwd=ROOT, check=True,
                            capture_output=True, text=True).stdout
    source = source.replace('@method("sparse_admm",', '@method("sparse_admm_before",')
    path = Path(tempfile.mkdtemp()) / "sparse_admm_before.py"
    path.write_text(source)
    spec = importlib.util.spec_from_file_location("baselines._sparse_admm_before", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module.sparse_admm


def timed(function, *args, **kwargs):
    wall, cpu = time.perf_counter(), time.process_time()
    out = function(*args, **kwargs)
    return out, time.perf_counter() - wall, time.process_time() - cpu


def counted(function, *args, **kwargs):
    """``timed``, and the evaluations of J(K) by doubling the ADMM module made (its K-steps' work, and a
    number the machine's load does not move)."""
    module = sys.modules[function.__module__]
    real, calls = module.infinite_horizon_point, [0]

    def evaluation(*a, **k):
        calls[0] += 1
        return real(*a, **k)

    module.infinite_horizon_point = evaluation
    try:
        return (*timed(function, *args, **kwargs), calls[0])
    finally:
        module.infinite_horizon_point = real


def issue_case(before=None) -> None:
    instance = paper_instance(1, n=6, a_norm=1.05)
    diagonal, seconds, _ = timed(decentralized, instance)
    print(f"Part 1: paper seed 1, N = 6, a_norm 1.05, gammas {list(ISSUE_GAMMAS)}; decentralized "
          f"{diagonal.cost:.6f} ({seconds:.1f} s alone)")
    runs = [("after", sparse_admm)] + ([("before", before)] if before else [])
    for name, method in runs:
        designs, wall, cpu = timed(method, instance, gammas=list(ISSUE_GAMMAS))
        ok = True
        for design in designs:
            gamma = design.params["gamma"]
            usable = design.status in USABLE
            expected = (NEWTON_GAMMA_3 if gamma == 3.0 else diagonal.cost) if np.isfinite(gamma) else diagonal.cost
            close = usable and abs(design.cost - expected) <= (1e-2 if gamma == 3.0 else 1e-8) * expected
            ok &= close
            print(f"  {name:6s} gamma {gamma:>5g}: {design.status:9s} links {design.links:2d} cost {design.cost:.6f} "
                  f"(expected {expected:.6f}: {'yes' if close else 'NO'})  ADMM iterations "
                  f"{design.extras.get('admm_iterations', '-')}, {design.seconds:.1f} s  {design.message[:90]}")
        verdict = "met" if ok and wall <= ISSUE_TARGET else "MISSED"
        print(f"  {name}: {wall:.1f} s wall, {cpu:.1f} s CPU for the three gammas "
              f"[target <= {ISSUE_TARGET:g} s and every design as expected: {verdict}]", flush=True)


def same_designs(a, b) -> tuple[bool, list]:
    differences = []
    for x, y in zip(a, b, strict=True):
        if x.links != y.links or x.status != y.status or not abs(x.cost - y.cost) <= 1e-6 * abs(x.cost):
            differences.append(f"gamma {x.params['gamma']:.3g}: before {x.status} {x.links} links {x.cost:.6f}, "
                               f"after {y.status} {y.links} links {y.cost:.6f}")
    return not differences, differences


def default_path(before, sizes, seeds, repeats) -> None:
    print(f"Part 2: default path (10 gammas + inf, polished), code before and after run in turn (ABBA...), "
          f"the least of {repeats} runs each")
    totals = {}
    for n in sizes:
        for a_norm in (1.05, 1.2):
            for seed in seeds:
                instance = paper_instance(seed, n=n, a_norm=a_norm)
                runs = {"before": [], "after": []}
                for rep in range(repeats):  # alternate the order: a machine's load drifts
                    order = (("before", before), ("after", sparse_admm))
                    for name, method in order if rep % 2 == 0 else order[::-1]:
                        runs[name].append(counted(method, instance))
                old, new = runs["before"][0][0], runs["after"][0][0]
                (old_wall, old_cpu), (new_wall, new_cpu) = (
                    (min(r[1] for r in runs[k]), min(r[2] for r in runs[k])) for k in ("before", "after"))
                old_evals, new_evals = runs["before"][0][3], runs["after"][0][3]
                total = totals.setdefault(n, [0.0, 0.0, 0, 0])
                for i, value in enumerate((old_cpu, new_cpu, old_evals, new_evals)):
                    total[i] += value
                same, differences = same_designs(old, new)
                its = [sum(d.extras.get("admm_iterations", 0) for d in ds) for ds in (old, new)]
                print(f"  N={n:<3d} a={a_norm:<4g} seed={seed}: before {old_wall:6.1f} s wall {old_cpu:6.1f} s CPU, "
                      f"after {new_wall:6.1f} s wall {new_cpu:6.1f} s CPU, ratio (CPU) {new_cpu / old_cpu:.2f}, "
                      f"J evaluations {old_evals} -> {new_evals} ({new_evals / old_evals:.2f}), ADMM iterations "
                      f"{its[0]} -> {its[1]}, designs {'the same' if same else 'DIFFER'}", flush=True)
                for line in differences:
                    print(f"      {line}")
        old_cpu, new_cpu, old_evals, new_evals = totals[n]
        ratio = new_cpu / old_cpu
        print(f"  N={n}: all instances, before {old_cpu:.1f} s CPU, after {new_cpu:.1f} s CPU, ratio {ratio:.2f} "
              f"[target <= 1 (no slower; single ratios move by about 15 % with the machine's load): "
              f"{'met' if ratio <= 1.0 else 'MISSED'}]; J evaluations {old_evals} -> {new_evals}, ratio "
              f"{new_evals / old_evals:.2f}", flush=True)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[20], help="N of part 2 (default: 20)")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2], help="seeds of part 2 (default: 0 1 2)")
    parser.add_argument("--repeats", type=int, default=2, help="runs of each path per instance (default 2)")
    parser.add_argument("--before", default=BEFORE, help=f"git revision of the code before (default {BEFORE})")
    parser.add_argument("--with-before", action="store_true", help="run the code before on part 1 (~10 min)")
    parser.add_argument("--skip-issue", action="store_true", help="part 2 only")
    args = parser.parse_args(argv)
    before = load_before(args.before)
    if not args.skip_issue:
        issue_case(before if args.with_before else None)
    default_path(before, args.sizes, args.seeds, args.repeats)


if __name__ == "__main__":
    main()
