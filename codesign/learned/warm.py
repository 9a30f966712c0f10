"""Warm starts of the GRNN (``init`` setting): a static design embedded as the model's first parameters.

``init = "diagonal"`` starts from the best diagonal static gain on the run's instance,
``init = "delayed"`` from a delayed static gain, both embedded exactly by
:func:`codesign.learned.embed_delayed_gain` into a GRNN with a per-node readout
(docs/methods.md, "Warm starts"). The static designs are the method layer's
(``baselines.decentralized``, ``baselines.sparse_delayed``): they reach the trainer
through a :class:`StartSources` the caller passes (``baselines.grnn`` passes its
``StartCache``), so that this package imports nothing of that layer. Which delayed
design, by variant:

- ``sparse``: the delayed ℓ1 path run on the grid (0, γ) with γ = β / trace(P), the
  run's own ℓ1 weight in the path's units (the GRNN's loss is the raw cost, mean over
  draws x(0) ~ N(0, I), plus β Σ|S_ij|; the path's objective is the cost divided by
  trace(P) plus γ Σ w_ij |K_d,ij|, and the embedding has S = K_d);
- ``dense``: the path's dense end (γ = 0, every link free);
- ``given``: the delayed gain polished on the given graph's links (the path's polish
  and stabilizing search, from the diagonal gain), the best delayed gain with the
  GRNN's own links;
- ``fixed``: refused (S is frozen at the normalized adjacency, which no delayed gain's
  weights are in general).

A source that is not usable (no stabilizing gain) or that no GRNN holds (node blocks
whose delayed blocks are not multiples of one matrix) falls back to the diagonal gain,
and a missing stabilizing diagonal gain to the random initialization; each fallback
is recorded (``extras["init_note"]``) and said in the design's message.

Every ensemble member starts at the same closed loop, the embedded design's. The
hidden features the embedding leaves unused (h > 2p) get the member's own random
draw in F and in W's columns into them, with W's rows out of them and G on them zero:
they are computed but not read, so the start's inputs u(t) are unchanged, while
their gradients are not zero (with all-zero extra features they would be a saddle
that training never leaves). With the diagonal gain the relay features (S's) are not
read either (G's relay rows zero) and S starts where the variant's random start puts
it (the normalized adjacency, or the row-stochastic draw), so that S trains from the
first step; with a delayed gain S starts at its delayed weights.

With tanh the embedding's ε is ``init_scale`` / σ, σ >= 1 the largest standard deviation of
any state along the design's closed loop from x(0) ~ N(0, I) (:func:`state_std`), so that
tanh's inputs stay in its near-linear range on plants of any scale; the run's learning rates
are divided by σ too (Adam moves each parameter by about ``lr`` per step, and F is σ times
smaller). Sources are computed once per instance (and γ) in a batch (the caller's
:class:`StartSources` caches them).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..instances import node_width

__all__ = ["INITS", "WARM_INITS", "AUTO_RADIUS", "Start", "StartSources", "build_start", "member_start",
           "usable_source",
           "check_warm_settings", "delayed_gamma", "state_std"]

#: The GRNN's initializations: the paper's random draw, a static design embedded (warm start), or
#: "auto": the diagonal gain where the plant's open-loop spectral radius exceeds :data:`AUTO_RADIUS`.
INITS = ("random", "diagonal", "delayed", "auto")
#: The warm starts among them.
WARM_INITS = ("diagonal", "delayed", "auto")
#: ``init = "auto"`` starts from the diagonal gain above this open-loop spectral radius, else draws at random.
#: Measured (benchmarks/bench_stable_start.py, paper family, 4 instances, GRNN 300 steps and GRNN-Sparse 150):
#: from the random draw the designs were usable at radius 1.2 (median cost 2.6 and 1.26) and not from 1.25 on
#: (499 and 6.4 at 1.25, 1.8e5 and 5279 at 1.3, 8 of 8 diverged at 1.6 and 1.8 and on the random network,
#: 1.76-1.87), where the diagonal start gave 1.61 and 1.30 at 1.25 and no divergence anywhere.
AUTO_RADIUS = 1.22

_LABELS = {"diagonal": "the diagonal gain", "delayed": "a delayed gain"}


def delayed_gamma(instance, beta: float) -> float:
    """The delayed path's γ for a GRNN-Sparse run with ℓ1 weight ``beta``: β / trace(P) (same units)."""
    return float(beta) / instance.trace_P


