"""Refit: the best controller of one class on a given communication graph.

Every co-design picks a graph and fits a controller on it. A refit keeps the graph
and fits the controller again, with the best search the toolkit has for each class,
so that a report can say which part of a design's cost is its graph and which its
controller (docs/methods.md, "Refit on a graph"). The classes, by information model:

- ``delayed``: the delayed static gain ``u = K_l x(t) + K_d x(t-1)``, K_d on the
  graph's links, each node's own block local (:func:`baselines.sparse_delayed.polish_delayed`
  from the caller's starts and the diagonal gain, every one polished and the lowest
  stabilizing minimum kept; the stabilizing search's local starts only where none of
  those stabilizes);
- ``instantaneous``: the static gain ``u = K x`` on the graph's links (the same
  search on :func:`baselines.polish_gain`);
- ``sls``: SLS with the graph as its communication graph at one hop per step
  (:func:`baselines.sls`): where the delay constraints are quadratically invariant,
  the best linear controller with that information (``extras["qi"]``); otherwise a
  restriction of it, and the message says so. Where two steps after a disturbance
  the plant has carried it to a node the graph does not link, and no local input can
  cancel that, the constraints cannot be met (``infeasible``, found without solving:
  the plant spreads the disturbance faster than the graph carries news of it);
- ``grnn``: the GRNN with a per-node readout, S held to the graph's support, started
  from the ``delayed`` refit by the exact embedding and kept only where training
  ends below that start (:func:`baselines.grnn` with ``variant = "given"``,
  ``init = "delayed"``); tanh or linear (``activation``).

The graph's value V(G) is the lowest refit cost on G in one information model; a
report takes it over the classes (:mod:`compare.report.graph_gaps`).
"""

from __future__ import annotations

import inspect
from dataclasses import replace
from typing import Annotated, Literal

import numpy as np

from codesign.design import Design, Timer
from codesign.graphs import GRAPH_PATTERN, graph_hash, graph_links, graph_text, parse_graph
from codesign.methods import AtLeast, Matches, method
from codesign.status import INFEASIBLE

from ._sparse import DecentralizedCache, gain_design, pattern_starts
from .grnn import grnn_batch
from .sls import sls
from .sparse_delayed import DelayedStaticGain, Nodes, delayed_gain_design, stabilizing_delayed
from .stabilizing import stabilizing_gain

__all__ = ["refit", "refit_design", "CONTROLLERS", "INFO_MODELS"]

#: The controller classes a graph is refit with, and the information model of each.
INFO_MODELS = {"delayed": "delayed", "instantaneous": "instantaneous", "sls": "delayed", "grnn": "delayed"}
CONTROLLERS = tuple(INFO_MODELS)

METHOD = "refit"


def _gains(design, instance):
    """(K_local, K_delayed) of a design's static gain as a start of the delayed search, or None."""
    controller = getattr(design, "controller", None)
    if isinstance(controller, DelayedStaticGain):
        return np.asarray(controller.K_local, float), np.asarray(controller.K_delayed, float)
    K = getattr(controller, "K", None)
    if K is None or np.shape(K) != (instance.m, instance.n):
        return None
    own = instance.block_mask()
    return np.where(own, K, 0.0), np.where(own, 0.0, K)  # the instantaneous links, one step late


def _static_gain(design, instance):
    """K of a design's instantaneous static gain as a start, or None."""
    K = getattr(getattr(design, "controller", None), "K", None)
    return None if K is None or np.shape(K) != (instance.m, instance.n) else np.asarray(K, float)


def _named(starts) -> list:
    return [(f"start {k}" if getattr(d, "method", None) is None else f"{d.method} start", d)
            for k, d in enumerate(starts)]


