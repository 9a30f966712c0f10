"""Seconds per 750-step GRNN training, per engine, against the machine's own matrix-product peak.

Trains M GRNN models of the paper's size (N = 20, T = 50, batch 20, h = 5,
validation curve every 10 steps on 100 draws) for a fixed number of steps with
:func:`codesign.learned.grnn_bptt.train_grnn` (the one trainer with the GRNN model), for M = 1 and M = 64 (or ``--models``),
with each engine (``torch``: one torch call per product and time step;
``fused``: one compiled numba pass per model, :mod:`codesign.learned.fused`), and
prints, measured in this one run:

* seconds per 750-step model of each, per core, and the ratios;
* the arithmetic of one model (floating-point operations counted from the
  torch engine's dense products) and the rate it achieves per core, against
  the single-core peak of a large matrix product measured here (``matmul
  peak``). The fused engine skips the zeros of S, A and B, so its rate is an
  effective one: the dense work divided by its time;
* the torch engine's *kernel bound*: the same per-time-step products and
  elementwise passes it issues, each timed alone at the stack's shapes and
  summed. No arrangement of torch calls beats it;
* seconds per model at N = 50 and N = 100 (``--sizes``), per engine.

The paper's own code takes 20-28 s per model on a 2-core machine. The trainer
runs on CPU; no GPU figure is measured here. Compiling the fused kernels
(seconds, once per shape; numba caches them on disk) happens in the warm-up.

    python benchmarks/bench_grnn.py                 # float64 and float32, 2 processes x 1 thread
    python benchmarks/bench_grnn.py --procs 1 --threads 2 --dtype float32 --steps 30

M = 1 runs in one process; the M-model run splits the models over ``--procs``
single-threaded processes (one stack each, as the runner's workers do), which
uses 2 cores better than 2 torch threads on one stack of tiny matrix products.
Seconds per model per core are the wall seconds per model times the cores used.
"""

from __future__ import annotations

import argparse
import multiprocessing
import time

import numpy as np
import torch

from codesign import paper_instance
from codesign.learned.trainer import selection_set
from codesign.learned.grnn_bptt import ModelSpec, init_fwg, train_grnn


#: The timed run's settings (the paper's): the flop count and the kernel bound use the same.
HIDDEN, BATCH, HORIZON, CURVE_SIZE, CURVE_EVERY = 5, 20, 50, 100, 10


def make_specs(M: int, instances) -> list[ModelSpec]:
    specs = []
    for m in range(M):
        inst = instances[m % len(instances)]
        F, W, G = init_fwg(np.random.default_rng([m, 1]), HIDDEN)
        specs.append(ModelSpec(
            A=inst.A, B=inst.B, Q=inst.Q, R=inst.R, P=inst.P, trace_P=inst.trace_P,
            S0=inst.gso, mask=inst.comm_adj != 0, F0=F, W0=W, G0=G, data_seed=[m, 0],
            curve_x0=selection_set(inst, CURVE_SIZE), lr=0.02,
        ))
    return specs


def _train_share(args):
    M, offset, count, steps, dtype, threads, barrier, n, engine = args
    torch.set_num_threads(threads)
    instances = [paper_instance(seed, n=n) for seed in range(min(M, 8))]
    specs = make_specs(M, instances)[offset:offset + count]
    train_grnn(specs[:2], steps=2, batch=BATCH, horizon=HORIZON, dtype=dtype, engine=engine)  # warm-up (allocator, BLAS, compiling)
    if barrier is not None:
        barrier.wait()
    start = time.perf_counter()
    train_grnn(specs, steps=steps, batch=BATCH, horizon=HORIZON, dtype=dtype, curve_every=CURVE_EVERY,
                engine=engine)
    return start, time.perf_counter()


