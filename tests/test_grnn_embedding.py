"""Delayed static designs as GRNNs with a per-node readout (issue #50): the exact embedding.

A delayed gain u(t) = K_l x(t) + K_d x(t - 1) is the linear GRNN with h = 2, F = (ε, 0),
W = [[0, 1], [0, 0]], S = K_d, G_i = (k_ii, 1) / ε (codesign/learned/embedding.py,
docs/methods.md). Its exact cost must be the design's to rounding on every family, its
links the design's; with tanh the gap closes like ε².
"""

from __future__ import annotations

import numpy as np
import pytest

from baselines import decentralized, sparse_admm, sparse_delayed
from baselines.sparse_delayed import DelayedStaticGain, polish_delayed
from codesign import exact_cost, paper_instance, simulate
from codesign.design import count_links
from codesign.evaluation import validation_set
from codesign.learned import GRNNController, LinearGRNNController, delayed_gain_parts, embed_delayed_gain
from compare.run.families.chain import chain_instance
from compare.run.families.mass_spring import mass_spring_instance

#: Relative agreement of the embedded GRNN's exact cost with the design's.
RTOL = 1e-10
#: The scales ε tried; with the identity activation every one is exact.
SCALES = (1.0, 1e-3)


def _relative(a, b):
    return abs(a - b) / abs(b)


@pytest.fixture(scope="module")
def paper():
    inst = paper_instance(0)
    return inst, sparse_delayed(inst, gammas=[0.0, 1e-3]) + [decentralized(inst)]


@pytest.fixture(scope="module")
def chain():
    inst = chain_instance(10)
    return inst, sparse_delayed(inst, gammas=[0.0, 1e-4]) + [decentralized(inst)]


@pytest.fixture(scope="module")
def springs():
    """Mass-spring nodes (position and velocity, one force): the decentralized block gain, and a delayed
    gain polished on the pattern "each mass reads the one before it" (one delayed block per node)."""
    inst = mass_spring_instance(6)
    diagonal = decentralized(inst)
    N = inst.nodes
    free = inst.expand_blocks(np.eye(N, k=-1, dtype=bool)) & ~inst.block_mask()
    polished = polish_delayed(inst, diagonal.controller.K, np.where(free, 0.01, 0.0), free)
    assert polished.success
    delayed = DelayedStaticGain(polished.local, polished.K_delayed, inst.state_nodes, inst.input_nodes)
    return inst, diagonal, delayed


def _check_exact(inst, designs):
    gaps = []
    for design in designs:
        assert design.status in ("optimal", "inaccurate"), design.message
        reference = exact_cost(inst, design.controller)
        assert _relative(reference, design.cost) < RTOL
        for scale in SCALES:
            embedded = embed_delayed_gain(design, instance=inst, scale=scale)
            assert isinstance(embedded, LinearGRNNController) and embedded.readout == "per_node"
            assert count_links(embedded.S)[0] == design.links  # the GRNN's links are the design's
            gaps.append(_relative(exact_cost(inst, embedded), design.cost))
    assert max(gaps) < RTOL, gaps
    return gaps


def test_paper_family_embeds_exactly(paper):
    inst, designs = paper
    assert {d.links for d in designs} >= {0, 380}  # the dense end, sparse points and the diagonal gain
    _check_exact(inst, designs)


def test_chain_family_embeds_exactly(chain):
    inst, designs = chain
    assert {d.links for d in designs} >= {0, 90}  # the dense end (all 90 pairs), the diagonal gain
    _check_exact(inst, designs)


def test_multi_state_nodes_embed_exactly(springs):
    """p = 2 states per node: h = 4, F = ε [I, 0], G_i = [K_l,ii' ; M_i'] / ε (N, 4, 1)."""
    inst, diagonal, delayed = springs
    embedded = embed_delayed_gain(diagonal, instance=inst)
    assert embedded.G.shape == (inst.nodes, 4, 1) and embedded.F.shape == (2, 4)
    assert _relative(exact_cost(inst, embedded), diagonal.cost) < RTOL
    reference = exact_cost(inst, delayed)
    for scale in SCALES:
        embedded = embed_delayed_gain(delayed, scale=scale)
        assert count_links(embedded.S)[0] == inst.nodes - 1
        assert _relative(exact_cost(inst, embedded), reference) < RTOL


def test_node_blocks_that_no_grnn_holds_are_refused(springs):
    """The dense delayed gain on node blocks: node i's blocks K_d,ij are not multiples of one matrix."""
    inst = springs[0]
    dense = sparse_delayed(inst, gammas=[0.0], diagonal_end=False)[0]
    with pytest.raises(ValueError, match=r"node 0's delayed blocks from nodes \[1, 2, 3, 4, 5\] are not multiples "
                                         r"of one 1 x 2 matrix"):
        embed_delayed_gain(dense)


