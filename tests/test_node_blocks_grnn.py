"""The GRNN on nodes with several states and inputs: padded node signals, x_i F and Z_i G."""

from __future__ import annotations

import numpy as np
import pytest

import compare.run.registry  # noqa: F401  (the built-ins: importing a family registers no method)
from codesign import compare_exact_and_simulated, controller_from_arrays, count_links, get_method
from codesign.evaluation import impulse_responses
from codesign.learned.grnn import GRNNController, LinearGRNNController, _padded_problem
from codesign.learned.trainer import selection_set
from codesign.learned.grnn_bptt import ModelSpec, init_fwg, train_grnn
from compare.run.families.mass_spring import mass_spring_instance
from references import assert_bptt_matches_autograd  # tests/references.py

SHORT = dict(steps=60, ensemble=1, stability_steps=50, curve_size=20)


@pytest.fixture(scope="module")
def chain():
    return mass_spring_instance(6, horizon=20)


def _spec(instance, m, **kw):
    padded = _padded_problem(instance)
    F, W, G = init_fwg(np.random.default_rng([m, 7]), 4, padded["p"], padded["q"])
    return ModelSpec(A=padded["A"], B=padded["B"], Q=padded["Q"], R=padded["R"], P=padded["P"],
                     trace_P=instance.trace_P, S0=instance.gso, mask=instance.comm_adj != 0, F0=F, W0=W, G0=G,
                     data_seed=[m, 0], curve_x0=padded["embed"](selection_set(instance, 10)),
                     state_index=padded["state_index"], **kw)


@pytest.mark.parametrize("activation", ["tanh", "identity"])
def test_bptt_matches_autograd_on_uneven_blocks(uneven, activation):
    """p = 3 states and q = 2 inputs per node after padding: loss and every gradient equal autograd's."""
    specs = [_spec(uneven, 0, beta=0.2), _spec(uneven, 1, penalty=(1.0, 0.5, 0.7, 2.0))]
    assert tuple(np.shape(specs[0].F0)) == (3, 4) and tuple(np.shape(specs[0].G0)) == (4, 2)
    rng = np.random.default_rng(1)
    x0 = np.zeros((2, 5, 12))
    x0[:, :, specs[0].state_index] = rng.standard_normal((2, 5, 8))
    assert_bptt_matches_autograd(specs, x0, horizon=uneven.horizon, activation=activation)


def test_training_draws_leave_the_padding_at_zero(uneven):
    """The trainer's loss equals the unpadded plant's cost of the controller it trains (padding inert)."""
    (result,) = train_grnn([_spec(uneven, 0)], steps=3, batch=4, horizon=uneven.horizon, curve_every=1)
    controller = GRNNController(**result.params, state_nodes=uneven.state_nodes, input_nodes=uneven.input_nodes)
    from codesign import simulate

    x0 = selection_set(uneven, 10)
    rollout = simulate(uneven, controller, x0, control_variates=False)
    np.testing.assert_allclose(rollout.plain_cost, result.curve_cost[-1], rtol=1e-10)


def test_controller_reads_each_state_in_its_slot(uneven):
    rng = np.random.default_rng(2)
    h = 3
    S, W = rng.standard_normal((4, 4)), rng.standard_normal((h, h))
    F, G = rng.standard_normal((3, h)), rng.standard_normal((h, 2))
    c = GRNNController(S, F, W, G, uneven.state_nodes, uneven.input_nodes)
    x = rng.standard_normal((2, 8))
    u, Z = c.step(c.reset(2), x)
    Z = Z.transpose(2, 1, 0)  # the controller keeps Z feature-major, (h, batch, N): node-major here
    # node 0 holds states 0, 4, 7 in slots 0, 1, 2; node 1 holds inputs 1, 2 in slots 0, 1
    np.testing.assert_allclose(Z[0], np.tanh(x[:, [0, 4, 7]] @ F))
    np.testing.assert_allclose(Z[2], np.tanh(x[:, [2]] @ F[:1]))
    np.testing.assert_allclose(u[:, [1, 2]], Z[1] @ G)
    np.testing.assert_allclose(u[:, 3], Z[2] @ G[:, 0])
    with pytest.raises(ValueError, match=r"F and G must have shapes \(3, 3\) and \(3, 2\)"):
        GRNNController(S, F[:2], W, G, uneven.state_nodes, uneven.input_nodes)


def test_linearized_closed_loop_of_a_linear_grnn_is_its_closed_loop(uneven):
    rng = np.random.default_rng(3)
    c = LinearGRNNController(0.3 * rng.standard_normal((4, 4)), 0.3 * rng.standard_normal((3, 4)),
                             0.5 * rng.standard_normal((4, 4)), 0.3 * rng.standard_normal((4, 2)),
                             uneven.state_nodes, uneven.input_nodes)
    phi_x, _ = impulse_responses(uneven, c, 6)
    L = c.linearized_closed_loop(uneven)
    power = np.eye(L.shape[0])
    for t in range(7):
        np.testing.assert_allclose(power[:8, :8], phi_x[t], atol=1e-12)
        power = L @ power


@pytest.mark.parametrize("name, kw", [("grnn", {}), ("grnn_fixed", {}), ("grnn_dense", {}),
                                      ("grnn_sparse", {"beta": 0.1})])
def test_every_variant_trains_on_the_chain_and_counts_links_between_nodes(chain, name, kw):
    (design,) = get_method(name)(chain, **SHORT, **kw)
    assert design.status == "optimal", design.message
    c = design.controller
    assert c.F.shape == (2, 5) and c.G.shape == (5, 1) and c.S.shape == (6, 6)
    assert (design.links, design.self_loops) == count_links(c.S)
    if name in ("grnn", "grnn_fixed"):
        assert np.all(c.S[chain.comm_adj == 0] == 0)
    assert np.isfinite(design.cost) and design.cost < get_method("autonomous")(chain)[0].cost
    again = controller_from_arrays(c.kind, c.arrays())
    x = np.random.default_rng(0).standard_normal((3, chain.n))
    np.testing.assert_array_equal(again.step(again.reset(3), x)[0], c.step(c.reset(3), x)[0])


def test_linear_grnn_on_blocks_is_scored_exactly(chain):
    (design,) = get_method("grnn_sparse")(chain, beta=0.1, activation="identity", **SHORT)
    assert design.status == "optimal" and design.cost_kind == "exact"
    check = compare_exact_and_simulated(chain, design.controller)
    assert abs(check["z"]) < 3
    np.testing.assert_allclose(check["control_variate"], design.cost, rtol=1e-9)