def seconds_per_model(M: int, steps: int, dtype: str, threads: int, procs: int, n: int = 20,
                      engine: str = "torch") -> float:
    """Wall seconds per 750-step model; with procs > 1 the M models are split over that many
    single-stack processes running at once (how the runner uses several cores)."""
    if procs == 1 or M < procs:
        start, end = _train_share((M, 0, M, steps, dtype, threads, None, n, engine))
        return (end - start) / M * (750 / steps)
    ctx = multiprocessing.get_context("spawn")
    with ctx.Manager() as manager:
        barrier = manager.Barrier(procs)
        shares = [M // procs + (i < M % procs) for i in range(procs)]
        offsets = [sum(shares[:i]) for i in range(procs)]
        with ctx.Pool(procs) as pool:
            spans = pool.map(_train_share, [(M, o, c, steps, dtype, threads, barrier, n, engine)
                                            for o, c in zip(offsets, shares)])
    wall = max(end for _, end in spans) - min(start for start, _ in spans)
    return wall / M * (750 / steps)


def training_flops(N: int, steps: int = 750, curve_every: int = CURVE_EVERY, h: int = HIDDEN, B: int = BATCH,
                   T: int = HORIZON, curve_size: int = CURVE_SIZE) -> float:
    """Floating-point operations of one model's training (one state and input per node, Q = R = I).

    Counted from the products of :func:`codesign.learned.grnn_bptt.grnn_loss_and_grad` (2 per
    multiply-add), per time step of the forward pass (Z W, S (.), x F, Z G, x A', u B',
    the cost) and of the backward pass (lambda B, G du, dG, tanh', dF, dS, dPre S, dW,
    W dY, lambda A, F dPre); the validation curve rolls ``curve_size`` draws forward.
    """
    BN = B * N
    forward = 2 * h * BN * (h + N) + 4 * BN * N + 2 * 2 * h * BN + 4 * BN
    backward = 4 * h * BN * N + 4 * h * h * BN + 4 * BN * N + 4 * 2 * h * BN + 3 * h * BN
    train = steps * T * (forward + backward)
    curves = (steps // curve_every + 1 if curve_every else 1) * T * forward * curve_size / B
    return float(train + curves)


def _timed(fn, repeat: int) -> float:
    for _ in range(3):
        fn()
    start = time.perf_counter()
    for _ in range(repeat):
        fn()
    return (time.perf_counter() - start) / repeat


def matmul_peak(dtype: str, size: int = 1024) -> float:
    """GFLOP/s of one large square matrix product on the current torch threads."""
    a = torch.randn(size, size, dtype=getattr(torch, dtype))
    b, out = torch.randn_like(a), torch.empty_like(a)
    seconds = _timed(lambda: torch.mm(a, b, out=out), 10)
    return 2 * size**3 / seconds / 1e9


def kernel_bound(M: int, dtype: str, N: int = 20, h: int = HIDDEN, B: int = BATCH, repeat: int = 50) -> float:
    """Seconds per 750-step model if the trainer's per-time-step kernels ran back to back at stack size M.

    Each product and elementwise pass of one forward and one backward time step
    (the trainer's shapes, layouts and ``out=`` buffers) is timed alone, warm in
    cache, and the sum is scaled to 750 steps of ``HORIZON`` time steps per model.
    The validation curve is left out, so this is a lower bound on the trainer's time.
    """
    dt = getattr(torch, dtype)
    BN, hB = B * N, h * B

    def t(*shape):
        return torch.randn(*shape, dtype=dt)

    S, W, A = t(M, N, N), t(M, h, h), t(M, N, N)
    Z, Zp, Y, dPre, out_h = t(M, h, B, N), t(M, h, B, N), t(M, h, B, N), t(M, h, B, N), t(M, h, B, N)
    x, u, lam, xn = t(M, B, N), t(M, B, N), t(M, B, N), t(M, B, N)
    Fb, Gq, Gc = t(M, h, 1, 1), t(M, 1, h), t(M, h, 1)
    J, dS, dW, dF, dG = t(M, 1, 1), t(M, N, N), t(M, h, h), t(M, 1, h), t(M, 1, h)
    St = S.transpose(1, 2)
    kernels = [
        # forward
        lambda: torch.bmm(W.transpose(1, 2), Zp.view(M, h, BN), out=Y.view(M, h, BN)),
        lambda: torch.bmm(Y.view(M, hB, N), St, out=Z.view(M, hB, N)),
        lambda: Z.addcmul_(x.unsqueeze(1), Fb),
        lambda: torch.sigmoid(Z.mul_(0.5), out=Z).mul_(2.0).sub_(1.0),  # the trainer's tanh passes (x0.5: stays bounded)
        lambda: torch.bmm(Gq, Z.view(M, h, BN), out=u.view(M, 1, BN)),
        lambda: torch.bmm(x, A, out=xn),
        lambda: xn.baddbmm_(u, A),
        lambda: J.baddbmm_(x.view(M, 1, BN), x.view(M, BN, 1)),
        lambda: J.baddbmm_(u.view(M, 1, BN), u.view(M, BN, 1)),
        # backward
        lambda: torch.baddbmm(u, lam, A, out=xn),
        lambda: torch.baddbmm(Zp.view(M, h, BN), Gc, u.view(M, 1, BN), out=out_h.view(M, h, BN)),
        lambda: dG.baddbmm_(u.view(M, 1, BN), Z.view(M, h, BN).transpose(1, 2)),
        lambda: torch.mul(out_h, Z, out=Y),
        lambda: torch.addcmul(out_h, Y, Z, value=-1.0, out=dPre),
        lambda: dF.baddbmm_(x.view(M, 1, BN), dPre.view(M, h, BN).transpose(1, 2)),
        lambda: dS.baddbmm_(dPre.view(M, hB, N).transpose(1, 2), Zp.view(M, hB, N)),
        lambda: torch.bmm(dPre.view(M, hB, N), S, out=Y.view(M, hB, N)),
        lambda: dW.baddbmm_(Y.view(M, h, BN), Zp.view(M, h, BN).transpose(1, 2)),
        lambda: torch.bmm(W, Y.view(M, h, BN), out=out_h.view(M, h, BN)),
        lambda: torch.baddbmm(x, lam, A, out=xn),
        lambda: xn.view(M, 1, BN).baddbmm_(Gq, dPre.view(M, h, BN)),
    ]
    per_step = 0.0
    for kernel in kernels:
        Z.copy_(Zp.clamp(-1, 1))  # keep the elementwise passes in range
        per_step += _timed(kernel, repeat)
    return per_step * HORIZON * 750 / M


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--models", type=int, default=64, help="stack size M of the batched run (default 64)")
    parser.add_argument("--steps", type=int, default=50, help="training steps timed (extrapolated to 750)")
    parser.add_argument("--dtype", choices=("float64", "float32", "both"), default="both")
    parser.add_argument("--engines", nargs="+", choices=("torch", "fused"), default=["torch", "fused"])
    parser.add_argument("--threads", type=int, default=1, help="torch intra-op threads per process (default 1)")
    parser.add_argument("--procs", type=int, default=2,
                        help="processes sharing the M models, one stack each (default 2: one per core)")
    parser.add_argument("--sizes", type=int, nargs="*", default=[50, 100],
                        help="larger N timed in float32 on one core (default 50 100; none to skip)")
    parser.add_argument("--large-models", type=int, default=8, help="stack size at the larger N (default 8)")
    parser.add_argument("--large-steps", type=int, default=10, help="training steps timed at the larger N")
    args = parser.parse_args(argv)
    dtypes = ("float64", "float32") if args.dtype == "both" else (args.dtype,)
    cores = args.procs * args.threads
    torch.set_num_threads(1)
    print(f"GRNN training, N=20 T={HORIZON} batch={BATCH} h={HIDDEN}, {args.steps} steps timed (curve every {CURVE_EVERY} on "
          f"{CURVE_SIZE} draws), {args.procs} process(es) x {args.threads} torch thread(s); torch {torch.__version__}, "
          f"{torch.backends.cpu.get_cpu_capability()}")
    flops, train_flops = training_flops(20), training_flops(20, curve_every=0)
    print(f"arithmetic per 750-step model: {flops / 1e9:.2f} GFLOP (training {train_flops / 1e9:.2f}"
          f" + validation curve), dense")
    print(f"{'dtype':8} {'engine':6} {'M':>4} {'s / model':>10} {'s / model / core':>17} {'GFLOP/s / core':>15} "
          f"{'matmul peak':>12} {'of peak':>8}")
    for dtype in dtypes:
        peak = matmul_peak(dtype)
        batched = {}
        for engine in args.engines:
            single = seconds_per_model(1, args.steps, dtype, args.threads, 1, engine=engine)
            many = batched[engine] = seconds_per_model(args.models, args.steps, dtype, args.threads, args.procs,
                                                       engine=engine)
            for M, wall, used in ((1, single, args.threads), (args.models, many, cores)):
                rate = flops / (wall * used) / 1e9
                print(f"{dtype:8} {engine:6} {M:>4} {wall:>10.3f} {wall * used:>17.3f} {rate:>15.1f} {peak:>12.1f} "
                      f"{rate / peak:>8.1%}")
            print(f"{dtype:8} {engine:6} ratio M=1 / M={args.models}: {single / many:.1f}x wall")
        if "torch" in batched:
            per_stack = -(-args.models // args.procs)
            bound = kernel_bound(per_stack, dtype)
            print(f"{dtype:8} torch  kernel bound at M={per_stack} per process: {bound:.3f} s / model / core "
                  f"(training only: {train_flops / bound / 1e9:.1f} GFLOP/s); the torch engine takes "
                  f"{batched['torch'] * cores / bound:.2f}x that with its validation curve")
        if len(batched) == 2:
            print(f"{dtype:8} fused engine: {batched['torch'] / batched['fused']:.2f}x the torch engine's speed "
                  f"at M={args.models}")
    for n in args.sizes:
        for engine in args.engines:
            wall = seconds_per_model(args.large_models, args.large_steps, "float32", 1, 1, n=n, engine=engine)
            rate = training_flops(n) / wall / 1e9
            print(f"N={n:<4d} float32 {engine:6} M={args.large_models}: {wall:.2f} s / 750-step model on one core "
                  f"({training_flops(n) / 1e9:.1f} GFLOP dense, {rate:.1f} GFLOP/s)")


if __name__ == "__main__":
    main()