def _delayed(instance, adj, params, starts) -> Design:
    free = instance.expand_blocks(adj) & ~instance.block_mask()
    decentral = DecentralizedCache(instance)
    given = [(name, g) for name, d in _named(starts) if (g := _gains(d, instance)) is not None]
    zero = np.zeros((instance.m, instance.n))
    with Timer() as timer:
        diagonal = decentral.usable() if not given else None
        first = given[0][1] if given else (zero if diagonal is None else np.array(diagonal.controller.K), zero)
        found = stabilizing_delayed(instance, *first, free, decentral=decentral, starts=given[1:], exhaustive=True)
    local, K_delayed = found.gain
    extras = {"solver": "polish_delayed", "search_start": found.start, "search_starts": found.tried,
              "polish_message": found.result.message}
    design = delayed_gain_design(instance, params, Nodes(instance).local(local), K_delayed, extras=extras,
                                 free=free, seconds=timer.seconds)
    return replace(design, method=METHOD, params=dict(params))


def _instantaneous(instance, adj, params, starts) -> Design:
    mask = instance.expand_blocks(adj) | instance.block_mask()
    decentral = DecentralizedCache(instance)
    given = [(name, K) for name, d in _named(starts) if (K := _static_gain(d, instance)) is not None]
    with Timer() as timer:
        # Every caller's start and the diagonal gain polished, the lowest stabilizing minimum kept; the
        # search's local starts only where none of those stabilizes (as the delayed refit does).
        first = given + pattern_starts(decentral)
        found = stabilizing_gain(instance, mask, first, exhaustive=True, local=False) if first else None
        if found is None or not found.stable:
            more = stabilizing_gain(instance, mask, [], local=True)
            found = more if found is None or more.stable or more.radius < found.radius else found
    result = found.result
    extras = {"solver": "polish_gain", "grad_norm": result.grad_norm, "polish_iterations": result.iterations,
              "polish_message": result.message, "search_start": found.start, "search_starts": found.tried}
    return gain_design(instance, METHOD, params, result.K, seconds=timer.seconds, extras=extras, polished=True)


def _unreachable(instance, adj) -> tuple | None:
    """A (node i, node j) pair that proves no SLS at one hop per step exists on the graph, or None.

    Two steps after a disturbance at node j, the state response is Φx[2] = A + B Φu[1], and
    it may reach only one hop of the graph, while Φu[1] is local (act_delay 1: node j's
    own inputs). So for every state s of node j, A[r, s] + B[r, inputs of j] Φu[1][:, s]
    must vanish on the states r of every node i the graph does not link to j; where no
    Φu[1] does that (least squares leaves a residual), the QP is infeasible.
    """
    off = (~adj) & ~np.eye(instance.nodes, dtype=bool)
    A, B = instance.A, instance.B
    scale = max(float(np.abs(A).max()), float(np.abs(B).max()), 1.0)
    for s in range(instance.n):
        j = int(instance.state_nodes[s])
        rows = np.isin(instance.state_nodes, np.flatnonzero(off[:, j]))
        if not rows.any():
            continue
        inputs = instance.input_nodes == j
        target = -A[rows, s]
        if inputs.any():
            coef = B[np.ix_(rows, inputs)]
            fit, *_ = np.linalg.lstsq(coef, target, rcond=None)
            target = target - coef @ fit
        worst = int(np.argmax(np.abs(target)))
        if abs(target[worst]) > 1e-9 * scale:
            return int(instance.state_nodes[np.flatnonzero(rows)[worst]]), j
    return None


def _sls(instance, adj, params) -> Design:
    pair = _unreachable(instance, adj)
    if pair is not None:
        i, j = pair
        return Design.failure(METHOD, params, INFEASIBLE, f"no SLS at one hop per step on this graph: node {i} "
                              f"feels a disturbance at node {j} two steps later, which no local input of node {j} "
                              f"cancels, and the graph has no link {i}-{j} to carry that news in time (known "
                              "without solving)", info_model="delayed", links=int(adj.sum()),
                              extras={"qi": False, "solved": False, "unreachable": [i, j]})
    design = sls(instance, comm_adj=adj, speed=1.0, act_delay=1)
    message = design.message
    if design.ok and not design.extras.get("qi", False):
        message = "; ".join(filter(None, ["the delay constraints on this graph are not quadratically invariant: "
                                          "a restriction, not the best linear controller with this information",
                                          message]))
    return replace(design, method=METHOD, params=dict(params), message=message)


