"""The one trainer of every learned controller: stacks of models, Adam, divergence, curves, designs.

A learned method is a :class:`StackModel` (how M models of its kind roll out,
and the loss and gradient of each on a batch of initial states) and the
:class:`Member` specs of the models it wants trained. This module does the rest
for every such method alike:

- :func:`train_stack` advances a stack: per-model Adam (:class:`BatchedAdam`)
  with a cosine or step learning-rate schedule (:class:`Loop`), a fresh batch of
  draws x(0) ~ N(0, I) per update from each model's own seed, gradient-norm
  clipping, freezing of a model whose loss or gradient stops being finite, and
  the validation curve; one :class:`TrainResult` per model.
- :func:`train_jobs` groups many runs' members into stacks of models that can
  train together (same model type, options, loop and shapes) and shares each
  stack's seconds among its runs.
- :func:`best_member` picks an ensemble's member; :func:`simulated_design`
  turns a trained nonlinear controller into a :class:`~codesign.design.Design`
  (stability rollout, cost to precision, a status and message for divergence).

Every tensor of a stack carries a leading model axis, so one torch call does M
models' work; the models never mix, so a stacked run gives the parameters of M
separate runs with the same seeds.
"""

from __future__ import annotations

import functools
import math
import time
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from .._lazy import lazy_import
from ..cluster import SPREAD_ABOVE, spread
from ..design import Design
from ..evaluation import simulate, simulate_to_precision, validation_set
from ..instances import gaussian_states
from ..status import DIVERGED, OPTIMAL

torch = lazy_import("torch")

__all__ = ["DTYPES", "Loop", "Member", "StackModel", "AutogradModel", "TrainResult", "TrainingJob", "BatchedAdam",
           "train_stack", "train_jobs", "selection_costs", "selection_set", "best_member", "curve", "simulated_design", "diverged_members_message",
           "clip_coefficients", "torch_dtype", "no_grad", "tanh_"]

#: Floating-point types the trainer runs in, by name.
DTYPES = ("float64", "float32")


def torch_dtype(name: str):
    """The torch dtype called ``name`` (one of :data:`DTYPES`)."""
    if name not in DTYPES:
        raise ValueError(f"dtype must be one of {sorted(DTYPES)}, got {name!r}")
    return getattr(torch, name)


def no_grad(function):
    """``torch.no_grad()`` as a decorator that does not load torch until the function runs."""
    @functools.wraps(function)
    def wrapper(*args, **kwargs):
        with torch.no_grad():
            return function(*args, **kwargs)
    return wrapper


def tanh_(pre):
    """In-place tanh(pre) as 2 sigmoid(2 pre) - 1: three times torch.tanh's speed on CPU, within 4e-16."""
    return torch.sigmoid(pre.mul_(2.0), out=pre).mul_(2.0).sub_(1.0)


@dataclass(frozen=True)
class Loop:
    """Settings every model of a stack shares (hashable: part of the key that groups runs into stacks).

    Attributes
    ----------
    steps, batch, horizon : int
        Adam updates, draws x(0) per update, rollout length.
    clip : float or None
        Per-model gradient-norm clip (None or 0: none).
    curve_every : int
        Record the curve every this many updates (0: only after the last).
    dtype : {"float64", "float32"}
    schedule : {"cosine", "step"}
        Learning rate ``lr`` cosine-annealed to 0 over ``steps`` updates, or
        ``lr * decay ** ceil(k / decay_every)`` at update k (torch's StepLR stepped
        after updates 0, decay_every, ...).
    decay_every : int
    weight_decay : float
        Coupled L2 weight decay (added to the gradient, as torch.optim.Adam does).
    """

    steps: int
    batch: int
    horizon: int
    clip: float | None = None
    curve_every: int = 10
    dtype: str = "float64"
    schedule: Literal["cosine", "step"] = "cosine"
    decay_every: int = 1
    weight_decay: float = 0.0

    def __post_init__(self):
        torch_dtype(self.dtype)
        if self.steps < 1 or self.batch < 1:
            raise ValueError(f"steps and batch must be positive, got steps={self.steps}, batch={self.batch}")
        if self.schedule not in ("cosine", "step"):
            raise ValueError(f"schedule must be 'cosine' or 'step', got {self.schedule!r}")

    def rates(self, k: int, lr, decay):
        """Learning rates (M,) at update ``k`` from the base rates ``lr`` and decay factors ``decay``."""
        if self.schedule == "cosine":
            return lr * (0.5 * (1.0 + math.cos(math.pi * k / self.steps)))
        return lr * decay ** math.ceil(k / self.decay_every)


