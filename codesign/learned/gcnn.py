"""The GCNN baseline of Gama & Sojoudi (2021), as the paper benchmarked it (docs/methods.md).

Memoryless: one graph-filter layer with K = 5 taps and 32 features, tanh, and a
per-node linear readout, no bias:

    z_f(t) = sum_{k=0}^{4} h_{f,k} S^k x(t),   u_i(t) = sum_f w_f tanh(z_{f,i}(t)),

5 * 32 + 32 = 192 parameters, S the given normalized adjacency. ``S^k x(t)`` is
used with no delay: the controller assumes instantaneous multi-hop communication.

Node blocks (nodes with several states or inputs, ``Instance.scalar_nodes``
False): the node signal has p = (most states at a node) channels, X in R^{N x p},
state k in channel "its rank among its node's states" of node ``state_nodes[k]``
(nodes with fewer states are padded with zeros). Each tap maps the p channels to
the F features and the readout maps the features to q = (most inputs at a node)
outputs per node:

    Z = sum_k S^k X H_k   (H_k in R^{p x F}),   Y = tanh(Z) W   (W in R^{F x q}),

and input a is entry (input_nodes[a], its rank among its node's inputs) of Y
(padded outputs are unused): K p F + F q parameters. With p = q = 1 this is the
model above; the controller then keeps the shapes H (K, F), w (F,) and the
general one stores H (K, p, F), w (F, q) and the node maps.

Training (paper code): Adam, learning rate 0.01 multiplied by 0.9 every 10
updates, coupled weight decay 2, no clipping, loss = mean raw J per batch, by the
one trainer (:mod:`codesign.learned.trainer`) with the model
:class:`codesign.learned.gcnn_bptt.GCNNStack` (two hand-written BPTTs: the
paper's setting, and node blocks or other Q and R). Initialization, data and
selection draws use the same streams on both paths.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Annotated, Literal

import numpy as np

from .._lazy import lazy_import
from ..controllers import register_controller
from ..design import Design, count_links
from ..evaluation import STRUCTURED_ABOVE, spectral_radius, structured_operator
from ..instances import node_ranks, node_width
from ..methods import Above, AtLeast, AtMost, method
from ..status import DIVERGED
from .engines import ENGINES, fused_unsupported, resolve_engine
from .gcnn_bptt import GCNN_FEATURES, GCNN_TAPS, GCNNProblem, GCNNStack, node_layout, gcnn_init, tap_map
from .settings import SEED, TrainingSettings, takes_settings
from .trainer import (Loop, Member, TrainingJob, best_member, curve, diverged_members_message,
                      finish_designs, selection_costs, selection_set, simulated_design, train_jobs)

torch = lazy_import("torch")

__all__ = ["gcnn", "gcnn_batch", "GCNNController", "GCNNSettings", "GCNN_TAPS", "GCNN_FEATURES",
           "parse_job", "ensemble_member"]

_DATA, _INIT = 21, 22


@register_controller("gcnn")
@dataclass(frozen=True, eq=False)
class GCNNController:
    """u = tanh(sum_k S^k x h_k) w, applied at every node (numpy, batched).

    Attributes
    ----------
    S : ndarray (N, N)
    H : ndarray (K, F), or (K, p, F) on node blocks
        Filter taps h_{f,k} (tap k, feature f); on node blocks tap k maps the p
        channels of a node's signal to the F features.
    w : ndarray (F,), or (F, q) on node blocks
        Readout weights (to the q outputs of a node).
    state_nodes, input_nodes : ndarray of int or None
        On node blocks (3-D H), the node of each state and input (default one per
        node, in order); state k is channel (its rank among its node's states)
        of its node, input a the output (its rank among its node's inputs). None
        for the one-state-one-input model (2-D H).
    """

    S: np.ndarray
    H: np.ndarray
    w: np.ndarray
    state_nodes: np.ndarray | None = None
    input_nodes: np.ndarray | None = None

    def __post_init__(self):
        for name in ("S", "H", "w"):
            value = np.array(getattr(self, name), dtype=float)
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        N = self.S.shape[0]
        if self.S.shape != (N, N):
            raise ValueError(f"S must be square, got {self.S.shape}")
        if self.H.ndim == 2:
            if self.w.shape != (self.H.shape[1],):
                raise ValueError(f"H must be (K, F) and w (F,), got {self.H.shape} and {self.w.shape}")
            for name in ("state_nodes", "input_nodes"):
                nodes = getattr(self, name)
                if nodes is not None and not np.array_equal(nodes, np.arange(N)):
                    raise ValueError(f"{name} other than one per node needs the node-block shapes "
                                     "H (K, p, F) and w (F, q)")
                object.__setattr__(self, name, None)
            return
        if self.H.ndim != 3 or self.w.ndim != 2 or self.w.shape[0] != self.H.shape[2]:
            raise ValueError(f"H must be (K, F) and w (F,), or (K, p, F) and (F, q); got {self.H.shape} "
                             f"and {self.w.shape}")
        for name, width in (("state_nodes", self.H.shape[1]), ("input_nodes", self.w.shape[1])):
            nodes = np.arange(N) if getattr(self, name) is None else np.array(getattr(self, name))
            if nodes.ndim != 1 or not (nodes.size == 0 or np.issubdtype(nodes.dtype, np.integer)):
                raise ValueError(f"{name} must be a 1-D array of node numbers, got {nodes!r}")
            nodes = nodes.astype(int)
            if nodes.size and (nodes.min() < 0 or nodes.max() >= N):
                raise ValueError(f"{name} must name nodes 0..{N - 1}, got {nodes.tolist()}")
            if nodes.size and np.bincount(nodes, minlength=N).max() > width:
                raise ValueError(f"{name}: a node has {np.bincount(nodes).max()} entries, more than the "
                                 f"{width} channels of H and w")
            nodes.setflags(write=False)
            object.__setattr__(self, name, nodes)

    @property
    def blocks(self) -> bool:
        """Whether this is the node-block form (3-D H)."""
        return self.H.ndim == 3

    @property
    def n_parameters(self) -> int:
        return self.H.size + self.w.size

    def reset(self, batch: int):
        return None

    def step(self, state, x):
        if self.blocks:
            return self._step_blocks(x), None
        # Feature-major: the taps' powers are K rows of width batch N, so the filter bank is one
        # wide (F, K) x (K, batch N) product. tanh(z) = 2 sigmoid(2 z) - 1 with the factors folded
        # into the weights: u = (2 w)' sigmoid((2 H)' p) - sum(w), one elementwise pass (rounding
        # within 1e-15 of tanh). The node-major (batch N, K) x (K, F) product and torch.tanh took
        # 4x as long, and rollouts of the cost's refinement are most of the GCNN's time.
        K, batch, N = self.H.shape[0], x.shape[0], self.S.shape[0]
        if self._sparse_S is not None:  # node-major powers, S by its CSR: O(N degree) per draw, not O(N^2)
            powers = np.empty((K, N, batch))
            powers[0] = x.T
            for k in range(1, K):
                powers[k] = self._sparse_S @ powers[k - 1]
        else:
            powers = np.empty((K, batch, N))
            powers[0] = x
            for k in range(1, K):
                np.matmul(powers[k - 1], self.S.T, out=powers[k])
        Ht2, w2, wsum = self._folded
        Z = Ht2 @ powers.reshape(K, batch * N)  # (F, batch N)
        torch.sigmoid(torch.from_numpy(Z), out=torch.from_numpy(Z))
        u = w2 @ Z
        u -= wsum
        if self._sparse_S is not None:
            return np.ascontiguousarray(u.reshape(N, batch).T), None
        return u.reshape(batch, N), None

    @cached_property
    def _sparse_S(self):
        """S as CSR above STRUCTURED_ABOVE nodes where it is sparse (else None: the dense products, unchanged)."""
        return structured_operator(self.S) if self.S.shape[0] > STRUCTURED_ABOVE else None

    @cached_property
    def _folded(self):
        return np.ascontiguousarray(2.0 * self.H.T), 2.0 * self.w, float(self.w.sum())

    @cached_property
    def _block_maps(self):
        """(G, input nodes, input slots): z = x G (batch, N F) is the filter bank, linear in x."""
        K, p, F = self.H.shape
        N = self.S.shape[0]
        L = tap_map(self.S, self.state_nodes, K, p)  # (n, N K p)
        G = (L.reshape(-1, N, K * p) @ self.H.reshape(K * p, F)).reshape(-1, N * F)
        return G, self.input_nodes, node_ranks(self.input_nodes)

    def _step_blocks(self, x):
        G, nodes, slots = self._block_maps
        N, F = self.S.shape[0], self.H.shape[2]
        z = (np.asarray(x, dtype=float) @ G).reshape(-1, N, F)
        y = torch.tanh(torch.from_numpy(z)).numpy() @ self.w  # (batch, N, q)
        return y[:, nodes, slots]

    def arrays(self) -> dict:
        arrays = {"S": self.S, "H": self.H, "w": self.w}
        if self.blocks:
            arrays.update(state_nodes=self.state_nodes, input_nodes=self.input_nodes)
        return arrays

    @classmethod
    def from_arrays(cls, arrays: dict) -> "GCNNController":
        return cls(arrays["S"], arrays["H"], arrays["w"], arrays.get("state_nodes"), arrays.get("input_nodes"))

    @property
    def support(self) -> np.ndarray:
        """Node-level support (N, N): the given graph the filter shifts over."""
        return self.S != 0

    def linear_gain(self) -> np.ndarray:
        """Gain (m, n) of the controller linearized at the origin: sum_k (H_k . w) S^k.

        On node blocks, input a and state s see sum_k (S^k)_{node(a), node(s)} (H_k w)_{slot(s), slot(a)}.
        """
        if not self.blocks:
            coeffs = self.H @ self.w
            K = np.zeros_like(self.S)
            power = np.eye(self.S.shape[0])
            for c in coeffs:
                K += c * power
                power = self.S @ power
            return K
        coeffs = self.H @ self.w  # (K, p, q)
        sn, ss = self.state_nodes, node_ranks(self.state_nodes)
        un, us = self.input_nodes, node_ranks(self.input_nodes)
        K = np.zeros((un.size, sn.size))
        power = np.eye(self.S.shape[0])
        for c in coeffs:
            K += power[np.ix_(un, sn)] * c[ss][:, us].T
            power = self.S @ power
        return K




@dataclass(frozen=True)
class GCNNSettings(TrainingSettings):
    """The GCNN's training settings (the paper code's values): :class:`TrainingSettings` and these.

    Attributes
    ----------
    lr : float
        Initial learning rate.
    decay : float
        Factor the learning rate is multiplied by every ``decay_every`` updates (from update 0 on).
    decay_every : int
        Updates between learning-rate decays.
    weight_decay : float
        Coupled L2 weight decay (added to the gradient, as torch.optim.Adam does).
    engine : {"torch", "fused", "auto"}
        How the loss and its gradient are computed: torch's batched products, or one
        compiled pass per model (numba, :mod:`codesign.learned.gcnn_fused`), about twice as
        fast, on the paper's setting only (one state and one input per node, Q = R = I).
        The default "auto" takes "fused" there up to 32 nodes (beyond, its dense
        products are slower than torch's) and "torch" elsewhere, by the GRNN's rule
        (:func:`codesign.learned.engines.resolve_engine`); the engines agree to
        rounding at every step.
    """

    lr: Annotated[float, Above(0)] = 0.01
    decay: Annotated[float, Above(0), AtMost(1)] = 0.9
    decay_every: Annotated[int, AtLeast(1)] = 10
    weight_decay: Annotated[float, AtLeast(0)] = 2.0
    engine: Literal[ENGINES] = "auto"

    def loop(self, horizon: int) -> Loop:
        return Loop(steps=self.steps, batch=self.batch, horizon=horizon, curve_every=self.curve_every,
                    dtype=self.dtype, schedule="step", decay_every=self.decay_every,
                    weight_decay=self.weight_decay)


@dataclass
class _Job:
    instance: object
    seed: int
    params: dict
    settings: GCNNSettings
    engine: str = "torch"  # the one that runs ("auto" resolved)


def parse_job(instance, kwargs: dict) -> _Job:
    """One design's settings checked (``kwargs`` of :func:`gcnn`) and its engine chosen (``"auto"`` resolved)."""
    kwargs = dict(kwargs)
    seed = kwargs.pop("seed", 0)
    SEED.check(seed, "seed")
    settings = GCNNSettings.parse(kwargs, "GCNN")
    # Its kernel multiplies by S, A and B dense, in loops that unroll only for small N: at N = 50 and
    # 100 the fused pass trained 2.3x and 4.6x slower than torch's (the scale preset), at N = 20 2.1x
    # faster (benchmarks/bench_gcnn.py); hence support_density 1.
    unsupported = fused_unsupported(
        states_per_node=node_width(instance.state_nodes), inputs_per_node=node_width(instance.input_nodes),
        unit_weights=node_layout(instance) is None)
    engine = resolve_engine(settings.engine, unsupported=unsupported, nodes=instance.nodes, support_density=1.0)
    return _Job(instance, int(seed), {"seed": int(seed), **dict(sorted(settings.changed().items()))}, settings,
                engine)


def ensemble_member(job: _Job, m: int) -> Member:
    """Ensemble member ``m`` of a parsed job (:func:`parse_job`): its initial weights and seeds, ready to train."""
    inst, s = job.instance, job.settings
    channels, outputs = node_width(inst.state_nodes), node_width(inst.input_nodes)
    H0, w0 = gcnn_init(np.random.default_rng([job.seed, m, _INIT]), GCNN_TAPS, GCNN_FEATURES, channels, outputs)
    return Member(problem=GCNNProblem(inst, H0, w0), data_seed=[job.seed, m, _DATA], curve_x0=selection_set(inst, s.curve_size),
                  lr=s.lr, decay=s.decay, x0_factor=inst.x0_factor)


def gcnn_batch(jobs, *, stack_size: int = 64) -> list[Design]:
    """Train many GCNN designs together; ``jobs`` is an iterable of (Instance, kwargs of :func:`gcnn`)."""
    parsed = [parse_job(instance, kwargs) for instance, kwargs in jobs]
    trained, seconds = train_jobs(
        [TrainingJob(GCNNStack, [ensemble_member(job, m) for m in range(job.settings.ensemble)],
                     job.settings.loop(job.instance.horizon), options=(("engine", job.engine),))
         for job in parsed], stack_size=stack_size)
    return finish_designs(_finish, [(job, results, seconds[j]) for j, (job, results) in enumerate(zip(parsed, trained))],
                          states=min(job.instance.n for job in parsed))


def _controller(instance, params: dict) -> GCNNController:
    """The trained model as a controller: the (K, F), (F,) shapes whenever nodes hold one state and input."""
    H, w = params["H"], params["w"]
    if H.ndim == 2:
        return GCNNController(instance.gso, H, w)
    if instance.scalar_nodes:  # p = q = 1 (trained on the node-block path for Q, R other than I)
        return GCNNController(instance.gso, H[:, 0, :], w[:, 0])
    return GCNNController(instance.gso, H, w, instance.state_nodes, instance.input_nodes)


def _finish(job: _Job, results, seconds) -> Design:
    extras = {"ensemble_curve_costs": selection_costs(results),
              "diverged_members": sum(r.diverged for r in results)}
    links, self_loops = count_links(job.instance.comm_adj)
    best = best_member(results)
    if best is None:
        return Design.failure("gcnn", job.params, DIVERGED, "every ensemble member diverged",
                              info_model="instantaneous", seconds=seconds, links=links,
                              self_loops=self_loops, extras=extras)
    controller = _controller(job.instance, results[best].params)
    extras["curve"] = curve(results[best])
    extras["n_parameters"] = controller.n_parameters
    extras["spectral_radius"] = spectral_radius(job.instance.A + job.instance.B @ controller.linear_gain())
    s = job.settings
    return simulated_design(job.instance, controller, method="gcnn", params=job.params,
                            info_model="instantaneous", links=links, self_loops=self_loops, seconds=seconds,
                            extras=extras, stability_steps=s.stability_steps, stability_size=s.stability_size,
                            message=diverged_members_message(results))


def _dense_path_limit(instance, params: dict):
    """Off the paper's setting (node blocks, Q or R not I) the GCNN trains by dense products: its old limit."""
    if node_layout(instance) is None:
        return None
    return 300, ("off the paper's setting (nodes with several states or inputs, or Q, R other than I) its graph "
                 "filters are dense N x N products: one design takes 127 s at 200 states with the default settings")


# The runner hands gcnn_batch up to 25 runs at once: they train in shared stacks.
@method("gcnn", label="GCNN", batch=gcnn_batch, batch_size=25, produces=("training_curve",),
        node_blocks=True, max_states=1000, size_limit=_dense_path_limit,
        max_states_reason="the largest size it has been measured at (docs/performance.md, 'A thousand nodes'); "
                          "above 200 states its products with S, A and B run on their supports")
@takes_settings(GCNNSettings)
def gcnn(instance, *, seed: Annotated[int, AtLeast(0)] = 0, **settings) -> Design:
    """Gama-Sojoudi GCNN (192 parameters, instantaneous multi-hop information), trained as the paper did.

    On node blocks the filter has p input channels and q outputs per node
    (module docstring): 5 p 32 + 32 q parameters; any Q and R.

    Parameters
    ----------
    instance : Instance
    seed : int
        Seeds initializations and training draws (member k of the ensemble uses (seed, k)).
    **settings
        Any field of :class:`GCNNSettings`:

    Returns
    -------
    Design
        Simulated cost on the validation set (control-variate estimate; the
        sample mean in ``extras["plain_cost"]``); links are the given graph's
        off-diagonal edges (between nodes), ``info_model="instantaneous"``; ``extras`` holds the
        training curve, ``n_parameters``, the spectral radius of the closed loop
        linearized at the origin, and the boundedness of a long rollout.
    """
    return gcnn_batch([(instance, {"seed": seed, **settings})])[0]
