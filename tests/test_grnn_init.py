"""Warm starts of the GRNN (issue #50, item 3): ``init = "diagonal" | "delayed"`` with a per-node readout.

The start is a static design embedded exactly (codesign/learned/warm.py), the design computed by
the method layer (baselines/grnn.py: ``baselines.grnn`` is the trainer with its sources); every ensemble member
starts at its closed loop; the design is the start wherever training ended above it (the kept-start
rule); ``init = "random"`` (the default) changes no bit.
"""

from __future__ import annotations

import numpy as np
import pytest

from baselines import decentralized, grnn, grnn_batch, sparse_delayed
from baselines.grnn import StartCache
from codesign import exact_cost, paper_instance
from codesign.design import count_links
from codesign.learned.grnn import GRNNController, GRNNSettings, LinearGRNNController, _first_stage_specs, _parse
from codesign.learned.warm import build_start, delayed_gamma
from compare.run.families.mass_spring import mass_spring_instance

#: Short training: seconds per run at N = 8.
SHORT = dict(steps=15, ensemble=2, stability_steps=30, curve_size=20, batch=10)
WARM = dict(readout="per_node", init="diagonal")


@pytest.fixture(scope="module")
def small():
    return [paper_instance(seed, n=8, degree=3) for seed in range(3)]


def _member_controller(instance, spec, linear=True):
    S = np.where(spec.mask, spec.S0, 0.0) if spec.mask.any() else spec.S0  # as the stack masks it
    nodes = {} if instance.scalar_nodes else dict(state_nodes=instance.state_nodes, input_nodes=instance.input_nodes)
    kind = LinearGRNNController if linear else GRNNController
    return kind(S, spec.F0.reshape(-1, spec.W0.shape[0]) if not instance.scalar_nodes else spec.F0, spec.W0,
                spec.G0, **nodes)


@pytest.mark.parametrize("variant", ["given", "fixed", "dense", "sparse"])
def test_every_member_starts_at_the_diagonal_gain_exactly(small, variant):
    """Zero training steps: the parameters the trainer starts from are the diagonal gain's closed loop,
    to rounding, for every member (their own draws sit only on features nothing reads)."""
    inst = small[0]
    diagonal = decentralized(inst)
    kwargs = dict(variant=variant, **WARM, activation="identity", ensemble=3, hidden=5)
    if variant == "sparse":
        kwargs["beta"] = 0.1
    job = _parse(inst, kwargs)
    job.start = build_start(StartCache(), inst, job.settings, job.variant, job.beta)
    specs = _first_stage_specs(job)
    costs = [exact_cost(inst, _member_controller(inst, spec)) for spec in specs]
    np.testing.assert_allclose(costs, diagonal.cost, rtol=1e-12, atol=0)
    assert len({spec.F0.tobytes() for spec in specs}) == 3  # the members differ (on the unread features)
    start = job.start
    clean = LinearGRNNController(start.S, start.F, start.W, start.G)
    assert exact_cost(inst, clean) == pytest.approx(diagonal.cost, rel=1e-13)
    assert count_links(clean.S) == (0, 0)


def test_identity_run_that_keeps_the_start_costs_exactly_the_diagonal_gain(small):
    """Training made worse (a learning rate of 50 throws the model off): the design is the diagonal gain, exactly."""
    inst = small[1]
    diagonal = decentralized(inst)
    design = grnn(inst, **WARM, activation="identity", lr=50.0, clip=0.0, **SHORT)
    assert design.status == "optimal", design.message
    assert design.extras["kept_start"] is True
    assert design.cost == diagonal.cost or abs(design.cost - diagonal.cost) <= 1e-13 * diagonal.cost
    assert design.extras["init_cost"] == pytest.approx(diagonal.cost, rel=1e-13)
    assert not design.extras["trained_cost"] <= design.extras["init_cost"]
    assert design.links == 0 and design.extras["init_links"] == 0
    assert design.message.startswith("warm start from the diagonal gain kept (exact cost ")
    assert design.extras["init"] == "diagonal" and design.extras["init_source"] == "decentralized"
    assert design.params["init"] == "diagonal" and design.params["readout"] == "per_node"


