"""A learned method in one file: a per-node MLP on each node's own and its neighbours' states.

    u_i(t) = sum_f w_f tanh(a_f x_i(t) + b_f (S x(t))_i),

with S the given graph's normalized adjacency and (a, b, w) shared by every
node (3 h parameters). Node i reads its neighbours' current states, so the
controller needs instantaneous one-hop communication over the given graph.

The one trainer (``codesign.learned``) does the rest: Adam and its schedule,
batches of x(0) ~ N(0, I), divergence, the validation curve, the ensemble, and
the design's cost simulated to precision. The gradient here comes from torch's
autograd (:class:`~codesign.learned.AutogradModel`); only the GRNN and the GCNN
carry hand-written ones. Use it from a spec with ``plugins = ["examples/node_mlp.py"]``
and ``method = "node_mlp"`` (docs/extending.md).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

import numpy as np
import torch

from codesign import Design, count_links, method, register_controller
from codesign.learned import (AutogradModel, Loop, Member, TrainingJob, TrainingSettings, best_member, curve,
                              selection_set, simulated_design, takes_settings, train_jobs)
from codesign.methods import Above, AtLeast
from codesign.status import DIVERGED


@dataclass(frozen=True)
class NodeMLPSettings(TrainingSettings):
    """The node MLP's training settings: :class:`~codesign.learned.TrainingSettings` and these.

    Attributes
    ----------
    hidden : int
        Features h of the MLP.
    lr : float
        Learning rate, cosine-annealed to 0 over the steps.
    """

    hidden: Annotated[int, AtLeast(1)] = 8
    lr: Annotated[float, Above(0)] = 0.02


@register_controller("node_mlp")
@dataclass(frozen=True, eq=False)
class NodeMLPController:
    """u_i = w . tanh(a x_i + b (S x)_i) at every node (numpy, batched)."""

    S: np.ndarray
    a: np.ndarray
    b: np.ndarray
    w: np.ndarray

    def reset(self, batch):
        return None

    def step(self, state, x):
        z = np.tanh(x[..., None] * self.a + (x @ self.S.T)[..., None] * self.b)  # (batch, N, h)
        return z @ self.w, None

    def arrays(self):
        return {"S": self.S, "a": self.a, "b": self.b, "w": self.w}

    @classmethod
    def from_arrays(cls, arrays):
        return cls(**{k: np.asarray(arrays[k]) for k in ("S", "a", "b", "w")})


class NodeMLPStack(AutogradModel):
    """M node MLPs, one per member; each member's ``problem`` is (instance, initial a, b, w)."""

    names = ("a", "b", "w")

    def __init__(self, members, loop: Loop):
        dtype = getattr(torch, loop.dtype)
        instances = [m.problem[0] for m in members]

        def stack(arrays):
            return torch.tensor(np.stack(arrays), dtype=dtype)

        self.S_t = stack([i.gso.T for i in instances])
        self.A_t, self.B_t = stack([i.A.T for i in instances]), stack([i.B.T for i in instances])
        self.Q, self.R, self.P = (stack([getattr(i, k) for i in instances]) for k in "QRP")
        self.trace_P = torch.tensor([i.trace_P for i in instances], dtype=dtype)
        self.params = [stack([m.problem[k] for m in members]) for k in (1, 2, 3)]
        self.horizon, self.dim = loop.horizon, instances[0].n

    def loss(self, x0, *, penalized=True):
        a, b, w = (p[:, None, None, :] for p in self.params)  # (M, 1, 1, h)

        def quadratic(v, weight):
            return (torch.bmm(v, weight) * v).sum((1, 2))

        x, J = x0, 0.0
        for _ in range(self.horizon):
            z = torch.tanh(x[..., None] * a + torch.bmm(x, self.S_t)[..., None] * b)
            u = (z * w).sum(-1)
            J = J + quadratic(x, self.Q) + quadratic(u, self.R)
            x = torch.bmm(x, self.A_t) + torch.bmm(u, self.B_t)
        return (J + quadratic(x, self.P)) / x0.shape[1]


@method("node_mlp", label="Node MLP", produces=("training_curve",))
@takes_settings(NodeMLPSettings)
def node_mlp(instance, *, seed: Annotated[int, AtLeast(0)] = 0, **settings) -> Design:
    """A per-node MLP on each node's own and its neighbours' states, trained by the one trainer.

    Parameters
    ----------
    instance : Instance
    seed : int
        Seeds the initializations and the training draws.
    """
    s = NodeMLPSettings(**settings)
    members = []
    for k in range(s.ensemble):
        a, b, w = np.random.default_rng([seed, k, 1]).uniform(-1, 1, (3, s.hidden)) / np.sqrt(s.hidden)
        members.append(Member(problem=(instance, a, b, w), data_seed=[seed, k, 2],
                              curve_x0=selection_set(instance, s.curve_size), lr=s.lr))
    loop = Loop(steps=s.steps, batch=s.batch, horizon=instance.horizon, curve_every=s.curve_every, dtype=s.dtype)
    (results,), (seconds,) = train_jobs([TrainingJob(NodeMLPStack, members, loop)], stack_size=len(members))
    links, self_loops = count_links(instance.comm_adj)
    best = best_member(results)
    if best is None:
        return Design.failure("node_mlp", {}, DIVERGED, "every ensemble member diverged",
                              info_model="instantaneous", seconds=seconds, links=links, self_loops=self_loops)
    controller = NodeMLPController(instance.gso, **results[best].params)
    return simulated_design(instance, controller, method="node_mlp", params={}, info_model="instantaneous",
                            links=links, self_loops=self_loops, seconds=seconds,
                            extras={"curve": curve(results[best])}, stability_steps=s.stability_steps,
                            stability_size=s.stability_size)