@dataclass
class Member:
    """One model of a stack: what the trainer needs, and the model's own ``problem``.

    Attributes
    ----------
    problem : object
        What the :class:`StackModel` builds this model from (its plant, costs,
        initial parameters, masks: the model type's business).
    data_seed : int or sequence of int
        Seed of this model's training draws x(0) ~ N(0, I).
    curve_x0 : ndarray (curve size, dim)
        Initial conditions of the validation curve, in the model's state layout.
    lr : float
        Base learning rate.
    decay : float
        Step-schedule factor (:attr:`Loop.schedule` "step").
    placement : ndarray of int, optional
        Where the drawn states sit in the model's ``dim``-long state vector (the
        rest stays 0); None: every entry is drawn.
    x0_factor : ndarray (n, r), optional
        F of the initial-state covariance Σ₀ = F F' (:attr:`codesign.Instance.x0_factor`):
        the draws are x(0) = F z, z ~ N(0, I_r). None: x(0) ~ N(0, I).
    """

    problem: Any
    data_seed: Any
    curve_x0: np.ndarray
    lr: float
    decay: float = 1.0
    placement: np.ndarray | None = None
    x0_factor: np.ndarray | None = None

    def shape_key(self) -> tuple:
        """What must agree between the members of one stack besides the loop: the curve's shape."""
        return (np.shape(self.curve_x0), None if self.placement is None else len(self.placement))


class StackModel:
    """M models of one kind, stacked: the protocol :func:`train_stack` trains.

    A subclass sets in ``__init__(members, loop, **options)``:

    - ``names``: the parameters' names, and ``params``: their stacked tensors
      (model axis first), which the trainer updates in place;
    - ``dim``: the length of the state vector x(0) the models start from;

    and implements :meth:`loss_and_grad` (loss (M,) including any penalty, and
    one gradient per parameter, zero where a parameter must not train) and
    :meth:`curve_cost` (mean normalized cost (M,) from given initial states).
    :meth:`shape_key` says which members can share a stack.
    """

    names: tuple = ()
    params: list = []
    dim: int = 0

    @classmethod
    def shape_key(cls, member: Member) -> tuple:
        """Members with equal keys (and equal loops and options) train in one stack."""
        return member.shape_key()

    @classmethod
    def independent(cls, members, loop: "Loop", **options) -> bool:
        """Whether each of ``members`` trains to the same bits alone as in a stack with the others.

        Where it does, :func:`train_jobs` may train large members one per task of a dask
        cluster (:mod:`codesign.cluster`). False by default: batched torch products and
        reductions may round differently for another number of models.
        """
        return False

    def loss_and_grad(self, x0):
        raise NotImplementedError

    def curve_cost(self, x0):
        raise NotImplementedError


class AutogradModel(StackModel):
    """A :class:`StackModel` whose gradient torch's autograd takes from :meth:`loss`.

    A subclass writes the loss (M,) of the stack on a batch ``x0`` (M, batch, dim)
    with differentiable torch operations; :meth:`curve_cost` defaults to the loss
    with its penalty left out, divided by each model's ``trace_P`` (an (M,) tensor
    the subclass sets) when it has one.
    """

    trace_P = None

    def loss(self, x0, *, penalized: bool = True):
        raise NotImplementedError

    def loss_and_grad(self, x0):
        with torch.enable_grad():
            params = [p.detach().requires_grad_(True) for p in self.params]
            saved, self.params = self.params, params
            try:
                loss = self.loss(x0)
                grads = torch.autograd.grad(loss.sum(), params, allow_unused=True)
            finally:
                self.params = saved
        return loss.detach(), [torch.zeros_like(p) if g is None else g for p, g in zip(self.params, grads)]

    def curve_cost(self, x0):
        cost = self.loss(x0, penalized=False)
        return cost if self.trace_P is None else cost / self.trace_P