def test_a_trained_start_records_that_it_was_not_kept(small):
    inst = small[0]
    design = grnn(inst, **WARM, activation="identity", **SHORT)
    assert design.status == "optimal"
    if not design.extras["kept_start"]:
        assert design.extras["trained_cost"] <= design.extras["init_cost"]
        assert design.cost == pytest.approx(design.extras["trained_cost"], rel=1e-12)
        assert "kept" not in design.message and design.message.startswith("warm start from the diagonal gain: ")
    assert design.cost <= design.extras["init_cost"] * (1 + 1e-12)


@pytest.mark.parametrize("activation", ["identity", "tanh"])
def test_a_warm_started_grnn_sparse_is_never_worse_than_its_start(small, activation):
    """On the cost the start and the trained model are compared by: exact (identity), selection set (tanh)."""
    jobs = [(inst, dict(variant="sparse", beta=beta, **WARM, activation=activation, refine_ensemble=2, **SHORT))
            for inst in small for beta in (0.05, 1.0)]
    # and one whose training is thrown off (learning rates of 50): its start is kept
    jobs.append((small[0], dict(variant="sparse", beta=0.05, **WARM, activation=activation, lr=50.0, l1_lr=50.0,
                                clip=0.0, **SHORT)))
    designs = grnn_batch(jobs)
    assert designs[-1].extras["kept_start"] and not all(d.extras["kept_start"] for d in designs)
    from codesign.learned.grnn import _compared_cost

    for (inst, kwargs), design in zip(jobs, designs):
        assert design.status == "optimal", design.message
        extras = design.extras
        if activation == "identity":
            assert extras["init_cost"] == pytest.approx(extras["init_source_cost"], rel=1e-12)
        job = _parse(inst, {k: v for k, v in kwargs.items()})
        compared = _compared_cost(job, design.controller)
        assert compared <= extras["init_cost"] * (1 + 1e-12), (compared, extras["init_cost"])
        if extras["kept_start"]:
            assert "kept" in design.message and design.links == extras["init_links"]
        else:
            assert compared == pytest.approx(extras["trained_cost"], rel=1e-12)
        if activation == "tanh":
            assert abs(extras["init_tanh_gap"]) < 1e-2  # ε = 0.1 / the start's state scale: tanh nearly linear


def test_init_random_changes_no_bit():
    """The default, named or not: the same parameters, cost, curve and params (init not recorded)."""
    # The method-contract tests' shapes (T = 12, batch 20, curve 10): numba compiles a kernel per shape.
    inst = paper_instance(2, n=8, degree=3, horizon=12)
    short = dict(SHORT, batch=20, curve_size=10)
    for variant, extra in (("given", {}), ("sparse", {"beta": 0.2})):
        omitted = grnn(inst, variant=variant, **extra, **short)
        named = grnn(inst, variant=variant, init="random", **extra, **short)
        assert "init" not in omitted.params and named.params == omitted.params
        untimed = [{k: v for k, v in d.extras.items() if not k.endswith("seconds")} for d in (named, omitted)]
        assert named.cost == omitted.cost and untimed[0] == untimed[1] and named.message == omitted.message
        for key, value in omitted.controller.arrays().items():
            np.testing.assert_array_equal(named.controller.arrays()[key], value)


@pytest.mark.parametrize("kwargs, match", [
    (dict(init="warm"), r"init.*'random'.*'diagonal'.*'delayed'"),
    (dict(init="diagonal"), r"^init 'diagonal' needs readout 'per_node'"),
    (dict(init="delayed", readout="per_node", variant="fixed"), r"^init 'delayed' does not apply to variant 'fixed'"),
    (dict(init="delayed", readout="per_node", variant="sparse", beta=1.0, l1_hops=2), r"^init 'delayed' needs l1_hops"),
    (dict(init="diagonal", readout="per_node", hidden=1), r"^init 'diagonal' needs hidden >= 2"),
    (dict(init_scale=0.5), r"^init_scale applies to warm starts only"),
    (dict(init="diagonal", readout="per_node", init_scale=0.0), r"init_scale"),
])
def test_bad_init_settings_are_one_line_errors(small, kwargs, match):
    with pytest.raises(ValueError, match=match) as error:
        grnn(small[0], **{"steps": 1, **kwargs})
    assert "\n" not in str(error.value)


