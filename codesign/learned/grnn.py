"""The GRNN distributed controller and its co-design (Yang & Matni 2021, Sec. II-C, III).

    Z(t+1) = tanh(S Z(t) W + x(t) F),   u(t) = Z(t+1) G,   Z(0) = 0,

with S supported on the communication graph: node i reads its neighbours'
hidden states once per step, so information travels one hop per time step.
With ``activation="identity"`` the same parameterization is a linear dynamic
controller (:class:`LinearGRNNController`) whose cost has a closed form. With
``readout="per_node"`` node i reads out u_i(t) = Z_i(t+1) G_i with a G_i of its own
(the paper's G is shared, so every node has the same local gain F G); that class
holds every delayed static gain exactly (:mod:`codesign.learned.embedding`).

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
from ..design import Design, count_links
from ..evaluation import STRUCTURED_ABOVE, exact_cost, spectral_radius
from ..instances import hop_distances, node_width
from ..methods import Above, AtLeast
from ..status import DIVERGED, OPTIMAL
from .engines import ENGINES, fused_unsupported, resolve_engine
from .grnn_bptt import ACTIVATIONS, READOUTS, GRNNStack, ModelSpec, init_fwg
from .settings import SEED, TrainingSettings, takes_settings
from .trainer import (Loop, TrainingJob, best_member, curve, diverged_members_message, finish_designs,
                      selection_costs, selection_set, simulated_design, train_jobs)
from .grnn_controller import GRNNController, LinearGRNNController, slot_index
from .warm import INITS, Start, StartSources, build_start, check_warm_settings, member_start

torch = lazy_import("torch")

#: Imported on use (numba loads with it), and part of the fingerprint of every method that uses this module.
FINGERPRINT_MODULES = ("codesign.learned.grnn_rollout",)

__all__ = ["GRNNController", "LinearGRNNController", "GRNNSettings", "grnn", "grnn_batch", "VARIANTS",
           "ACTIVATIONS", "READOUTS", "INITS", "grnn_defaults", "paper_beta", "PAPER_BETA"]

VARIANTS = ("given", "dense", "fixed", "sparse")

#: Salts that keep the random streams of one (instance, seed) apart.
_DATA, _INIT, _DENSE_S, _REFINE = 11, 12, 13, 14


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
        Weight of the plain Frobenius norms of S, F, G in the loss (W is not penalized;
        with a per-node readout, of ||G||_F / sqrt(N), the root mean square of the
        nodes' readouts, so that N equal readouts cost what the shared one does).
    refine_ensemble : int
        Refinement runs of the ``sparse`` variant (the paper code used one).
    threshold : float
        Entries of the l1 stage's S below this magnitude are cut (the paper's 0.004).
    l1_hops : int, optional
        The ``sparse`` variant's candidate links: the l1 stage trains S on the pairs
        of nodes within this many hops of the given communication graph (self-loops
        included) instead of on all N^2 pairs (None, the paper's). Needed above
        :data:`baselines.grnn.DENSE_L1_MAX_STATES` states, where a dense S makes the l1 stage too slow.
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
        A per-node readout trains on "torch" ("auto" takes it; "fused" is an error).
    readout : {"shared", "per_node"}
        u_i(t) = z_i(t+1) G: one readout G shared by every node (the paper's, so every
        node has the same instantaneous local gain F G), or ``"per_node"``: node i
        reads out with its own G_i (G of shape (N, h), or (N, h, q)), which with
        h >= 2 and the identity activation contains every delayed static gain on one
        state and one input per node (:func:`codesign.learned.embed_delayed_gain`).
        Each G_i starts at the shared initialization. A per-node design is tied to
        its graph's size: it does not transfer to a graph with another number of nodes.
    init : {"random", "diagonal", "delayed", "auto"}
        The first parameters: the paper's random draw, or a warm start, a static design
        on the same instance embedded exactly (:mod:`codesign.learned.warm`): the best
        diagonal gain (:func:`baselines.decentralized`), or a delayed gain
        (``sparse``: the delayed l1 path's design at γ = β / trace(P); ``dense``: the
        path's dense end; ``given``: the delayed gain polished on the given graph's
        links; not ``fixed``); these designs are the method layer's, so a warm start
        runs through :func:`baselines.grnn` (the registered methods do), or takes
        ``start=``; ``auto``: the diagonal gain where the open-loop spectral
        radius exceeds :data:`~codesign.learned.warm.AUTO_RADIUS` (1.22, measured), else
        the random draw. Needs ``readout="per_node"`` and ``hidden`` >= 2 states per
        node. Every member starts at the design's closed loop, with learning rates
        divided by its state scale. The design is the start itself where training ended
        above it (selection-set cost; exact cost with the identity activation), diverged,
        or diverged when scored: ``extras["kept_start"]``, ``init_cost``,
        ``trained_cost`` and the message say so.
    init_scale : float
        How far into tanh the warm start's hidden states reach: the embedding's ε (F scaled
        by ε, G by 1/ε) is init_scale / the largest standard deviation of a state along the
        design's closed loop. A smaller value keeps tanh closer to linear (the start's cost
        gap to the design, ``extras["init_tanh_gap"]``, shrinks like its square) and the
        start stable from larger states; a larger one suits Adam's steps.
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
    readout: Literal[READOUTS] = "shared"
    init: Literal[INITS] = "random"
    init_scale: Annotated[float, Above(0)] = 0.1

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
    start: Start | None = None  # with init != "random": the warm start (set by grnn_batch)
    source: object = None  # with init "delayed": the delayed design the caller gives as the start


def _parse(instance, kwargs: dict) -> _Job:
    """One run's keywords as a job; ValueError naming the first bad one, before any training."""
    kwargs = dict(kwargs)
    variant = kwargs.pop("variant", "given")
    beta = kwargs.pop("beta", None)
    seed = kwargs.pop("seed", 0)
    source = kwargs.pop("start", None)
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
    check_warm_settings(settings, variant, instance)
    if source is not None and settings.init != "delayed":
        raise ValueError(f"start (a delayed design to start from) needs init 'delayed', got init {settings.init!r}")
    resolve_engine(settings.engine, unsupported=fused_unsupported(  # fails now, not after training
        states_per_node=node_width(instance.state_nodes), inputs_per_node=node_width(instance.input_nodes),
        readout=settings.readout))
    params = {"variant": variant, "seed": int(seed), **dict(sorted(settings.changed().items()))}
    if beta is not None:
        params["beta"] = float(beta)
    return _Job(instance, variant, None if beta is None else float(beta), int(seed), settings, params, source=source)