def test_the_recursion_is_the_delayed_gain_step_by_step(paper):
    """Not only the cost: u(t) of the embedded GRNN equals the delayed gain's along a closed-loop trajectory."""
    inst, designs = paper
    gain = designs[1].controller  # a sparse point of the path
    grnn = embed_delayed_gain(gain, scale=0.5)
    x = np.random.default_rng(0).standard_normal((3, inst.n))
    s_gain, s_grnn = gain.reset(3), grnn.reset(3)
    for _ in range(6):
        u, s_gain = gain.step(s_gain, x)
        v, s_grnn = grnn.step(s_grnn, x)
        np.testing.assert_allclose(v, u, rtol=0, atol=1e-13 * np.abs(u).max())
        x = x @ inst.A.T + u @ inst.B.T


def test_the_scalar_construction_is_the_issue_s(paper):
    """One state and one input per node: S = K_d, F = (ε, 0), W = [[0, 1], [0, 0]], G_i = (k_ii, 1) / ε."""
    inst, designs = paper
    gain = designs[1].controller
    c = embed_delayed_gain(gain, scale=0.25)
    np.testing.assert_array_equal(c.S, gain.K_delayed)
    np.testing.assert_array_equal(c.F, [0.25, 0.0])
    np.testing.assert_array_equal(c.W, [[0.0, 1.0], [0.0, 0.0]])
    np.testing.assert_allclose(c.G, np.column_stack([np.diag(gain.K_local), np.ones(inst.n)]) / 0.25, rtol=1e-15)
    wide = embed_delayed_gain(gain, hidden=5)
    assert wide.G.shape == (inst.n, 5) and _relative(exact_cost(inst, wide), exact_cost(inst, gain)) < RTOL


#: The tanh GRNN's cost gap |J_tanh - J_linear| / J_linear by ε, on the same 2000 validation draws
#: (paper_instance(0), the γ = 1e-3 point, 31 links), as measured: it falls like ε².
TANH_GAPS = {1.0: 8.13e-3, 1e-1: 1.65e-4, 1e-2: 1.79e-6, 1e-3: 1.80e-8}


def test_tanh_gap_closes_as_the_scale_shrinks(paper):
    inst, designs = paper
    design = designs[1]
    x0 = validation_set(inst)
    gaps = {}
    for scale in TANH_GAPS:
        tanh = embed_delayed_gain(design, scale=scale, activation="tanh")
        assert type(tanh) is GRNNController
        linear = simulate(inst, embed_delayed_gain(design, scale=scale), x0).plain_cost
        gaps[scale] = _relative(simulate(inst, tanh, x0).plain_cost, linear)
    print("tanh cost gap by scale:", {k: f"{v:.2g}" for k, v in gaps.items()})
    values = list(gaps.values())
    assert all(b < 0.05 * a for a, b in zip(values[1:], values[2:])), gaps  # ~ε² below ε = 0.1
    assert all(b < a for a, b in zip(values, values[1:])), gaps
    assert values[-1] < 1e-7, gaps
    for scale, expected in TANH_GAPS.items():
        assert gaps[scale] == pytest.approx(expected, rel=0.02), (scale, gaps)


def test_bad_sources_and_keywords_are_one_line_errors(paper, springs):
    inst, designs = paper
    with pytest.raises(ValueError, match="a static gain with links"):
        embed_delayed_gain(sparse_admm(inst, gammas=[1e-3])[0])
    failed = type(designs[0]).failure("sparse_delayed", {}, "diverged", "no", info_model="delayed")
    with pytest.raises(ValueError, match="has no controller"):
        embed_delayed_gain(failed)
    with pytest.raises(ValueError, match="takes a delayed static gain"):
        embed_delayed_gain(embed_delayed_gain(designs[0]))
    for kw, match in ((dict(scale=0.0), "scale"), (dict(scale=float("nan")), "scale"), (dict(hidden=1), "hidden"),
                      (dict(activation="relu"), "activation"), (dict(rtol=-1.0), "rtol")):
        with pytest.raises(ValueError, match=match):
            embed_delayed_gain(designs[0], **kw)
    with pytest.raises(ValueError, match="the gain is 20 x 20 .inputs x states., the instance has m = 6"):
        embed_delayed_gain(designs[0], instance=springs[0])
    with pytest.raises(ValueError, match="needs node maps"):
        delayed_gain_parts(springs[1])  # a block gain without its instance