def test_the_delayed_start_by_variant(small):
    """sparse: the path's design at γ = β / trace(P); dense: its dense end; given: polished on the given graph."""
    inst = small[0]
    beta = 0.05
    gamma = delayed_gamma(inst, beta)
    path = sparse_delayed(inst, gammas=[0.0, gamma], diagonal_end=False)
    cache = StartCache()
    starts = {variant: build_start(cache, inst, GRNNSettings(**WARM | {"init": "delayed"}), variant, beta)
              for variant in ("sparse", "dense", "given")}
    assert starts["sparse"].extras["init_gamma"] == gamma
    for variant, design in (("sparse", path[1]), ("dense", path[0])):
        start = starts[variant]
        assert start.init == "delayed" and start.extras["init_links"] == design.links
        embedded = LinearGRNNController(start.S, start.F, start.W, start.G)
        assert exact_cost(inst, embedded) == pytest.approx(design.cost, rel=1e-10)
    given = starts["given"]
    outside = (given.S != 0) & (inst.comm_adj == 0)
    assert not outside.any() and given.extras["init_source_cost"] <= decentralized(inst).cost
    assert exact_cost(inst, LinearGRNNController(given.S, given.F, given.W, given.G)) == pytest.approx(
        given.extras["init_source_cost"], rel=1e-10)


def test_a_batch_computes_each_start_once_per_instance(small, monkeypatch):
    import importlib

    sources = importlib.import_module("baselines.grnn")  # where StartCache finds it (baselines.grnn the name is the function)
    calls = []
    real = sources.decentralized
    monkeypatch.setattr(sources, "decentralized", lambda inst, **kw: calls.append(inst.seed) or real(inst, **kw))
    jobs = [(inst, dict(variant=variant, seed=seed, **WARM, steps=2, ensemble=1, stability_steps=0, curve_size=10,
                        **({"beta": 0.1} if variant == "sparse" else {})))
            for inst in small[:2] for variant in ("given", "sparse") for seed in (0, 1)]
    designs = grnn_batch(jobs)
    assert sorted(calls) == [0, 1]
    assert all(d.extras["init"] == "diagonal" for d in designs)


def test_node_blocks_start_exactly_and_refuse_what_no_grnn_holds():
    """Mass-spring nodes (2 states, 1 input): the block-diagonal gain embeds (h >= 4); the dense delayed gain does
    not (its blocks are not multiples of one matrix per node), so "delayed" on GRNN-Dense falls back to it."""
    inst = mass_spring_instance(4)
    diagonal = decentralized(inst)
    settings = GRNNSettings(**WARM, activation="identity")
    start = build_start(StartCache(), inst, settings, "given", None)
    controller = LinearGRNNController(start.S, start.F, start.W, start.G, inst.state_nodes, inst.input_nodes)
    assert exact_cost(inst, controller) == pytest.approx(diagonal.cost, rel=1e-12)
    fallback = build_start(StartCache(), inst, GRNNSettings(**WARM | {"init": "delayed"}), "dense", None)
    assert fallback.init == "diagonal" and "no GRNN holds" in fallback.extras["init_note"]
    design = grnn(inst, variant="dense", **WARM | {"init": "delayed"}, **SHORT)
    assert design.status == "optimal" and "no GRNN holds" in design.message


def test_init_auto_starts_from_the_diagonal_gain_on_unstable_plants_only():
    """Above the measured open-loop spectral radius (AUTO_RADIUS = 1.22) the diagonal gain, at or below it the
    random draw, to the bit of a per-node run with the random draw; the message says which and why."""
    from codesign.learned.warm import AUTO_RADIUS

    stable, unstable = paper_instance(0, n=8, degree=3, a_norm=1.05), paper_instance(0, n=8, degree=3, a_norm=1.5)
    assert stable.open_loop_radius <= AUTO_RADIUS < unstable.open_loop_radius
    auto = dict(readout="per_node", init="auto", **SHORT)
    warm, cold = grnn_batch([(unstable, auto), (stable, auto)])
    assert warm.extras["init"] == "diagonal" and "init_cost" in warm.extras
    assert warm.message.startswith("warm start from the diagonal gain")
    assert "init auto: open-loop spectral radius 1.5 > 1.22, so the diagonal gain" in warm.message
    assert cold.extras["init"] == "random" and "kept_start" not in cold.extras
    assert cold.message.startswith("init auto: open-loop spectral radius 1.05 <= 1.22, so the random initialization")
    plain = grnn(stable, readout="per_node", **SHORT)
    assert cold.cost == plain.cost and cold.params == {**plain.params, "init": "auto"}
    for key, value in plain.controller.arrays().items():
        np.testing.assert_array_equal(cold.controller.arrays()[key], value)
    with pytest.raises(ValueError, match="^init 'auto' needs readout 'per_node'"):
        grnn(stable, init="auto", steps=1)