def check_warm_settings(settings, variant: str, instance=None) -> None:
    """One-line ValueError for a warm start the run cannot take, before any training.

    Parameters
    ----------
    settings : GRNNSettings
    variant : str
        The GRNN variant (``"given"``, ``"dense"``, ``"fixed"``, ``"sparse"``).
    instance : Instance, optional
        None checks the settings alone (what a spec can be refused for when it is loaded,
        before any instance exists); with the instance, also ``hidden`` against its
        states per node.
    """
    init = settings.init
    if init == "random":
        if settings.init_scale != type(settings).init_scale:
            raise ValueError(f"init_scale applies to warm starts only (init in {WARM_INITS}), got init 'random'")
        return
    if settings.readout != "per_node":
        raise ValueError(f"init {init!r} needs readout 'per_node': a shared readout gives every node the same "
                         f"local gain F G, so it cannot hold a node-specific static gain")
    if init == "delayed" and variant == "fixed":
        raise ValueError("init 'delayed' does not apply to variant 'fixed' (S is frozen at the normalized "
                         "adjacency); use init 'diagonal'")
    if init == "delayed" and variant == "sparse" and settings.l1_hops is not None:
        raise ValueError("init 'delayed' needs l1_hops None: the delayed path's links are not limited to "
                         "the l1 stage's hops")
    if instance is None:
        return
    p = node_width(instance.state_nodes)
    if settings.hidden < 2 * p:
        raise ValueError(f"init {init!r} needs hidden >= {2 * p} (2 features per state of a node, "
                         f"{p} states per node), got hidden={settings.hidden}")


@dataclass
class Start:
    """A warm start: the embedded design's parameters and what it came from.

    ``S`` is the embedded S (zero for the diagonal gain), ``F``, ``W``, ``G`` the
    embedded F (h,) or (p, h), W (h, h) and per-node G (N, h) or (N, h, q) at the
    run's hidden size and scale; ``relay`` whether G reads the relay features
    (a delayed gain with links). ``init`` is what was used ("diagonal", "delayed",
    or "random" after a fallback), ``extras`` what the design records about it.
    """

    init: str
    S: np.ndarray | None = None
    F: np.ndarray | None = None
    W: np.ndarray | None = None
    G: np.ndarray | None = None
    relay: bool = False
    source: object = None
    extras: dict = field(default_factory=dict)

    @property
    def warm(self) -> bool:
        return self.init != "random"

    @property
    def lr_factor(self) -> float:
        """What the run's learning rates are multiplied by: 1 / the start's state scale (``init_lr_factor``)."""
        return float(self.extras.get("init_lr_factor", 1.0))

    @property
    def label(self) -> str:
        """How the message names the start ("the diagonal gain", "the delayed gain (12 links)")."""
        if self.init == "delayed":
            return f"the delayed gain ({self.extras.get('init_links', '?')} links)"
        return _LABELS.get(self.init, "the random initialization")


def usable_source(design) -> bool:
    """Whether a static design can start a GRNN: usable, with a controller, and a stable closed loop."""
    from ..status import USABLE, is_stable

    return (design is not None and design.status in USABLE and design.controller is not None
            and is_stable(design.extras.get("spectral_radius", np.inf)))


class StartSources:
    """Where a warm start's static designs come from: the method layer's designs, by the caller.

    A subclass answers the three questions a warm start asks of an instance; each returns a
    :class:`~codesign.design.Design` (a static controller with ``extras["spectral_radius"]``)
    or None. ``baselines.grnn.StartCache`` is the one the toolkit uses: the decentralized
    gain, the delayed l1 path and the delayed gain polished on the given graph, each
    computed once per instance in a batch.
    """

    def diagonal(self, instance):
        """The best diagonal (decentralized) static gain."""
        raise NotImplementedError

    def delayed_path(self, instance, gamma: float | None):
        """The delayed l1 path's design at ``gamma`` (run on the grid (0, γ)), or its dense end (None or 0)."""
        raise NotImplementedError

    def delayed_given(self, instance):
        """The delayed gain polished on the given graph's links, from the diagonal gain (None if it has none)."""
        raise NotImplementedError


def _source(sources: StartSources | None, instance, init: str, variant: str, beta):
    """(design, source name, extras) of the design a warm start embeds (before any fallback)."""
    if sources is None:
        raise ValueError(f"init {init!r} starts from a design of the method layer, which this call was not given: "
                         f"call baselines.grnn (or baselines.grnn_batch), which computes it, or pass start= "
                         f"(a delayed static design, with init 'delayed')")
    if init == "diagonal":
        return sources.diagonal(instance), "decentralized", {}
    if variant == "sparse":
        gamma = delayed_gamma(instance, beta)
        return sources.delayed_path(instance, gamma), "sparse_delayed", {"init_gamma": gamma}
    if variant == "dense":
        return sources.delayed_path(instance, 0.0), "sparse_delayed", {"init_gamma": 0.0}
    return sources.delayed_given(instance), "sparse_delayed on the given graph", {}


