"""The GRNN distributed controller and its co-design (Yang & Matni 2021, Sec. II-C, III).

    Z(t+1) = tanh(S Z(t) W + x(t) F),   u(t) = Z(t+1) G,   Z(0) = 0,

with S supported on the communication graph: node i reads its neighbours'
hidden states once per step, so information travels one hop per time step.
With ``activation="identity"`` the same parameterization is a linear dynamic
controller (:class:`LinearGRNNController`) whose cost has a closed form.

Entry points: :func:`grnn` (one instance, one variant) and :func:`grnn_batch`
(many (instance, settings) jobs trained together in stacks of models by the one
trainer, :mod:`codesign.learned.trainer`; the model is
:class:`codesign.learned.grnn_bptt.GRNNStack`). :class:`GRNNSettings` is the one
table of the training settings and their bounds.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Annotated, Literal

import numpy as np

from .._lazy import lazy_import
from ..controllers import register_controller
from ..design import Design, count_links
from ..evaluation import STRUCTURED_ABOVE, exact_cost, impulse_responses, spectral_radius, structured_operator
from ..instances import hop_distances, node_ranks, node_width
from ..methods import Above, AtLeast, method
from ..status import DIVERGED, OPTIMAL
from .engines import ENGINES, resolve_engine
from .grnn_bptt import ACTIVATIONS, GRNNStack, ModelSpec, init_fwg
from .settings import SEED, TrainingSettings, takes_settings
from .trainer import (Loop, TrainingJob, best_member, curve, diverged_members_message, finish_designs,
                      selection_costs, selection_set, simulated_design, tanh_, train_jobs)

torch = lazy_import("torch")

#: Imported on use (numba loads with it), and part of the fingerprint of every method that uses this module.
FINGERPRINT_MODULES = ("codesign.learned.grnn_rollout",)

__all__ = ["GRNNController", "LinearGRNNController", "GRNNSettings", "grnn", "grnn_batch", "VARIANTS",
           "ACTIVATIONS", "grnn_defaults", "paper_beta", "PAPER_BETA"]

VARIANTS = ("given", "dense", "fixed", "sparse")

#: Salts that keep the random streams of one (instance, seed) apart.
_DATA, _INIT, _DENSE_S, _REFINE = 11, 12, 13, 14


def _slot_index(owners, nodes: int) -> tuple[np.ndarray, int]:
    """Where each state (or input) sits in the padded node signal, slot-major, and the slot count.

    Slot c of node i is entry c N + i: with one entry per node the layout is the plain one.
    """
    owners = np.asarray(owners, dtype=int)
    return node_ranks(owners) * nodes + owners, node_width(owners)


@register_controller("grnn")
@dataclass(frozen=True, eq=False)
class GRNNController:
    """A trained GRNN as the common simulator sees it (numpy, batched).

    Attributes
    ----------
    S : ndarray (N, N)
        Graph shift operator; its off-diagonal support is the set of links.
    F : ndarray (h,), or (p, h) when nodes hold several states
        Input weights: node i's (padded) states x_i in R^p enter its hidden state as x_i' F.
    W : ndarray (h, h)
    G : ndarray (h,), or (h, q) when nodes hold several inputs
        Readout: node i's (padded) inputs are Z_i G.
    state_nodes, input_nodes : ndarray of int, optional
        The node of each state and input (None: one of each per node, in order).
        State k is slot "its rank among its node's states" of its node's signal.
    """

    S: np.ndarray
    F: np.ndarray
    W: np.ndarray
    G: np.ndarray
    state_nodes: np.ndarray | None = None
    input_nodes: np.ndarray | None = None

    def __post_init__(self):
        for name in ("S", "F", "W", "G"):
            value = np.array(getattr(self, name), dtype=float)
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        if self.S.ndim != 2 or self.S.shape[0] != self.S.shape[1]:
            raise ValueError(f"S must be square, got shape {self.S.shape}")
        if self.W.ndim != 2 or self.W.shape[0] != self.W.shape[1]:
            raise ValueError(f"W must be square (h, h), got shape {self.W.shape}")
        h, nodes = self.W.shape[0], self.S.shape[0]
        blocks = self.state_nodes is not None or self.input_nodes is not None
        if not blocks:
            if self.F.size != h or self.G.size != h:
                raise ValueError(f"F, W, G must have shapes (h,), (h, h), (h,); got {self.F.shape}, "
                                 f"{self.W.shape}, {self.G.shape}")
            object.__setattr__(self, "F", self.F.ravel())
            object.__setattr__(self, "G", self.G.ravel())
            # Above STRUCTURED_ABOVE nodes a sparse S is multiplied on its support, the hidden
            # state kept node-major (N, h, batch) so that S acts on rows: a step then costs
            # O(N degree h batch) instead of O(N^2 h batch) (11x at N = 1000, 7 links per node).
            # At and below, the dense products run unchanged (the shipped reports' costs).
            sparse = structured_operator(self.S) if nodes > STRUCTURED_ABOVE else None
            object.__setattr__(self, "_S_op", sparse)
            return
        object.__setattr__(self, "_S_op", None)
        layout = {}
        for name, default in (("state_nodes", nodes), ("input_nodes", nodes)):
            value = getattr(self, name)
            owners = np.arange(default) if value is None else np.array(value, dtype=int)
            owners.setflags(write=False)
            object.__setattr__(self, name, owners)
            layout[name] = _slot_index(owners, nodes)
        (p_index, p), (q_index, q) = layout["state_nodes"], layout["input_nodes"]
        if self.F.shape in ((p, h), (h,) * (p == 1)) and self.G.shape in ((h, q), (h,) * (q == 1)):
            object.__setattr__(self, "F", self.F.reshape(p, h))
            object.__setattr__(self, "G", self.G.reshape(h, q))
        else:
            raise ValueError(f"with {p} states and {q} inputs per node, F and G must have shapes ({p}, {h}) and "
                             f"({h}, {q}); got {self.F.shape} and {self.G.shape}")
        object.__setattr__(self, "_state_index", p_index)
        object.__setattr__(self, "_input_index", q_index)

    @property
    def hidden(self) -> int:
        return self.W.shape[0]

    @property
    def blocks(self) -> bool:
        """Whether nodes hold several states or inputs (F and G are matrices)."""
        return self.state_nodes is not None

    def reset(self, batch: int):
        # Hidden state kept feature-major, (h, batch, N): W acts on the first axis and S on the
        # last, each as one wide matrix product. The node-major (N, batch, h) layout needs a
        # tall-thin (N batch, h) x (h, h) product that runs several times slower.
        if self._S_op is not None:
            return np.zeros((self.S.shape[0], self.hidden, batch))
        return np.zeros((self.hidden, batch, self.S.shape[0]))

    def _pre_activation(self, state, x):
        if self._S_op is not None:  # node-major (N, h, batch): S by its CSR on rows, W per node
            n, h, batch = state.shape
            pre = (self._S_op @ np.matmul(self.W.T, state).reshape(n, h * batch)).reshape(n, h, batch)
            xt = np.ascontiguousarray(x.T)  # no copy in a rollout, whose states are node-major
            for k in range(h):
                pre[:, k, :] += self.F[k] * xt
            return pre
        h, batch, n = state.shape
        pre = ((self.W.T @ state.reshape(h, batch * n)).reshape(h * batch, n) @ self.S.T).reshape(h, batch, n)
        if not self.blocks:
            pre += self.F[:, None, None] * x[None]
            return pre
        padded = np.zeros((batch, self.F.shape[0] * n))
        padded[:, self._state_index] = x
        pre += np.einsum("ck,bcn->kbn", self.F, padded.reshape(batch, -1, n))
        return pre

    def _output(self, Z):
        if self._S_op is not None:
            return np.ascontiguousarray(np.matmul(self.G, Z).T)
        h, batch, n = Z.shape
        if not self.blocks:
            return (self.G @ Z.reshape(h, batch * n)).reshape(batch, n)
        return np.einsum("kc,kbn->bcn", self.G, Z).reshape(batch, -1)[:, self._input_index]

    #: The activation of the compiled rollout (tanh; the identity in LinearGRNNController).
    _squash = True

    def rollout(self, instance, x0, steps: int):
        """Each draw's cost and each step's peak state from one compiled pass (:mod:`.grnn_rollout`).

        None where that pass does not apply: node blocks, S taken sparse above
        STRUCTURED_ABOVE nodes, or a plant without one input per node.
        """
        if self.blocks or self._S_op is not None or instance.m != instance.n or instance.n != self.S.shape[0]:
            return None
        from .grnn_rollout import rollout_costs  # numba loads on first use

        return rollout_costs(instance, self.S, self.F, self.W, self.G, x0, steps, squash=self._squash)

    def step(self, state, x):
        Z = self._pre_activation(state, x)
        # tanh as 2 sigmoid(2 z) - 1 through torch (shared memory, in place): numpy's float64
        # tanh takes most of a rollout; this is several times faster and within 4e-16 of it.
        tanh_(torch.from_numpy(Z))
        return self._output(Z), Z

    def arrays(self) -> dict:
        arrays = {"S": self.S, "F": self.F, "W": self.W, "G": self.G}
        if self.blocks:
            arrays.update(state_nodes=self.state_nodes, input_nodes=self.input_nodes)
        return arrays

    @classmethod
    def from_arrays(cls, arrays: dict) -> "GRNNController":
        return cls(arrays["S"], arrays["F"], arrays["W"], arrays["G"],
                   arrays.get("state_nodes"), arrays.get("input_nodes"))

    @property
    def support(self) -> np.ndarray:
        return self.S != 0

    @property
    def states(self) -> int:
        return self.S.shape[0] if not self.blocks else self.state_nodes.size

    def linearized_closed_loop(self, instance, *, sparse: bool = False):
        """Closed loop in (x, vec Z) linearized at the origin (tanh'(0) = 1).

        With z = vec(Z) row-major (node i's features at i h, ..., i h + h - 1):
        z' = (S kron W') z + Kzx x, u = Gm z', x' = A x + B u, where Kzx puts
        F' x_i into node i's features and Gm reads Z_i G (I kron F', I kron G'
        with one state and one input per node). ``sparse``: as a scipy CSR
        matrix, built from sparse factors (one state and one input per node), for
        :func:`~codesign.evaluation.spectral_radius` at a thousand nodes, where
        the dense matrix is (n + n h)^2 (288 MB at n = 1000, h = 5).
        """
        n, h = self.S.shape[0], self.hidden
        if sparse and not self.blocks:
            import scipy.sparse as sp

            Kzz = sp.kron(sp.csr_array(self.S), self.W.T, format="csr")
            Kzx = sp.kron(sp.eye_array(n), self.F.reshape(h, 1), format="csr")
            Gm = sp.kron(sp.eye_array(n), self.G.reshape(1, h), format="csr")
            B = sp.csr_array(instance.B)
            top = sp.hstack([sp.csr_array(instance.A) + B @ (Gm @ Kzx), B @ (Gm @ Kzz)])
            return sp.vstack([top, sp.hstack([Kzx, Kzz])], format="csr")
        Kzz = np.kron(self.S, self.W.T)
        if not self.blocks:
            Kzx = np.kron(np.eye(n), self.F.reshape(h, 1))
            Gm = np.kron(np.eye(n), self.G.reshape(1, h))
        else:
            s_nodes, s_slots = self.state_nodes, node_ranks(self.state_nodes)
            u_nodes, u_slots = self.input_nodes, node_ranks(self.input_nodes)
            Kzx = np.zeros((n * h, s_nodes.size))
            Gm = np.zeros((u_nodes.size, n * h))
            for k in range(h):
                Kzx[s_nodes * h + k, np.arange(s_nodes.size)] = self.F[s_slots, k]
                Gm[np.arange(u_nodes.size), u_nodes * h + k] = self.G[k, u_slots]
        top = np.hstack([instance.A + instance.B @ Gm @ Kzx, instance.B @ Gm @ Kzz])
        bottom = np.hstack([Kzx, Kzz])
        return np.vstack([top, bottom])


@register_controller("grnn_linear")
@dataclass(frozen=True, eq=False)
class LinearGRNNController(GRNNController):
    """A GRNN with the identity activation: Z(t+1) = S Z(t) W + x(t) F, u(t) = Z(t+1) G.

    A linear dynamic controller that relays information one hop per step, so its
    cost has a closed form (:meth:`closed_loop_responses`, scored by
    :func:`codesign.exact_cost`) and :meth:`linearized_closed_loop` is its exact
    closed loop.
    """

    _squash = False

    def step(self, state, x):
        Z = self._pre_activation(state, x)
        return self._output(Z), Z

    def closed_loop_responses(self, instance, steps: int | None = None):
        """Maps ``(phi_x, phi_u)`` of this controller in closed loop with the instance (by :meth:`step`)."""
        if instance.n != self.states:
            raise ValueError(f"controller has n = {self.states}, instance has n = {instance.n}")
        return impulse_responses(instance, self, steps)


@dataclass(frozen=True)
class GRNNSettings(TrainingSettings):
    """The GRNN's training settings (the paper code's values): :class:`TrainingSettings` and these.

    Attributes
    ----------
    hidden : int
        Hidden size h of each node's state.
    lr : float
        Learning rate (of the refinement, for ``sparse``).
    l1_lr : float
        Learning rate of the ``sparse`` variant's l1 stage (0.03 in the paper's code).
    clip : float
        Gradient-norm clip per model (0 disables it).
    frob : float
        Weight of the plain Frobenius norms of S, F, G in the loss (W is not penalized).
    refine_ensemble : int
        Refinement runs of the ``sparse`` variant (the paper code used one).
    threshold : float
        Entries of the l1 stage's S below this magnitude are cut (the paper's 0.004).
    l1_hops : int, optional
        The ``sparse`` variant's candidate links: the l1 stage trains S on the pairs
        of nodes within this many hops of the given communication graph (self-loops
        included) instead of on all N^2 pairs (None, the paper's). Needed above
        :data:`DENSE_L1_MAX_STATES` states, where a dense S makes the l1 stage too slow.
    activation : {"tanh", "identity"}
        σ in Z(t+1) = σ(S Z(t) W + x(t) F): the paper's tanh, or the identity (the
        linear GRNN: a linear dynamic controller with the same parameterization,
        information model and training, scored exactly with ``cost_kind="exact"``;
        ``bounded`` is then whether its closed loop's spectral radius is below 1).
    engine : {"torch", "fused", "auto"}
        How the loss and its gradient are computed: one torch call per product
        and time step, or one compiled pass per model (numba), 2-3x as fast,
        needing one state and one input per node. The default "auto" takes
        "fused" where it applies and is faster (not on node blocks, nor for an S
        over half full at more than 32 nodes). The engines agree to rounding at
        every step; over a 750-step run that can grow to 1e-4 or so in the final cost.
    """

    hidden: Annotated[int, AtLeast(1)] = 5
    lr: Annotated[float, Above(0)] = 0.02
    l1_lr: Annotated[float, Above(0)] = 0.03
    clip: Annotated[float, AtLeast(0)] = 10.0
    frob: Annotated[float, AtLeast(0)] = 2.0
    refine_ensemble: Annotated[int, AtLeast(1)] = 1
    threshold: Annotated[float, AtLeast(0)] = 4e-3
    l1_hops: Annotated[int, AtLeast(1)] | None = None
    activation: Literal[ACTIVATIONS] = "tanh"
    engine: Literal[ENGINES] = "auto"

    def loop(self, horizon: int) -> Loop:
        return Loop(steps=self.steps, batch=self.batch, horizon=horizon, clip=self.clip,
                    curve_every=self.curve_every, dtype=self.dtype)


def grnn_defaults() -> dict:
    """The paper code's training settings (docs/methods.md), by name."""
    return dataclasses.asdict(GRNNSettings())


@dataclass
class _Job:
    instance: object
    variant: str
    beta: float | None
    seed: int
    settings: GRNNSettings
    params: dict


def _parse(instance, kwargs: dict) -> _Job:
    """One run's keywords as a job; ValueError naming the first bad one, before any training."""
    kwargs = dict(kwargs)
    variant = kwargs.pop("variant", "given")
    beta = kwargs.pop("beta", None)
    seed = kwargs.pop("seed", 0)
    if variant not in VARIANTS:
        raise ValueError(f"variant must be one of {VARIANTS}, got {variant!r}")
    if variant == "sparse":
        beta = paper_beta(instance) if beta is None else beta
        if not (isinstance(beta, (int, float, np.floating)) and np.isfinite(beta) and beta >= 0):
            raise ValueError(f"beta must be a finite non-negative number, got {beta!r}")
    elif beta is not None:
        raise ValueError(f"beta applies to variant 'sparse' only, got beta={beta!r} with variant {variant!r}")
    SEED.check(seed, "seed")
    settings = GRNNSettings.parse(kwargs, "GRNN")
    resolve_engine(settings.engine, _slot_index(instance.state_nodes, instance.nodes)[1],
                   _slot_index(instance.input_nodes, instance.nodes)[1])  # fails now, not after training
    params = {"variant": variant, "seed": int(seed), **dict(sorted(settings.changed().items()))}
    if beta is not None:
        params["beta"] = float(beta)
    return _Job(instance, variant, None if beta is None else float(beta), int(seed), settings, params)


#: The l1 weights the paper used for Table 1, by ||A||.
PAPER_BETA = {0.995: 1.0, 1.05: 2.0}


def paper_beta(instance) -> float:
    """The paper's Table 1 l1 weight for this instance's ||A|| (1 for 0.995, 2 for 1.05)."""
    a_norm = instance.spec.get("a_norm")
    for key, value in PAPER_BETA.items():
        if a_norm is not None and abs(a_norm - key) < 1e-12:
            return value
    raise ValueError(
        f"variant 'sparse' needs beta (the l1 weight); the paper's Table 1 values exist only for "
        f"a_norm in {sorted(PAPER_BETA)}, this instance has a_norm={a_norm!r}"
    )


def _padded_problem(inst) -> dict:
    """The plant, costs and placements in the trainer's padded node layout (p states, q inputs per node).

    With one state and one input per node the layout is the plant's own.
    """
    if inst.scalar_nodes:
        return dict(A=inst.A, B=inst.B, Q=inst.Q, R=inst.R, P=inst.P, state_index=None, p=1, q=1,
                    embed=lambda x: x)
    N = inst.nodes
    s_index, p = _slot_index(inst.state_nodes, N)
    u_index, q = _slot_index(inst.input_nodes, N)
    Ex = np.zeros((p * N, inst.n))
    Ex[s_index, np.arange(inst.n)] = 1.0
    Eu = np.zeros((q * N, inst.m))
    Eu[u_index, np.arange(inst.m)] = 1.0
    return dict(A=Ex @ inst.A @ Ex.T, B=Ex @ inst.B @ Eu.T, Q=Ex @ inst.Q @ Ex.T, R=Eu @ inst.R @ Eu.T,
                P=Ex @ inst.P @ Ex.T, state_index=s_index, p=p, q=q, embed=lambda x: x @ Ex.T)


def _spec(job: _Job, member: int, *, S0, mask, lr, beta, penalty, init_salt) -> ModelSpec:
    inst, s = job.instance, job.settings
    padded = _padded_problem(inst)
    F, W, G = init_fwg(np.random.default_rng([job.seed, member, init_salt]), s.hidden, padded["p"], padded["q"])
    return ModelSpec(
        A=padded["A"], B=padded["B"], Q=padded["Q"], R=padded["R"], P=padded["P"], trace_P=inst.trace_P,
        S0=np.asarray(S0, dtype=float), mask=np.asarray(mask, dtype=bool), F0=F, W0=W, G0=G,
        data_seed=[job.seed, member, _DATA], curve_x0=padded["embed"](selection_set(inst, s.curve_size)),
        lr=lr, beta=beta, penalty=penalty, state_index=padded["state_index"],
    )


def _dense_init(job: _Job, member: int, mask: np.ndarray | None = None) -> np.ndarray:
    rng = np.random.default_rng([job.seed, member, _DENSE_S])
    S = rng.random((job.instance.nodes, job.instance.nodes))
    if mask is not None:
        S = np.where(mask, S, 0.0)
    return S / S.sum(axis=1, keepdims=True)  # row-stochastic (on the candidates), as in the paper code


def _l1_candidates(job: _Job) -> np.ndarray:
    """Where the l1 stage's S may be nonzero: every pair, or the pairs within ``l1_hops`` hops."""
    n, hops = job.instance.nodes, job.settings.l1_hops
    if hops is None:
        return np.ones((n, n), bool)
    return hop_distances(job.instance.comm_adj) <= hops


def _first_stage_specs(job: _Job) -> list[ModelSpec]:
    inst, s = job.instance, job.settings
    standard = (s.frob, s.frob, 0.0, s.frob)
    n = inst.nodes
    specs = []
    for member in range(s.ensemble):
        if job.variant == "given":
            specs.append(_spec(job, member, S0=inst.gso, mask=inst.comm_adj != 0,
                               lr=s.lr, beta=0.0, penalty=standard, init_salt=_INIT))
        elif job.variant == "fixed":
            specs.append(_spec(job, member, S0=inst.gso, mask=np.zeros((n, n), bool),
                               lr=s.lr, beta=0.0, penalty=standard, init_salt=_INIT))
        elif job.variant == "dense":
            specs.append(_spec(job, member, S0=_dense_init(job, member), mask=np.ones((n, n), bool),
                               lr=s.lr, beta=0.0, penalty=standard, init_salt=_INIT))
        else:  # l1 stage: the paper code's sparse_criterion penalizes ||S|| and ||F|| only
            candidates = _l1_candidates(job)
            init = _dense_init(job, member, None if job.settings.l1_hops is None else candidates)
            specs.append(_spec(job, member, S0=init, mask=candidates,
                               lr=s.l1_lr, beta=float(job.beta), penalty=(s.frob, s.frob, 0.0, 0.0),
                               init_salt=_INIT))
    return specs


def _refine_specs(job: _Job, S_l1: np.ndarray) -> list[ModelSpec]:
    s = job.settings
    mask = np.abs(S_l1) >= s.threshold
    return [_spec(job, member, S0=np.where(mask, S_l1, 0.0), mask=mask, lr=s.lr, beta=0.0,
                  penalty=(s.frob, s.frob, 0.0, s.frob), init_salt=_REFINE)
            for member in range(s.refine_ensemble)]


def _training(job: _Job, specs: list[ModelSpec]) -> TrainingJob:
    s = job.settings
    return TrainingJob(GRNNStack, [spec.member() for spec in specs], s.loop(job.instance.horizon),
                       options=(("activation", s.activation), ("engine", s.engine)))


def grnn_batch(jobs, *, stack_size: int = 128) -> list[Design]:
    """Train many GRNN designs together; one :class:`Design` per job, in order.

    Parameters
    ----------
    jobs : iterable of (Instance, dict)
        Each dict holds :func:`grnn`'s keyword arguments (``variant``, ``beta``,
        ``seed`` and any field of :class:`GRNNSettings`). Jobs with the same
        loop settings (steps, batch, horizon, dtype, ...) share stacks of up to
        ``stack_size`` models: ensemble members, variants, instances and the
        sparse variant's l1 stage all train side by side, then all refinements.
    """
    parsed = [_parse(instance, kwargs) for instance, kwargs in jobs]
    if not parsed:
        return []
    first, seconds = train_jobs([_training(job, _first_stage_specs(job)) for job in parsed], stack_size=stack_size)
    chosen = [best_member(results) for results in first]

    refine = [j for j, job in enumerate(parsed) if job.variant == "sparse" and chosen[j] is not None]
    refined, refine_seconds = train_jobs(
        [_training(parsed[j], _refine_specs(parsed[j], first[j][chosen[j]].params["S"])) for j in refine],
        stack_size=stack_size)
    refined_by_job = dict(zip(refine, refined))
    for j, extra in zip(refine, refine_seconds):
        seconds[j] += extra
    return finish_designs(_finish, [(job, first[j], chosen[j], refined_by_job.get(j), seconds[j])
                                    for j, job in enumerate(parsed)],
                          states=min(job.instance.n for job in parsed))


def _finish(job: _Job, first, chosen, refined, seconds) -> Design:
    method = "grnn" if job.variant == "given" else f"grnn_{job.variant}"
    extras: dict = {
        "variant": job.variant,
        "ensemble_curve_costs": selection_costs(first),
        "diverged_members": sum(r.diverged for r in first),
    }
    if chosen is None:
        return Design.failure(method, job.params, DIVERGED,
                              f"all {len(first)} ensemble members diverged (non-finite loss or gradient)",
                              info_model="delayed", seconds=seconds, extras=extras)
    result = first[chosen]
    if job.variant == "sparse":
        extras["l1_curve"] = curve(result)
        extras["l1_links"], extras["l1_self_loops"] = count_links(np.abs(result.params["S"]) >= job.settings.threshold)
        best = best_member(refined) if refined else None
        extras["refine_curve_costs"] = selection_costs(refined)
        if best is None:
            return Design.failure(method, job.params, DIVERGED, "every refinement run diverged",
                                  info_model="delayed", seconds=seconds, extras=extras)
        result = refined[best]
    linear = job.settings.activation == "identity"
    nodes = {} if job.instance.scalar_nodes else dict(state_nodes=job.instance.state_nodes,
                                                       input_nodes=job.instance.input_nodes)
    controller = (LinearGRNNController if linear else GRNNController)(**result.params, **nodes)
    links, self_loops = count_links(controller.S)
    extras["curve"] = curve(result)
    extras["spectral_radius"] = spectral_radius(
        controller.linearized_closed_loop(job.instance, sparse=job.instance.n > STRUCTURED_ABOVE))
    if linear:
        return _finish_linear(job, controller, first, links, self_loops, seconds, extras)
    return simulated_design(job.instance, controller, method=method, params=job.params, info_model="delayed",
                            links=links, self_loops=self_loops, seconds=seconds, extras=extras,
                            stability_steps=job.settings.stability_steps,
                            stability_size=job.settings.stability_size, message=diverged_members_message(first))


def _finish_linear(job: _Job, controller, first, links, self_loops, seconds, extras) -> Design:
    """A linear GRNN scored exactly; stable in the long run iff its closed loop's spectral radius is < 1."""
    method = "grnn" if job.variant == "given" else f"grnn_{job.variant}"
    cost = exact_cost(job.instance, controller)
    extras["bounded"] = bool(extras["spectral_radius"] < 1.0)
    if not np.isfinite(cost):
        return Design.failure(method, job.params, DIVERGED, "the trained linear GRNN's exact cost is not finite",
                              info_model="delayed", seconds=seconds, links=links, self_loops=self_loops,
                              extras=extras)
    return Design(method=method, params=job.params, controller=controller, cost=cost, links=links,
                  self_loops=self_loops, info_model="delayed", status=OPTIMAL,
                  message=diverged_members_message(first), seconds=seconds, cost_stderr=0.0, cost_kind="exact",
                  extras=extras)


@takes_settings(GRNNSettings)
def grnn(instance, *, variant: str = "given", beta: Annotated[float, AtLeast(0)] | None = None,
         seed: Annotated[int, AtLeast(0)] = 0, **settings) -> Design:
    """Train a GRNN distributed controller on ``instance`` (paper Sec. III).

    Parameters
    ----------
    instance : Instance
    variant : {"given", "dense", "fixed", "sparse"}
        ``given``: S trains on the given graph's support (self-loops included),
        starting at the normalized adjacency. ``dense``: all N^2 entries train,
        starting row-stochastic random. ``fixed``: S frozen at the normalized
        adjacency. ``sparse``: co-design: an l1 stage on a dense S with weight
        ``beta`` (learning rate ``l1_lr``), entries with ``|S_ij| < threshold``
        zeroed, then a refinement on that support from the l1 values with F, W, G
        re-initialized. With ``l1_hops`` the l1 stage's candidates are the pairs
        within that many hops of the given graph instead of all N^2.
    beta : float, optional
        l1 weight, only allowed with ``variant="sparse"``. None there means the
        paper's Table 1 value for the instance's ||A||: 1 for 0.995, 2 for 1.05
        (ValueError for other norms).
    seed : int
        Seeds the training draws and initializations (member k of the ensemble
        uses streams derived from (seed, k)).
    **settings
        Any field of :class:`GRNNSettings` (the learning rate is cosine-annealed
        to 0 over the ``steps``; float32 is 1.5-2x as fast as float64,
        docs/performance.md):

    Returns
    -------
    Design
        ``cost`` is simulated on the instance's validation set (2000 draws; the
        control-variate estimate, the sample mean in ``extras["plain_cost"]``) with
        its standard error; ``extras`` holds the training curve
        (``extras["curve"] = {"step": [...], "cost": [...]}``), the linearized
        closed loop's ``spectral_radius`` and whether a ``stability_steps``
        rollout stays ``bounded``. Links are the off-diagonal support of S,
        with one step of delay per hop (``info_model="delayed"``).
    """
    return grnn_batch([(instance, {"variant": variant, "beta": beta, "seed": seed, **settings})])[0]


#: Settings of the co-design (l1 stage, threshold, refinement) that only ``sparse`` uses.
_SPARSE_ONLY = ("beta", "l1_lr", "threshold", "refine_ensemble", "l1_hops")


class _VariantBatch:
    """``grnn_batch`` for one variant: trains a runner's batch of runs in shared stacks."""

    def __init__(self, variant: str):
        self.variant = variant

    def __call__(self, pairs):
        return grnn_batch([(inst, {**params, "variant": self.variant}) for inst, params in pairs])


#: Variants are refused at once above these many states. Above STRUCTURED_ABOVE states training
#: multiplies S, A and B on their supports (the fused engine) and so do the rollouts that score
#: a design, so a time step costs O(N degree h batch): at 1000 states one GRNN design on the
#: given graph took 270 s with the default settings (one thread, docs/performance.md). A dense S
#: stays O(N^2): the ``dense`` variant, and the l1 stage of ``sparse`` without ``l1_hops``.
MAX_STATES = {"given": 1000, "fixed": 1000, "sparse": 1000, "dense": 500}
#: The most states of GRNN-Sparse's l1 stage on all N^2 pairs (``l1_hops`` None).
DENSE_L1_MAX_STATES = 500
_DENSE_S_REASON = ("S is a dense N x N matrix: one design takes 416 s at 500 states with the default settings, "
                   "about 20 minutes of training at 1000, where an Adam step of one model takes 0.74 s "
                   "(its products grow like N^2)")
_MEASURED = "the largest size it has been measured at (docs/performance.md, 'A thousand nodes')"
_MAX_STATES_REASONS = {"sparse": _MEASURED, "dense": _DENSE_S_REASON, "given": _MEASURED, "fixed": _MEASURED}


def _blocks_limit(instance, params: dict):
    """Nodes with several states or inputs: the torch engine's and the rollouts' dense products."""
    if not getattr(instance, "scalar_nodes", True):
        return DENSE_L1_MAX_STATES, "on nodes with several states or inputs its products with S, A and B are dense"
    return None


def _sparse_limit(instance, params: dict):
    """GRNN-Sparse's tighter size limits: its l1 stage on all N^2 pairs (``l1_hops`` not set), node blocks."""
    if params.get("l1_hops") is None:
        return DENSE_L1_MAX_STATES, f"its l1 stage trains all N^2 pairs; {_DENSE_S_REASON}: set l1_hops " \
                                    f"(e.g. 3) to train on a few hops of the communication graph"
    return _blocks_limit(instance, params)


# One function, four methods: the variant is bound, and the co-design's own settings
# are hidden from the other variants so that a spec setting them is an error naming the key.
for _name, _variant, _label, _summary in (
    ("grnn", "given", "GRNN", "GRNN with S trained on the given communication graph (one step delay per hop)."),
    ("grnn_dense", "dense", "GRNN-Dense", "GRNN with all N^2 entries of S trained (a centralized, delayed controller)."),
    ("grnn_fixed", "fixed", "GRNN-Fixed", "GRNN with S frozen at the normalized adjacency; only F, W, G train."),
    ("grnn_sparse", "sparse", "GRNN-Sparse",
     "GRNN co-design: l1 stage on a dense S, threshold, refinement on the found support."),
):
    method(_name, label=_label, summary=_summary, bind={"variant": _variant},
           exclude=() if _variant == "sparse" else _SPARSE_ONLY, batch=_VariantBatch(_variant), batch_size=25,
           node_blocks=True,
           max_states=MAX_STATES[_variant], max_states_reason=_MAX_STATES_REASONS[_variant],
           size_limit=_sparse_limit if _variant == "sparse" else _blocks_limit,
           produces=("training_curve", "topology_path") if _variant == "sparse" else ("training_curve",),
           path_param="beta" if _variant == "sparse" else None)(grnn)