def test_reports_tell_readouts_and_warm_starts_apart():
    from compare.report.styles import METHOD_STYLES, kind_suffix, style_for, style_key

    paper = {"beta": 0.1}
    per_node = {**paper, "readout": "per_node"}
    warm = {**per_node, "init": "diagonal"}
    delayed = {**per_node, "init": "delayed", "activation": "identity"}
    keys = [style_key("grnn_sparse", p) for p in (paper, per_node, warm, delayed)]
    assert keys == ["grnn_sparse", "grnn_sparse_per_node", "grnn_sparse_per_node_warm_diagonal",
                    "grnn_sparse_linear_per_node_warm_delayed"]
    styles = [style_for("grnn_sparse", p) for p in (paper, per_node, warm, delayed)]
    assert len({(s.colour, s.marker) for s in styles}) == 4
    # each readout and start its own colour (they shared GRNN-Sparse's orange, and their bands fused), the linear
    # ones hollow; the built-in table holds them
    assert len({s.colour for s in styles}) == 4 and styles[0].colour == METHOD_STYLES["grnn_sparse"][0]
    assert styles[3].colour == METHOD_STYLES["grnn_sparse_linear_per_node_warm_delayed"][0] and styles[3].face == "none"
    assert {s.info_model for s in styles} == {"delayed"}
    assert [kind_suffix("grnn_sparse", p) for p in (paper, per_node, warm, delayed)] == [
        "", " (per-node)", " (per-node, warm: diagonal)", " (per-node, warm: delayed)"]
    assert kind_suffix("sparse_admm", per_node) == "" and style_key("sparse_admm", warm) == "sparse_admm"


def test_a_trained_model_that_diverges_when_scored_gives_way_to_its_start(small, monkeypatch):
    """Better than the start on the selection set, unbounded on the draws that score it: the start is the design."""
    import sys

    from codesign.design import Design

    grnn_module = sys.modules["codesign.learned.grnn"]  # the package's name "grnn" is the function

    real, calls = grnn_module.simulated_design, []

    def first_diverges(instance, controller, **kwargs):
        calls.append(controller)
        if len(calls) == 1:
            return Design.failure(kwargs["method"], kwargs["params"], "diverged", "an unbounded draw",
                                  info_model="delayed", extras=kwargs["extras"])
        return real(instance, controller, **kwargs)

    monkeypatch.setattr(grnn_module, "simulated_design", first_diverges)
    design = grnn(small[0], **WARM, **SHORT)
    assert len(calls) == 2 and design.status == "optimal" and design.extras["kept_start"] is True
    assert design.extras["trained_cost"] <= design.extras["init_cost"]  # it had won on the selection set
    assert "kept" in design.message and "the trained model diverged when scored (an unbounded draw)" in design.message
    assert design.links == 0  # the diagonal gain's


def test_the_trainer_alone_refuses_a_warm_start_it_has_no_design_for(small):
    """codesign's grnn has no static designs of its own (it imports nothing of baselines): a warm start
    that needs one is a one-line ValueError naming where it is, before any training; a start the
    caller gives (``start=``) needs none, and gives what baselines.grnn gives from the same start."""
    from codesign.learned.grnn import grnn as trainer_grnn

    inst = small[0]
    with pytest.raises(ValueError, match=r"^init 'diagonal' starts from a design of the method layer.*baselines\.grnn"):
        trainer_grnn(inst, **WARM, **SHORT)
    given = sparse_delayed(inst, gammas=[0.0], diagonal_end=False)[0]
    on_graph = dict(readout="per_node", init="delayed", activation="identity", **SHORT)
    alone = trainer_grnn(inst, start=given, **on_graph)
    layered = grnn(inst, start=given, **on_graph)
    assert alone.extras["init_source"] == layered.extras["init_source"] == "the given delayed design"
    assert alone.cost == pytest.approx(layered.cost, rel=1e-12)