def check_settings(params: dict, *, variant: str = "given") -> None:
    """ValueError for GRNN settings that are each valid but not together, without an instance.

    What :func:`_parse` refuses before any training that needs no instance: a warm start
    the variant or readout cannot take (:func:`~codesign.learned.warm.check_warm_settings`)
    and the fused engine with a per-node readout. Each GRNN method registers it as its
    ``check`` (:class:`codesign.methods.Method`), so that a spec asking for these is refused
    when it is loaded, not stored as a ``failed`` run that a rerun never retries.

    Parameters
    ----------
    params : dict
        One run's hyperparameters (keys that are not :class:`GRNNSettings` fields, such as
        ``beta`` and ``seed``, are checked elsewhere).
    variant : str
        The variant the method binds.
    """
    fields = {f.name for f in dataclasses.fields(GRNNSettings)}
    settings = GRNNSettings.parse({k: v for k, v in params.items() if k in fields}, "GRNN")
    check_warm_settings(settings, variant)
    resolve_engine(settings.engine, unsupported=fused_unsupported(readout=settings.readout))


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
    s_index, p = slot_index(inst.state_nodes, N)
    u_index, q = slot_index(inst.input_nodes, N)
    Ex = np.zeros((p * N, inst.n))
    Ex[s_index, np.arange(inst.n)] = 1.0
    Eu = np.zeros((q * N, inst.m))
    Eu[u_index, np.arange(inst.m)] = 1.0
    return dict(A=Ex @ inst.A @ Ex.T, B=Ex @ inst.B @ Eu.T, Q=Ex @ inst.Q @ Ex.T, R=Eu @ inst.R @ Eu.T,
                P=Ex @ inst.P @ Ex.T, state_index=s_index, p=p, q=q, embed=lambda x: x @ Ex.T)