def _grnn_job(instance, adj, params, starts, settings: dict):
    """(the GRNN's start: the delayed refit, and its grnn_batch job), or (the start's failure, None)."""
    start = _delayed(instance, adj, {**params, "controller": "delayed"}, starts)
    if not start.ok:
        return Design.failure(METHOD, params, start.status, "no stabilizing delayed gain on the graph to start the "
                              f"GRNN from ({start.message})", info_model="delayed", seconds=start.seconds,
                              links=start.links, self_loops=start.self_loops, extras=start.extras), None
    # The GRNN's "given" graph is the refit's (self-loops included): S trains on its support only.
    on_graph = replace(instance, comm_adj=(adj | np.eye(instance.nodes, dtype=bool)).astype(float))
    return start, (on_graph, {"variant": "given", "readout": "per_node", "init": "delayed", "start": start,
                              **settings})


def _train_grnns(jobs) -> list:
    """:func:`baselines.grnn.grnn_batch` on (instance, settings) jobs of the ``given`` variant."""
    return grnn_batch([(instance, {k: v for k, v in settings.items() if k != "variant"}) for instance, settings in jobs])


def _grnn_design(trained: Design, start: Design, params: dict) -> Design:
    extras = {**trained.extras, "start_cost": start.cost, "start_links": start.links}
    return replace(trained, method=METHOD, params=dict(params), seconds=trained.seconds + start.seconds,
                   extras=extras)


def _grnn(instance, adj, params, starts, settings: dict) -> Design:
    start, job = _grnn_job(instance, adj, params, starts, settings)
    return start if job is None else _grnn_design(_train_grnns([job])[0], start, params)


def refit_design(instance, graph, controller: str = "delayed", *, starts=(), activation: str = "tanh",
                 seed: int = 0, **grnn_settings) -> Design:
    """The best controller of class ``controller`` on ``graph`` (see the module docstring).

    Parameters
    ----------
    instance : Instance
    graph : array_like of bool, shape (N, N), or str
        The communication graph: ``graph[i, j]`` nonzero means node i reads node j
        (the diagonal is ignored: a node's own state needs no link), or its
        :func:`codesign.graphs.graph_text`.
    controller : {"delayed", "instantaneous", "sls", "grnn"}
    starts : sequence of Design
        Designs whose gains start the static searches, tried first (a source design's
        own gain: then the refit costs no more than it wherever that gain stabilizes).
        Static gains and delayed static gains are used; other controllers are skipped.
    activation : {"tanh", "identity"}
        The GRNN's (``controller = "grnn"`` only).
    seed : int
        The GRNN's training seed (``controller = "grnn"`` only).
    **grnn_settings
        Training settings of :func:`baselines.grnn` (``steps``, ``lr``, ...).

    Returns
    -------
    Design
        With ``extras["graph"]`` (the graph's hash), ``extras["graph_links"]`` and
        ``extras["controller_class"]``; a graph no controller of the class
        stabilizes is a recorded status (``diverged``, ``infeasible``), never an
        exception.
    """
    adj, params = _checked(instance, graph, controller)
    if controller == "grnn":
        params.update(activation=activation, seed=int(seed), **grnn_settings)
        design = _grnn(instance, adj, params, starts, {"activation": activation, "seed": int(seed),
                                                        **grnn_settings})
    elif grnn_settings or activation != "tanh" or seed != 0:
        raise ValueError(f"activation, seed and training settings apply to controller 'grnn' only, "
                         f"not {controller!r}")
    elif controller == "delayed":
        design = _delayed(instance, adj, params, starts)
    elif controller == "instantaneous":
        design = _instantaneous(instance, adj, params, starts)
    else:
        design = _sls(instance, adj, params)
    return _stamped(design, adj, controller)


def _checked(instance, graph, controller: str) -> tuple:
    """(the graph as an (N, N) bool adjacency without self-loops, the refit's params); ValueError naming the problem."""
    if controller not in INFO_MODELS:
        raise ValueError(f"controller must be one of {CONTROLLERS}, got {controller!r}")
    adj = parse_graph(graph, instance.nodes) if isinstance(graph, str) else np.asarray(graph) != 0
    if adj.shape != (instance.nodes, instance.nodes):
        raise ValueError(f"graph must have shape {(instance.nodes, instance.nodes)} (one row per node), "
                         f"got {adj.shape}")
    adj = adj & ~np.eye(instance.nodes, dtype=bool)
    return adj, {"graph": graph_text(adj), "controller": controller}