@dataclass
class TrainResult:
    """Final parameters and history of one model of a stack."""

    params: dict
    diverged_at: int | None  # the update whose loss or gradient was not finite; None if it trained to the end
    curve_step: list = field(default_factory=list)
    curve_cost: list = field(default_factory=list)
    final_loss: float = float("nan")

    @property
    def diverged(self) -> bool:
        """Whether training froze this model at a non-finite loss or gradient.

        A training outcome, not a design status: the method decides what a
        diverged member means for its design.
        """
        return self.diverged_at is not None

    @property
    def final_curve_cost(self) -> float:
        return self.curve_cost[-1] if self.curve_cost else float("nan")


class BatchedAdam:
    """Adam (torch's formulas) over stacked parameters, one learning rate per model.

    ``params`` is a list of tensors whose first axis is the model axis.
    ``weight_decay`` is coupled L2 (added to the gradient, as torch.optim.Adam does).
    """

    def __init__(self, params, *, betas=(0.9, 0.999), eps=1e-8, weight_decay=0.0):
        self.params = params
        self.beta1, self.beta2 = betas
        self.eps = eps
        self.weight_decay = weight_decay
        self.m = [torch.zeros_like(p) for p in params]
        self.v = [torch.zeros_like(p) for p in params]
        self.t = 0

    def step(self, grads, lr) -> None:
        """One update; ``lr`` has shape (M,) (0 freezes a model)."""
        self.t += 1
        bc1 = 1.0 - self.beta1**self.t
        bc2 = 1.0 - self.beta2**self.t
        for p, g, m, v in zip(self.params, grads, self.m, self.v):
            if self.weight_decay:
                g = g.add(p, alpha=self.weight_decay)
            m.lerp_(g, 1.0 - self.beta1)
            v.mul_(self.beta2).addcmul_(g, g, value=1.0 - self.beta2)
            denom = (v.sqrt() / math.sqrt(bc2)).add_(self.eps)
            step = (lr / bc1).view((-1,) + (1,) * (p.dim() - 1))
            p.addcmul_(m / denom, step, value=-1.0)


def clip_coefficients(grads, max_norm: float):
    """Per-model total gradient norm and torch's clip_grad_norm_ coefficient.

    The norm is taken of the gradients scaled by their largest entry, so that it
    stays finite in float32 for gradients up to ~1e38 (a linear GRNN's first
    steps on an unstable plant reach 1e22, whose square overflows).
    """
    flat = [g.reshape(g.shape[0], -1) for g in grads]
    scale = torch.stack([f.abs().amax(1) for f in flat]).amax(0)
    safe = torch.where(scale > 0, scale, torch.ones_like(scale)).unsqueeze(1)
    norm = sum((f / safe).pow(2).sum(1) for f in flat).sqrt() * safe.squeeze(1)
    coef = (max_norm / (norm + 1e-6)).clamp(max=1.0)
    return norm, coef


def _per_model(value, like):
    """``value`` (M,) shaped to broadcast against ``like`` (M, ...)."""
    return value.view((-1,) + (1,) * (like.dim() - 1))