def _spec(job: _Job, member: int, *, S0, mask, lr, beta, penalty, init_salt, fwg=None) -> ModelSpec:
    """One member's spec; ``fwg``: its first (F, W, G) where not drawn (a warm start's refinement)."""
    inst, s = job.instance, job.settings
    padded = _padded_problem(inst)
    F, W, G = init_fwg(np.random.default_rng([job.seed, member, init_salt]), s.hidden, padded["p"], padded["q"])
    if s.readout == "per_node":
        # Every node starts at the shared draw, and ||G||_F / sqrt(N) is penalized: the start is the
        # shared model's, loss included, and the same draws as a shared run (no extra stream).
        G = np.repeat(G[None], inst.nodes, axis=0)
        penalty = (*penalty[:3], penalty[3] / np.sqrt(inst.nodes))
    if job.start is not None and job.start.warm:
        # The embedded design, the member's draw only on the features it leaves unread, and learning rates
        # divided by the start's state scale, as its F is (codesign/learned/warm.py).
        lr = lr * job.start.lr_factor
        if fwg is None:
            S0, F, W, G = member_start(job.start, F, W, np.where(mask, S0, 0.0) if mask.any() else S0, padded["p"])
    if fwg is not None:
        F, W, G = (np.array(a, dtype=float) for a in fwg)
    return ModelSpec(
        A=padded["A"], B=padded["B"], Q=padded["Q"], R=padded["R"], P=padded["P"], trace_P=inst.trace_P,
        S0=np.asarray(S0, dtype=float), mask=np.asarray(mask, dtype=bool), F0=F, W0=W, G0=G,
        data_seed=[job.seed, member, _DATA], curve_x0=padded["embed"](selection_set(inst, s.curve_size)),
        lr=lr, beta=beta, penalty=penalty, state_index=padded["state_index"], x0_factor=inst.x0_factor,
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


def _refine_specs(job: _Job, l1: dict) -> list[ModelSpec]:
    """The refinement on the l1 stage's support: F, W, G redrawn (the paper's), or kept from a warm start's l1 stage."""
    s = job.settings
    S_l1 = l1["S"]
    mask = np.abs(S_l1) >= s.threshold
    fwg = (l1["F"], l1["W"], l1["G"]) if job.start is not None and job.start.warm else None
    return [_spec(job, member, S0=np.where(mask, S_l1, 0.0), mask=mask, lr=s.lr, beta=0.0,
                  penalty=(s.frob, s.frob, 0.0, s.frob), init_salt=_REFINE, fwg=fwg)
            for member in range(s.refine_ensemble)]


def _training(job: _Job, specs: list[ModelSpec]) -> TrainingJob:
    s = job.settings
    options = (("activation", s.activation), ("engine", s.engine))
    if s.readout != "shared":  # the shared runs' options (their stacks' keys) stay as they were
        options += (("readout", s.readout),)
    return TrainingJob(GRNNStack, [spec.member() for spec in specs], s.loop(job.instance.horizon), options=options)


def _warm_starts(parsed: list[_Job], sources: StartSources | None) -> None:
    """Each warm-started job's :class:`Start`, its source design from ``sources`` (which caches it per instance)."""
    import time

    for job in parsed:
        if job.settings.init != "random":
            t0 = time.perf_counter()
            job.start = build_start(sources, job.instance, job.settings, job.variant, job.beta, source=job.source)
            job.start.extras["init_seconds"] = time.perf_counter() - t0  # 0 where the source was computed already


def grnn_batch(jobs, *, stack_size: int = 128, sources: StartSources | None = None) -> list[Design]:
    """Train many GRNN designs together; one :class:`Design` per job, in order.

    Parameters
    ----------
    jobs : iterable of (Instance, dict)
        Each dict holds :func:`grnn`'s keyword arguments (``variant``, ``beta``,
        ``seed`` and any field of :class:`GRNNSettings`; ``start``, with ``init =
        "delayed"``, a delayed static design to start from instead of the variant's
        own, as :func:`baselines.refit` gives its refitted gain). Jobs with the same
        loop settings (steps, batch, horizon, dtype, ...) share stacks of up to
        ``stack_size`` models: ensemble members, variants, instances and the
        sparse variant's l1 stage all train side by side, then all refinements.
    stack_size : int
        The most models one stack trains side by side.
    sources : StartSources, optional
        Where warm starts' static designs come from (the method layer's:
        ``baselines.grnn_batch`` passes them). None: a job whose ``init`` needs one
        and has no ``start`` is a one-line ValueError before any training.
    """
    parsed = [_parse(instance, kwargs) for instance, kwargs in jobs]
    if not parsed:
        return []
    _warm_starts(parsed, sources)
    specs = [_first_stage_specs(job) for job in parsed]
    first, seconds = train_jobs([_training(job, job_specs) for job, job_specs in zip(parsed, specs)],
                                stack_size=stack_size)
    for j, job in enumerate(parsed):
        if job.start is not None:
            seconds[j] += job.start.extras.get("init_seconds", 0.0)
    chosen = [best_member(results) for results in first]

    refine = [j for j, job in enumerate(parsed) if job.variant == "sparse" and chosen[j] is not None]
    refined, refine_seconds = train_jobs(
        [_training(parsed[j], _refine_specs(parsed[j], first[j][chosen[j]].params)) for j in refine],
        stack_size=stack_size)
    refined_by_job = dict(zip(refine, refined))
    for j, extra in zip(refine, refine_seconds):
        seconds[j] += extra
    return finish_designs(_finish, [(job, first[j], chosen[j], refined_by_job.get(j), seconds[j])
                                    for j, job in enumerate(parsed)],
                          states=min(job.instance.n for job in parsed))


def _method_name(job: _Job) -> str:
    return "grnn" if job.variant == "given" else f"grnn_{job.variant}"


def _trained(job: _Job, first, chosen, refined) -> tuple:
    """(result, failure, extras) of a run's training: the chosen member (the sparse variant's refined one),
    or None and why; the extras every GRNN design records about its training."""
    extras: dict = {
        "variant": job.variant,
        "ensemble_curve_costs": selection_costs(first),
        "diverged_members": sum(r.diverged for r in first),
    }
    if chosen is None:
        return None, f"all {len(first)} ensemble members diverged (non-finite loss or gradient)", extras
    result = first[chosen]
    if job.variant == "sparse":
        extras["l1_curve"] = curve(result)
        extras["l1_links"], extras["l1_self_loops"] = count_links(np.abs(result.params["S"]) >= job.settings.threshold)
        best = best_member(refined) if refined else None
        extras["refine_curve_costs"] = selection_costs(refined)
        if best is None:
            return None, "every refinement run diverged", extras
        result = refined[best]
    return result, None, extras


def _finish(job: _Job, first, chosen, refined, seconds) -> Design:
    if job.start is not None:
        return _finish_warm(job, first, chosen, refined, seconds)
    method = _method_name(job)
    result, failure, extras = _trained(job, first, chosen, refined)
    if result is None:
        return Design.failure(method, job.params, DIVERGED, failure, info_model="delayed", seconds=seconds,
                              extras=extras)
    extras["curve"] = curve(result)
    return _scored(job, method, _controller(job, result.params), seconds, extras, diverged_members_message(first))


def _controller(job: _Job, params: dict, *, linear: bool | None = None):
    """The controller of trained (or start) parameters S, F, W, G; ``linear`` defaults to the activation's."""
    nodes = {} if job.instance.scalar_nodes else dict(state_nodes=job.instance.state_nodes,
                                                       input_nodes=job.instance.input_nodes)
    linear = job.settings.activation == "identity" if linear is None else linear
    kind = LinearGRNNController if linear else GRNNController
    return kind(**{k: params[k] for k in ("S", "F", "W", "G")}, **nodes)


def _compared_cost(job: _Job, controller) -> float:
    """The cost a warm start and its trained model are compared by: exact (identity activation), or the
    mean normalized cost on the selection set (the draws that pick ensemble members), inf if unbounded."""
    if job.settings.activation == "identity":
        cost = exact_cost(job.instance, controller)
        return float(cost) if np.isfinite(cost) else float("inf")
    from ..evaluation import simulate

    rollout = simulate(job.instance, controller, selection_set(job.instance, job.settings.curve_size))
    return float(rollout.plain_cost) if rollout.bounded and np.isfinite(rollout.plain_cost) else float("inf")


def _finish_warm(job: _Job, first, chosen, refined, seconds) -> Design:
    """A run with ``init`` set: trained as any run, then the start kept where training made it worse.

    The trained model and the start (the embedded design, the closed loop every member
    starts from) are compared by :func:`_compared_cost`; the start is kept where the
    trained model costs more, where training diverged, and where the trained model
    diverges when scored (on draws beyond the selection set). A start that fell back to
    the random draw has nothing to keep: the run is an ordinary one, its fallback noted.
    """
    start = job.start
    method = _method_name(job)
    result, failure, extras = _trained(job, first, chosen, refined)
    extras.update(start.extras)
    notes = [extras["init_note"]] if "init_note" in extras else []
    members = [diverged_members_message(first)] if diverged_members_message(first) else []
    trained = _controller(job, result.params) if result is not None else None
    if not start.warm:  # fell back to the random draw: an ordinary run
        if trained is None:
            return Design.failure(method, job.params, DIVERGED, "; ".join([failure] + notes), info_model="delayed",
                                  seconds=seconds, extras=extras)
        extras["curve"] = curve(result)
        design = _scored(job, method, trained, seconds, extras, "; ".join(notes + members))
        chain = "; ".join(notes)
        if design.status == DIVERGED and chain not in design.message:  # a simulated failure says the rollout's only
            design = dataclasses.replace(design, message="; ".join([design.message, chain]))
        return design

    # The embedded design itself: every member starts at its closed loop (what they add is unread).
    start_params = dict(S=start.S, F=start.F, W=start.W, G=start.G)
    start_controller = _controller(job, start_params)
    start_cost = _compared_cost(job, start_controller)
    extras["init_cost"] = start_cost
    extras["init_tanh_gap"] = 0.0
    if job.settings.activation == "tanh":  # the start against its linear twin (the embedded design) on the same draws
        twin = _compared_cost(job, _controller(job, start_params, linear=True))
        extras["init_tanh_gap"] = float((start_cost - twin) / twin) if np.isfinite(twin) and twin else float("nan")
    trained_cost = _compared_cost(job, trained) if trained is not None else float("nan")
    kept = trained is None or not trained_cost <= start_cost
    extras["trained_cost"] = trained_cost
    extras["kept_start"] = bool(kept)
    extras["curve"] = curve(result) if result is not None else {"step": [], "cost": []}
    measure = "exact cost" if job.settings.activation == "identity" else "selection-set cost"
    if not kept:
        head = f"warm start from {start.label}: {measure} {start_cost:.6g} -> {trained_cost:.6g}"
        design = _scored(job, method, trained, seconds, dict(extras), "; ".join([head] + notes + members))
        if design.status != DIVERGED:
            return design
        # The trained model diverged where it was scored (draws beyond the selection set's): the start instead.
        failure = f"the trained model diverged when scored ({design.message})"
        extras["kept_start"] = True
    why = failure or f"training ended at {trained_cost:.6g}, above the start"
    head = f"warm start from {start.label} kept ({measure} {start_cost:.6g}): {why}"
    return _scored(job, method, start_controller, seconds, extras, "; ".join([head] + notes + members))


def _scored(job: _Job, method: str, controller, seconds, extras, message: str) -> Design:
    """A GRNN design scored as :func:`_finish` scores it (exact when linear, else simulated), with ``message``."""
    links, self_loops = count_links(controller.S)
    extras["spectral_radius"] = spectral_radius(
        controller.linearized_closed_loop(job.instance, sparse=job.instance.n > STRUCTURED_ABOVE))
    if job.settings.activation != "identity":
        return simulated_design(job.instance, controller, method=method, params=job.params, info_model="delayed",
                                links=links, self_loops=self_loops, seconds=seconds, extras=extras,
                                stability_steps=job.settings.stability_steps,
                                stability_size=job.settings.stability_size, message=message)
    cost = exact_cost(job.instance, controller)
    extras["bounded"] = bool(extras["spectral_radius"] < 1.0)
    if not np.isfinite(cost):
        return Design.failure(method, job.params, DIVERGED, "; ".join(
            ["the linear GRNN's exact cost is not finite"] + ([message] if message else [])), info_model="delayed",
            seconds=seconds, links=links, self_loops=self_loops, extras=extras)
    return Design(method=method, params=job.params, controller=controller, cost=cost, links=links,
                  self_loops=self_loops, info_model="delayed", status=OPTIMAL, message=message, seconds=seconds,
                  cost_stderr=0.0, cost_kind="exact", extras=extras)


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