def build_start(sources: StartSources | None, instance, settings, variant: str, beta, source=None) -> Start:
    """The run's :class:`Start`: its source design (from ``sources``) embedded.

    ``sources``: where the static designs come from (``baselines.grnn.StartCache``); None
    where the caller has none, and then a start that needs one is a one-line ValueError.
    ``source``: with ``init = "delayed"``, the delayed design to start from, given by the
    caller (a method of the method layer that found it, such as ``baselines.refit``)
    instead of the one the variant's rule computes.
    """
    from ..evaluation import exact_cost
    from .embedding import embed_delayed_gain

    init, notes = settings.init, []
    if init == "auto":
        radius = instance.open_loop_radius
        init = "diagonal" if radius > AUTO_RADIUS else "random"
        notes.append(f"init auto: open-loop spectral radius {radius:.4g} {'>' if init == 'diagonal' else '<='} "
                     f"{AUTO_RADIUS:g}, so {_LABELS.get(init, 'the random initialization')}")
    while init != "random":
        if source is not None and init == "delayed":
            design, name, extras = source, "the given delayed design", {}
        else:
            design, name, extras = _source(sources, instance, init, variant, beta)
        if not usable_source(design):
            why = (getattr(design, "message", "") or getattr(design, "status", "")) if design is not None else ""
            reason = f"{name} gave no usable design" + (f" ({why})" if why else "")
        else:
            try:
                embedded = embed_delayed_gain(design, instance=instance, activation="identity",
                                              hidden=settings.hidden)
            except ValueError as error:
                reason = f"no GRNN holds {name}'s design ({error})"
            else:
                # ε = init_scale / the largest standard deviation of a state along the design's closed loop
                # (x(0) ~ N(0, I), so at least 1): tanh's inputs ε x_i(t) then stay within init_scale's range.
                std = state_std(instance, embedded)
                epsilon = settings.init_scale / std
                embedded = embed_delayed_gain(design, instance=instance, scale=epsilon, activation="identity",
                                              hidden=settings.hidden)
                arrays = embedded.arrays()
                source_cost = float(exact_cost(instance, design.controller))
                extras.update(init=init, init_source=name, init_source_cost=source_cost,
                              init_links=int(design.links), init_state_std=std, init_epsilon=epsilon,
                              init_lr_factor=1.0 / std)
                if notes:
                    extras["init_note"] = "; ".join(notes)
                relay = bool(np.any(arrays["S"]))
                return Start(init, S=arrays["S"], F=arrays["F"], W=arrays["W"], G=arrays["G"], relay=relay,
                             source=design, extras=extras)
        fallback = "diagonal" if init == "delayed" else "random"
        notes.append(f"{reason}, so {_LABELS.get(fallback, 'the random initialization')}")
        init = fallback
    return Start("random", extras={"init": "random", "init_note": "; ".join(notes)} if notes else {"init": "random"})


def state_std(instance, controller) -> float:
    """The largest standard deviation of any state x_i(t), t <= horizon, in closed loop from x(0) ~ N(0, I)."""
    from ..evaluation import impulse_responses

    phi_x, _ = impulse_responses(instance, controller)
    return float(np.sqrt(np.max(np.sum(phi_x * phi_x, axis=2))))


def member_start(start: Start, F_rand, W_rand, S_variant, states: int) -> tuple:
    """(S0, F0, W0, G0) of one ensemble member warm-started at ``start``.

    ``F_rand``, ``W_rand``: the member's random draw (:func:`init_fwg`), used only on the
    hidden features the embedding leaves unused; ``S_variant``: where the variant's random
    start puts S, used when the start reads no relay feature; ``states``: p, states per node.
    """
    h = start.W.shape[0]
    active = 2 * states
    F = np.array(start.F, dtype=float).reshape(-1, h)
    W = np.array(start.W, dtype=float)
    G = np.array(start.G, dtype=float)
    F[:, active:] = np.asarray(F_rand, dtype=float).reshape(-1, h)[:, active:]
    W[:, active:] = np.asarray(W_rand, dtype=float)[:, active:]  # into the unread features; W[unread, :active] = 0
    if start.relay:
        S = np.array(start.S, dtype=float)
    else:
        S = np.array(S_variant, dtype=float)
        G[:, states:active] = 0.0  # the relay features, unread: S is free to start anywhere
    return S, F.reshape(np.shape(start.F)), W, G