@no_grad
def train_stack(model_type, members: list[Member], loop: Loop, **options) -> list[TrainResult]:
    """Train the models of ``members`` together; one :class:`TrainResult` per member.

    ``model_type(members, loop, **options)`` builds the :class:`StackModel`. Each
    model: Adam with its own learning rate on ``loop.schedule``, a fresh batch of
    ``loop.batch`` draws x(0) ~ N(0, Σ₀) per update from its own ``data_seed``,
    gradient-norm clipping at ``loop.clip``. A model whose loss or gradient stops
    being finite is frozen (its parameters zeroed, its learning rate 0) and
    reported diverged; the others go on. The validation curve (mean normalized
    cost on ``member.curve_x0``) is recorded every ``loop.curve_every`` updates
    and after the last one.
    """
    M = len(members)
    if M == 0:
        return []
    tdt = torch_dtype(loop.dtype)
    model = model_type(members, loop, **options)
    params = model.params
    placements = [np.arange(model.dim) if m.placement is None else np.asarray(m.placement) for m in members]
    if len({len(k) for k in placements}) != 1:
        raise ValueError("every model of a stack needs the same number of states")
    base_lr = torch.tensor([m.lr for m in members], dtype=tdt)
    decay = torch.tensor([m.decay for m in members], dtype=tdt)
    rngs = [np.random.default_rng(m.data_seed) for m in members]
    curve_x0 = torch.tensor(np.stack([np.asarray(m.curve_x0) for m in members]), dtype=tdt)
    adam = BatchedAdam(params, weight_decay=loop.weight_decay)
    alive = torch.ones(M, dtype=torch.bool)
    diverged_at: list[int | None] = [None] * M
    curve_steps: list[int] = []
    curve_costs: list = []
    last_loss = torch.full((M,), float("nan"), dtype=tdt)
    draws = np.zeros((M, loop.batch, model.dim))

    def record(k):
        curve_steps.append(k)
        curve_costs.append(model.curve_cost(curve_x0))

    for k in range(loop.steps):
        if loop.curve_every and k % loop.curve_every == 0:
            record(k)
        for m, (rng, where) in enumerate(zip(rngs, placements)):
            draws[m][:, where] = gaussian_states(rng, loop.batch, len(where), members[m].x0_factor)
        x0 = torch.tensor(draws, dtype=tdt)
        x0.mul_(alive.view(M, 1, 1).to(tdt))
        loss, grads = model.loss_and_grad(x0)
        norm, coef = clip_coefficients(grads, loop.clip if loop.clip else float("inf"))
        bad = alive & ~(torch.isfinite(loss) & torch.isfinite(norm))
        if bool(bad.any()):
            for m in torch.nonzero(bad).flatten().tolist():
                diverged_at[m] = k
            alive &= ~bad
            for p in params:  # a dead model rolls out zeros from now on
                p.copy_(torch.where(_per_model(alive, p), p, torch.zeros_like(p)))
            grads = [torch.nan_to_num(g, nan=0.0, posinf=0.0, neginf=0.0) for g in grads]
            coef = torch.where(alive, torch.nan_to_num(coef, nan=0.0), torch.zeros_like(coef))
        last_loss = torch.where(alive, loss, last_loss)
        if loop.clip:
            for g in grads:
                g.mul_(_per_model(coef, g))
        adam.step(grads, loop.rates(k, base_lr, decay) * alive.to(tdt))
    record(loop.steps)

    costs = torch.stack(curve_costs).numpy()  # (points, M)
    return [TrainResult(params={name: p[m].numpy().astype(float) for name, p in zip(model.names, params)},
                        diverged_at=diverged_at[m], curve_step=list(curve_steps),
                        curve_cost=[float(c) for c in costs[:, m]], final_loss=float(last_loss[m]))
            for m in range(M)]


@dataclass
class TrainingJob:
    """One run's models to train: its members and how (model type, options, loop)."""

    model: type
    members: list
    loop: Loop
    options: tuple = ()  # (name, value) pairs passed to the model type

    def key(self, member: Member) -> tuple:
        return (self.model, self.options, self.loop, self.model.shape_key(member))


def _timed_stack(model, loop, options, members) -> tuple[list[TrainResult], float]:
    t0 = time.perf_counter()
    out = train_stack(model, members, loop, **dict(options))
    return out, time.perf_counter() - t0


def train_jobs(jobs: list[TrainingJob], *, stack_size: int) -> tuple[list[list[TrainResult]], list[float]]:
    """Train every job's members, in stacks of up to ``stack_size`` models that share a key.

    Returns each job's results (one per member, in order) and its seconds: each
    stack's time shared equally among its models. Members of more than
    :data:`~codesign.cluster.SPREAD_ABOVE` states whose model type trains them
    :meth:`~StackModel.independent` of each other train one per stack, which, run
    as a task of a dask cluster, are tasks of their own on its workers
    (:func:`~codesign.cluster.spread`); the results are the same bits either way.
    """
    results = [[None] * len(job.members) for job in jobs]
    seconds = [0.0] * len(jobs)
    groups: dict[tuple, list[tuple[int, int]]] = {}
    for j, job in enumerate(jobs):
        for k, member in enumerate(job.members):
            groups.setdefault(job.key(member), []).append((j, k))
    for (model, options, loop, _), slots in groups.items():
        members = [jobs[j].members[k] for j, k in slots]
        alone = (len(members) > 1 and np.shape(members[0].curve_x0)[-1] > SPREAD_ABOVE
                 and model.independent(members, loop, **dict(options)))
        size = 1 if alone else stack_size
        chunks = [list(range(start, min(start + size, len(slots)))) for start in range(0, len(slots), size)]
        trained, _ = spread(_timed_stack, [[members[i] for i in chunk] for chunk in chunks],
                            shared=(model, loop, options))
        for chunk, (out, elapsed) in zip(chunks, trained):
            for i, result in zip(chunk, out):
                j, k = slots[i]
                results[j][k] = result
                seconds[j] += elapsed / len(chunk)
    return results, seconds