def _stamped(design: Design, adj, controller: str) -> Design:
    extras = {**design.extras, "graph": graph_hash(adj), "graph_links": graph_links(adj),
              "controller_class": controller}
    return replace(design, extras=extras)


def _refit_batch(pairs) -> list:
    """The registered method's batch: the GRNN refits of a batch train together (one grnn_batch), the rest alone."""

    out, jobs = [None] * len(pairs), []
    for k, (instance, params) in enumerate(pairs):
        params = {**_DEFAULTS, "graph": "", "controller": "delayed", **params}
        if params["controller"] != "grnn":
            out[k] = refit(instance, **params)
            continue
        adj, base = _checked(instance, params["graph"], "grnn")
        settings = {key: params[key] for key in ("activation", "seed", "steps", "ensemble", "lr", "dtype")}
        base.update(settings)
        start, job = _grnn_job(instance, adj, base, (), settings)
        if job is None:
            out[k] = _stamped(start, adj, "grnn")
        else:
            jobs.append((k, adj, base, start, job))
    trained = _train_grnns([job for *_, job in jobs]) if jobs else []
    for (k, adj, base, start, _), design in zip(jobs, trained):
        out[k] = _stamped(_grnn_design(design, start, base), adj, "grnn")
    return out


@method(METHOD, label="Refit on a graph", node_blocks=True, max_states=200, batch=_refit_batch,
        batch_size=25,
        max_states_reason="the delayed and static searches polish every start on dense finite-horizon costs "
                          "(as sparse_delayed, whose path takes about an hour at 500 states)")
def refit(
    instance,
    *,
    graph: Annotated[str, Matches(GRAPH_PATTERN, "comma-separated 'i-j' pairs, node i reads node j")] = "",
    controller: Literal["delayed", "instantaneous", "sls", "grnn"] = "delayed",
    activation: Literal["tanh", "identity"] = "tanh",
    steps: Annotated[int, AtLeast(1)] = 150,
    ensemble: Annotated[int, AtLeast(1)] = 3,
    lr: Annotated[float, AtLeast(0)] = 0.03,
    dtype: Literal["float64", "float32"] = "float32",
    seed: Annotated[int, AtLeast(0)] = 0,
) -> Design:
    """The best controller of one class on a given graph (a co-design's graph, refit).

    Parameters
    ----------
    graph : str
        The communication graph as ``"i-j,..."`` (node i reads node j); in a spec,
        set by the harness from a source design's graph (``sources``).
    controller : {"delayed", "instantaneous", "sls", "grnn"}
        The class refit on the graph: delayed static gain, instantaneous static gain,
        SLS at one hop per step, or the warm-started per-node GRNN.
    activation : {"tanh", "identity"}
        The GRNN's activation (``controller = "grnn"``).
    steps : int
        The GRNN's training steps.
    ensemble : int
        The GRNN's ensemble members.
    lr : float
        The GRNN's learning rate.
    dtype : {"float64", "float32"}
        The GRNN's training precision.
    seed : int
        The GRNN's training seed.
    """
    if controller != "grnn":
        settings = {"activation": activation, "steps": steps, "ensemble": ensemble, "lr": lr, "dtype": dtype,
                    "seed": seed}
        changed = [k for k, v in settings.items() if v != _DEFAULTS[k]]
        if changed:
            raise ValueError(f"{', '.join(changed)} apply to controller 'grnn' only, not {controller!r}")
        return refit_design(instance, graph, controller)
    return refit_design(instance, graph, "grnn", activation=activation, seed=seed, steps=steps,
                        ensemble=ensemble, lr=lr, dtype=dtype)


#: The registered method's GRNN settings and their defaults, read from its signature (one table of defaults).
_DEFAULTS = {name: p.default for name, p in inspect.signature(refit).parameters.items()
             if p.kind is p.KEYWORD_ONLY and name not in ("graph", "controller")}