def _call(function, args: tuple):
    return function(*args)


def finish_designs(finish, args: list[tuple], *, states: int) -> list[Design]:
    """``[finish(*a) for a in args]``: the designs of a batch, scored (the part after training).

    Above :data:`~codesign.cluster.SPREAD_ABOVE` ``states``, where scoring one design
    takes tens of seconds, each is a task of the dask cluster this runs in, if any
    (:func:`~codesign.cluster.spread`). ``finish`` must be a module-level function.
    """
    if states <= SPREAD_ABOVE:
        return [finish(*a) for a in args]
    return spread(_call, args, shared=(finish,))[0]


def selection_costs(results: list[TrainResult]) -> list[float]:
    """Each member's final curve cost, infinite for a member that diverged or ended at a non-finite cost."""
    return [float(r.final_curve_cost) if not r.diverged and np.isfinite(r.final_curve_cost) else float("inf")
            for r in results]


#: Salt of the selection-set stream, apart from every training and validation stream.
_SELECT = 0xC0DE


def selection_set(instance, size: int) -> np.ndarray:
    """(size, n) initial states for the training curve and ensemble selection, seeded by the instance.

    Drawn apart from the validation set so that picking the best ensemble member
    does not bias the reported cost; every learned method draws the same set.
    """
    return instance.initial_states(np.random.default_rng([instance.seed, _SELECT]), size)


def best_member(results: list[TrainResult]) -> int | None:
    """The member with the lowest :func:`selection_costs` entry; None when every one is infinite."""
    costs = selection_costs(results)
    best = int(np.argmin(costs))
    return None if not np.isfinite(costs[best]) else best


def curve(result: TrainResult) -> dict:
    """A result's validation curve as a design stores it: ``{"step": [...], "cost": [...]}``."""
    return {"step": list(result.curve_step), "cost": [float(c) for c in result.curve_cost]}


def diverged_members_message(results: list[TrainResult]) -> str:
    """"k of n ensemble members diverged", or "" when none did."""
    diverged = sum(r.diverged for r in results)
    return f"{diverged} of {len(results)} ensemble members diverged" if diverged else ""


def simulated_design(instance, controller, *, method: str, params: dict, info_model: str, links: int,
                     self_loops: int, seconds: float, extras: dict, stability_steps: int, stability_size: int,
                     message: str = "") -> Design:
    """A trained nonlinear controller's :class:`Design`: its cost simulated to precision.

    A ``stability_steps`` rollout from ``stability_size`` validation draws records
    whether the closed loop stays ``bounded`` (0 steps skips it); a validation
    rollout that diverges, or a cost that is not finite, makes the design
    ``diverged`` with the rollout's message.
    """
    start = time.perf_counter()
    rollout = simulate_to_precision(instance, controller)
    extras.update(rollout.summary())
    if stability_steps:
        long = simulate(instance, controller, validation_set(instance)[:stability_size], steps=stability_steps)
        extras["bounded"] = bool(long.bounded)
        extras["max_state"] = float(long.max_state)
        extras["stability_steps"] = stability_steps
    # Scoring, not design: ``seconds`` is the training's. The harness's own scoring leaves a design
    # that has a cost alone, so this is where a learned design's scoring time is known at all.
    extras["scoring_seconds"] = time.perf_counter() - start
    if not rollout.bounded or not np.isfinite(rollout.cost):
        return Design.failure(method, params, DIVERGED,
                              rollout.divergence or "the trained controller's validation rollout is unbounded",
                              info_model=info_model, seconds=seconds, links=links, self_loops=self_loops,
                              extras=extras)
    return Design(method=method, params=params, controller=controller, cost=rollout.cost, links=links,
                  self_loops=self_loops, info_model=info_model, status=OPTIMAL, message=message,
                  seconds=seconds, cost_stderr=rollout.stderr, cost_kind="simulated", extras=extras)
